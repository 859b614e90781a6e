"""The plausibility rules for what a person sees at once, each on a small hand-built house: the older rules pass
the scene, the new rule flags it, and the validator refuses the move that would make it."""

from __future__ import annotations

import numpy as np
import pytest

from adaptenv.adapt.edits import Edit, apply_edit
from adaptenv.adapt.plausibility import audit
from adaptenv.adapt.validation import EditValidator
from adaptenv.scene.assets import load_catalog
from adaptenv.scene.house import House, HouseObject, Opening, Room, Vec3
from tests.sim import helpers as H


def _moved(house: House, object_id: str, x: float, z: float, yaw: float | None = None) -> House:
    obj = house.object_by_id(object_id)
    return apply_edit(house, Edit(object_id=object_id, achieved_dx=x - obj.position.x,
                                  achieved_dz=z - obj.position.z, yaw_before=obj.yaw,
                                  yaw_after=obj.yaw if yaw is None else yaw))


def _rules(original: House, adapted: House) -> set[str]:
    """The hand-written rules broken (the learned ``unlike_reference`` is tested in test_placement_model.py)."""
    return {v.rule for v in audit(original, adapted).violations} - {"unlike_reference"}


def _refused_by(house: House, object_id: str, dx: float, dz: float, yaw: float | None, start) -> set[str]:
    """The plausibility rules the validator names when it refuses the move (dx, dz in m); empty when it accepts."""
    v = EditValidator(house, start=start)
    upm = v.ctx.grid.units_per_meter
    p = v.propose(object_id, dx * upm, dz * upm, yaw)
    assert p.result.changed and p.result.stop_reason == "reached", p.result
    return {m.message.split("(")[1].split(")")[0] for m in p.problems if m.kind == "implausible"} - {"unlike_reference"}


def _object(n: int, asset_id: str, x: float, z: float, yaw: float) -> HouseObject:
    asset = load_catalog().asset(asset_id)
    return HouseObject(id=f"{asset.object_type}|{n}", assetId=asset_id, position=Vec3(x=x, y=asset.size[1] / 2, z=z),
                       rotation=Vec3(y=yaw), kinematic=True)


@pytest.fixture(scope="module")
def l_room() -> House:
    """One L-shaped room (a 6 x 3 m bar and a 3 x 3 m arm above its left half); a dresser backs onto the wall
    z = 3 from x = 3 to 6, which ends at the inner corner (3, 3)."""
    pts = [(0.0, 0.0), (6.0, 0.0), (6.0, 3.0), (3.0, 3.0), (3.0, 6.0), (0.0, 6.0)]
    walls = []
    for a, b in zip(pts, pts[1:] + pts[:1], strict=True):
        walls += [H._wall(H._wall_id("0", a, b), "room|0", a, b), H._wall(H._wall_id("exterior", a, b), "exterior", a, b)]
    room = Room(id="room|0", roomType="Bedroom", floorPolygon=[Vec3(x=x, z=z) for x, z in pts])
    house = House(rooms=[room], walls=walls, doors=[], objects=[_object(0, "Dresser_205_1", 4.5, 2.81, 180.0)])
    house.set_agent_pose(1.0, 1.0, 0.0)
    return house


def test_dresser_slid_past_the_end_of_its_wall(l_room):
    assert _rules(l_room, _moved(l_room, "Dresser|0", 4.0, 2.81)) == set()  # along the wall
    assert _rules(l_room, _moved(l_room, "Dresser|0", 3.0, 2.81)) == {"wall_overhang"}  # 0.6 m past its end
    assert _refused_by(l_room, "Dresser|0", -1.5, 0.0, None, (1.0, 1.0)) == {"wall_overhang"}
    assert _refused_by(l_room, "Dresser|0", -0.8, 0.0, None, (1.0, 1.0)) == set()


def test_builtin_g_slides_wall_furniture_only_as_far_as_its_wall(l_room):
    from adaptenv.adapt.generators.builtin import along_wall

    v = EditValidator(l_room, start=(1.0, 1.0))
    d, rotation = along_wall(v, "Dresser|0", np.array([-1.5, 0.0]), 90.0, np.random.default_rng(0))
    assert np.allclose(d, [-0.75, 0.0]) and rotation is None  # 1.5 m would run 0.6 m past the wall's end
    assert np.allclose(along_wall(v, "Dresser|0", np.array([-0.6, 0.3]), None, np.random.default_rng(0))[0],
                       [-0.6, 0.0])  # within the wall: the whole slide


@pytest.fixture(scope="module")
def alcove() -> House:
    """A bedroom (0-4 m) open to its alcove (4-8 m) along the whole shared wall x = 4 (no wall, no door)."""
    house = H.make_house([(0.0, 0.0, 4.0, 4.0), (4.0, 0.0, 8.0, 4.0)], objects=[H.Obj("Dining_Table_201_1", 2.0, 2.0)],
                         agent=(6.0, 2.0, 0.0), room_types=["Bedroom", "Bedroom"])
    for w in house.walls:
        if w.id.startswith(("wall|0|4.00", "wall|1|4.00|0.00|4.00")):
            w.empty = True
    return house


def test_table_turned_into_the_open_connection(alcove):
    assert sum(bool(w.empty) for w in alcove.walls) == 2
    assert _rules(alcove, _moved(alcove, "DiningTable|0", 2.4, 2.0, yaw=90.0)) == set()
    assert _rules(alcove, _moved(alcove, "DiningTable|0", 3.4, 2.0, yaw=90.0)) == {"in_opening"}
    assert _refused_by(alcove, "DiningTable|0", 1.4, 0.0, 90.0, (6.0, 2.0)) == {"in_opening"}


@pytest.fixture(scope="module")
def dining() -> House:
    """A dining table (1.78 m along x) with a chair at each end, 5 cm off, facing it."""
    return H.make_house([(0.0, 0.0, 6.0, 5.0)], agent=(5.5, 4.5, 0.0), room_types=["Kitchen"], objects=[
        H.Obj("Dining_Table_201_1", 3.0, 2.5), H.Obj("Chair_002_1", 1.81, 2.5, 90.0),
        H.Obj("Chair_002_1", 4.19, 2.5, 270.0)])


def test_chairs_left_behind_by_their_table(dining):
    turned = audit(dining, _moved(dining, "DiningTable|0", 3.0, 2.5, yaw=90.0))  # the chairs now at its corners
    assert {(v.rule, v.others) for v in turned.violations if v.rule != "unlike_reference"} == {
        ("group_left_behind", ("Chair|1",)), ("group_left_behind", ("Chair|2",))}
    assert _rules(dining, _moved(dining, "DiningTable|0", 3.0, 2.95)) == {"group_left_behind"}
    assert _rules(dining, _moved(dining, "DiningTable|0", 3.0, 2.5, yaw=180.0)) == set()  # looks the same
    assert _rules(dining, _moved(dining, "DiningTable|0", 3.0, 2.7)) == set()  # 0.2 m
    assert _rules(dining, _moved(dining, "Chair|1", 1.81, 2.95)) == set()  # a chair moves alone
    assert _refused_by(dining, "DiningTable|0", 0.0, 0.45, None, (5.5, 4.5)) == {"group_left_behind"}


@pytest.fixture(scope="module")
def window_room() -> House:
    """A 6 x 5 m kitchen with a window (sill 0.8 m, top 1.8 m) at x = 3-4 in the wall z = 0; a fridge (1.97 m
    tall) and a sofa (0.82 m) back onto that wall beside it."""
    house = H.make_house([(0.0, 0.0, 6.0, 5.0)], agent=(5.5, 4.5, 0.0), room_types=["Kitchen"], objects=[
        H.Obj("Fridge_1", 1.0, 0.365), H.Obj("RoboTHOR_sofa_alrid", 5.0, 0.475)])
    house.windows = [Opening(id="window|0|0", assetId="Window_Hung_32x60", room0="room|0", room1="room|0",
                             wall0="wall|0|0.00|0.00|6.00|0.00", wall1="wall|exterior|0.00|0.00|6.00|0.00",
                             holePolygon=[Vec3(x=3.0, y=0.8, z=0.0), Vec3(x=4.0, y=1.8, z=0.0)])]
    return house


def test_fridge_in_front_of_a_window(window_room):
    assert _rules(window_room, _moved(window_room, "Fridge|0", 2.0, 0.365)) == set()  # beside it
    assert _rules(window_room, _moved(window_room, "Fridge|0", 3.5, 0.365)) == {"blocks_window"}
    assert _rules(window_room, _moved(window_room, "Fridge|0", 3.5, 1.2)) == {"edge_off_wall"}  # 0.84 m off: free
    assert _rules(window_room, _moved(window_room, "Sofa|1", 3.5, 0.475)) == set()  # low: it stands under it
    assert _refused_by(window_room, "Fridge|0", 2.5, 0.0, None, (5.5, 4.5)) == {"blocks_window"}


def test_builtin_g_fits_moves_to_the_rules(dining, window_room):
    from adaptenv.adapt.generators.builtin import fit_rules

    v = EditValidator(dining, start=(5.5, 4.5))
    now = {f.object_id: f for f in v.geometry.footprints}
    d = fit_rules(v, now, "DiningTable|0", np.array([0.0, 0.45]), None)
    assert np.allclose(d, [0.0, 0.225])  # 0.45 and 0.34 m leave its chairs behind; half of it does not
    assert np.allclose(fit_rules(v, now, "Chair|1", np.array([0.0, 0.2]), None), [0.0, 0.2])  # nothing to fit
    assert fit_rules(v, now, "DiningTable|0", np.zeros(2), 90.0) is None  # the turn leaves the chairs at its corners
    w = EditValidator(window_room, start=(5.5, 4.5))
    now = {f.object_id: f for f in w.geometry.footprints}
    assert np.allclose(fit_rules(w, now, "Fridge|0", np.array([2.5, 0.0]), None), [1.25, 0.0])  # stops beside it
    assert fit_rules(w, now, "Fridge|0", np.array([2.5, 0.0]), None, shrink=False) is None


def test_builtin_g_candidates_respect_the_rules_by_construction():
    from adaptenv.adapt.generators.builtin import BuiltinGenerator
    from adaptenv.adapt.objectives import RouteSpec
    from adaptenv.adapt.plausibility import check_move
    from adaptenv.sim.world import compile_world
    from tests.adapt.scenes import procedural_scene

    house, world, ep, traj, _ = procedural_scene(3, 5, [0, 1])
    v = EditValidator(house, episode_targets=[ep.target_type], start=ep.start[:2])
    route = RouteSpec.from_episode(ep.target_type, ep.start, traj)
    targets = {t.object_id for t in world.instances_of(ep.target_type)}
    cands = BuiltinGenerator()._candidates(v, compile_world(v.house, "c"), route, targets, np.random.default_rng(3),
                                           limit=60)
    assert len(cands) >= 30 and {c.kind for c in cands} >= {"turn", "sideways"}
    now = {f.object_id: f for f in v.geometry.footprints}
    upm = v.ctx.grid.units_per_meter

    def broken(c) -> list:
        i = v.ctx.index[c.object_id]
        yaw = float(v.ctx.yaws[i]) if c.rotation is None else c.rotation
        return check_move(v.plausible, v.footprint_at(i, v.ctx.centers[i] + np.array([c.dx_units, c.dy_units]) / upm,
                                                      yaw), now)

    assert all(broken(c) == [] for c in cands)  # the pose each asks for breaks no rule (placement may stop short)
    unfitted = BuiltinGenerator(fit_to_rules=False)._candidates(v, compile_world(v.house, "c"), route, targets,
                                                                np.random.default_rng(3), limit=60)
    assert any(broken(c) for c in unfitted)  # drawn as they come, some would be refused
