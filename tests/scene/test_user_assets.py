"""Houses with assets the ProcTHOR catalog lacks (Objaverse-style ids) load with a user asset table,
and L/C counters have their true, non-rectangular footprints."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from shapely.geometry import Point, Polygon
from typer.testing import CliRunner

from adaptenv.adapt.placement import PlacementContext
from adaptenv.adapt.validation import NavRaster
from adaptenv.cli import app
from adaptenv.errors import ConfigError, HouseError
from adaptenv.scene.assets import (
    ASSETS_ENV,
    COUNTER_ARM_DEPTH,
    load_catalog,
    read_asset_table,
    use_assets,
)
from adaptenv.scene.geometry import SceneGeometry, footprint_room
from adaptenv.scene.graph import NEXT_TO_DISTANCE, build_scene_graph
from adaptenv.scene.house import House, HouseObject, Room, Vec3, Wall, load_house, save_house
from adaptenv.scene.validate import validate_house
from adaptenv.sim.geodesic import is_solvable
from adaptenv.sim.rollout import expert_policy, run_episode
from adaptenv.sim.spec import AGENT_RADIUS
from adaptenv.sim.task import sample_episode
from adaptenv.sim.world import compile_world
from tests.conftest import REAL_HOUSE
from tests.sim import helpers as H

L_COUNTER = "Countertop_L_10x10"
SOFA, BED, TABLE = "0a1b2c3d4e5f4a5b8c9d0e1f2a3b4c5d", "9f8e7d6c5b4a49388271605f4e3d2c1b", "5e5e5e5e5e5e4e5e9e5e5e5e5e5e5e5e"


@pytest.fixture
def table_file(tmp_path):
    """An Objaverse-style asset table: hex ids, ProcTHOR types, boxes, one L-shaped outline."""
    doc = {"assets": {
        SOFA: {"type": "Sofa", "size": [2.0, 0.9, 0.9]},
        BED: {"objectType": "Bed", "boundingBox": {"x": 1.4, "y": 0.6, "z": 2.1}},
        TABLE: {"type": "DiningTable", "size": [1.6, 0.75, 1.6],
                "footprint": [[-0.8, -0.8], [0.8, -0.8], [0.8, 0.8], [0.2, 0.8], [0.2, -0.2], [-0.8, -0.2]]},
    }}
    p = tmp_path / "my_assets.json"
    p.write_text(json.dumps(doc), encoding="utf-8")
    return p


@pytest.fixture
def objaverse_house(tmp_path, table_file, monkeypatch):
    """Two rooms furnished only with table assets, written with the table in use, then the table dropped."""
    monkeypatch.setenv(ASSETS_ENV, "")
    use_assets(table_file)
    house = H.two_rooms(objects=[H.Obj(SOFA, 2.0, 0.6), H.Obj(BED, 6.0, 2.0), H.Obj(TABLE, 1.0, 3.0)],
                        agent=(2.0, 2.0, 0.0))
    path = save_house(house, tmp_path / "objaverse_house.json")
    monkeypatch.setenv(ASSETS_ENV, "")
    return path


def test_unknown_ids_give_one_error_naming_count_and_flag(objaverse_house):
    with pytest.raises(HouseError) as err:
        load_house(objaverse_house)
    msg = str(err.value)
    assert len(err.value.problems) == 1
    assert "3 assetIds" in msg and repr(SOFA) in msg and "--assets FILE" in msg


def test_objaverse_house_loads_simulates_and_is_solvable(objaverse_house, table_file, monkeypatch):
    house = load_house(objaverse_house, catalog=load_catalog(table_file))  # the API argument
    assert not os.environ.get(ASSETS_ENV)
    use_assets(table_file)  # every function from here on
    world = compile_world(load_house(objaverse_house), "objaverse")
    assert sorted(world.object_types) == ["Bed", "DiningTable", "Sofa"]
    table = world.geometry.footprint(next(o.id for o in house.objects if o.assetId == TABLE))
    assert table.polygon.area == pytest.approx(1.6 * 1.6 - 1.0 * 1.0, abs=1e-6)
    # The cut-out corner of the table's outline (local -x, +z) is free floor in the simulator.
    assert world.grid.blocked[world.grid.to_cell(0.6, 3.6)] == 0
    assert world.grid.blocked[world.grid.to_cell(1.5, 3.0)] == 1
    for seed in range(4):
        ep = sample_episode(world, seed)
        assert is_solvable(world, ep)
        assert run_episode(world, ep, expert_policy(), max_steps=600).metrics.success


def test_cli_assets_flag_validates_and_adapts(objaverse_house, table_file, tmp_path, monkeypatch):
    monkeypatch.setenv(ASSETS_ENV, "")
    res = CliRunner().invoke(app, ["validate", str(objaverse_house)])
    assert res.exit_code != 0
    res = CliRunner().invoke(app, ["--assets", str(table_file), "validate", str(objaverse_house)])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(app, ["--assets", str(table_file), "adapt", str(objaverse_house), "-o",
                                   str(tmp_path / "out"), "--steps", "2", "--json"])
    assert res.exit_code == 0, res.output
    assert load_house(tmp_path / "out" / "house.json", catalog=load_catalog(table_file))


def test_bad_tables_are_one_clear_error(tmp_path):
    p = tmp_path / "t.json"
    for doc, words in [({"assets": {"x": {"type": "Spaceship", "size": [1, 1, 1]}}}, "not a ProcTHOR object type"),
                       ({"assets": {"x": {"type": "Sofa", "size": [1, 1]}}}, r"size\[2\] is missing"),
                       ({"assets": {"x": {"type": "Sofa", "size": [1, 1, 1], "footprint": [[0, 0]]}}}, "at least 3"),
                       ([], "expected a JSON object")]:
        p.write_text(json.dumps(doc), encoding="utf-8")
        with pytest.raises(ConfigError, match=words) as err:
            read_asset_table(p)
        assert str(p) in str(err.value)


def test_real_l_counter_outline_holds_its_children():
    """The L outline (derived from asset sizes) contains every object standing on the real L counter."""
    house = load_house(REAL_HOUSE, validate=False)
    geom = SceneGeometry.from_house(house)
    counter = next(o for o in house.objects if o.assetId.startswith("Countertop_L_"))
    fp = geom.footprint(counter.id)
    sx, sz = fp.size
    assert fp.polygon.area == pytest.approx(sx * sz - (sx - COUNTER_ARM_DEPTH) * (sz - COUNTER_ARM_DEPTH), rel=1e-6)
    assert fp.polygon.area < 0.8 * sx * sz
    outline = fp.polygon.buffer(0.02)
    assert counter.children and all(outline.covers(Point(c.position.x, c.position.z)) for c in counter.children)


@pytest.mark.parametrize("asset_id", ["Countertop_L_10x10", "Countertop_C_10x6"])
def test_wrapped_floor_of_l_and_c_counters_is_navigable(asset_id):
    """A big L or C counter against the back wall: the floor it wraps around is navigable and reachable."""
    size = load_catalog().asset(asset_id).size
    cx, cz = 4.5 - size[0] / 2, size[2] / 2 + 0.01
    house = H.one_room((5.0, 5.0), objects=[H.Obj(asset_id, cx, cz)])
    world = compile_world(house)
    d = COUNTER_ARM_DEPTH
    inside = (cx - size[0] / 2 + d + 0.45, cz + size[2] / 2 - 0.45) if asset_id.startswith("Countertop_C") else \
        (cx - 0.3, cz + size[2] / 2 - 0.45)
    comp, _ = world.grid.components(AGENT_RADIUS)
    r, c = world.grid.to_cell(*inside)
    assert world.grid.clearance[r, c] >= AGENT_RADIUS
    assert comp[r, c] == comp[world.grid.to_cell(1.0, 4.5)] != 0
    # The editing validator's raster agrees with the simulator's.
    geom = SceneGeometry.from_house(house)
    assert np.array_equal(NavRaster(geom).navigable(), world.grid.navigable(AGENT_RADIUS))


def _l_room_house(notch_room: bool) -> House:
    """A 6 x 5 m room missing its 3 x 2 m top-left corner (x < 3, z > 3), which is a second room when
    ``notch_room``, else outside the house; an L counter wraps the room's inner corner (3, 3), so its
    arms stand in the room and the square they wrap is the notch (its bounding box's centre too)."""
    size = load_catalog().asset("Countertop_L_6x6").size
    d = COUNTER_ARM_DEPTH
    cx, cz = 3.0 + d - size[0] / 2, 3.0 - d + size[2] / 2
    rooms = {"room|2": [(0.0, 0.0), (6.0, 0.0), (6.0, 5.0), (3.0, 5.0), (3.0, 3.0), (0.0, 3.0)]}
    if notch_room:
        rooms["room|3"] = [(0.0, 3.0), (3.0, 3.0), (3.0, 5.0), (0.0, 5.0)]
    walls, sides = [], {}
    for rid, pts in rooms.items():
        for a, b in zip(pts, pts[1:] + pts[:1], strict=True):
            sides.setdefault(frozenset((a, b)), []).append(rid)
            walls.append(_wall(rid, a, b))
    walls += [_wall("exterior", *sorted(ab)) for ab, rids in sides.items() if len(rids) == 1]
    objects = [HouseObject(id="CounterTop|2|0", assetId="Countertop_L_6x6", position=Vec3(x=cx, y=size[1] / 2, z=cz),
                           rotation=Vec3(y=0.0)),
               HouseObject(id="Fridge|2|1", assetId=H.TALL_TARGET, position=Vec3(x=5.0, y=1.0, z=1.0))]
    house = House(rooms=[Room(id=rid, roomType="Kitchen", floorPolygon=[Vec3(x=x, z=z) for x, z in pts])
                         for rid, pts in rooms.items()], walls=walls, objects=objects)
    house.set_agent_pose(4.5, 4.0, 0.0)
    return house


def _wall(room: str, a: tuple[float, float], b: tuple[float, float]) -> Wall:
    number = room.split("|")[-1]
    (x0, z0), (x1, z1) = a, b
    wid = f"wall|{number}|{min(x0, x1):.2f}|{min(z0, z1):.2f}|{max(x0, x1):.2f}|{max(z0, z1):.2f}"
    return Wall(id=wid, roomId=room, polygon=[Vec3(x=x0, z=z0), Vec3(x=x1, z=z1),
                                              Vec3(x=x0, y=2.5, z=z0), Vec3(x=x1, y=2.5, z=z1)])


def test_an_l_counter_is_in_the_room_its_outline_stands_in():
    """Its bounding box's centre lies in the notch (outside, or another room); its outline decides."""
    alone = _l_room_house(notch_room=False)
    fp = SceneGeometry.from_house(alone).footprint("CounterTop|2|0")
    assert not Polygon(fp.corners).within(SceneGeometry.from_house(alone).floor.buffer(0.05))
    assert validate_house(alone) == []  # the in-room check uses the true outline
    with_notch = _l_room_house(notch_room=True)
    geometry = SceneGeometry.from_house(with_notch)
    assert geometry.room_of_point(*fp.center) == "room|3"
    assert footprint_room(geometry.footprint("CounterTop|2|0"), geometry.rooms) == "room|2"
    assert build_scene_graph(with_notch).has("in_room", "CounterTop|2|0", "room|2")
    ctx = PlacementContext.from_house(with_notch)
    assert ctx.room_ids[ctx.room_of[ctx.index["CounterTop|2|0"]]] == "room|2"


def test_next_to_an_l_counter_is_measured_from_its_arms():
    """In the wrapped floor, an object 0.3 m from an arm is next to the counter; one 0.8 m from both is not
    (though both stand inside the counter's bounding box)."""
    sx, _, sz = load_catalog().asset(L_COUNTER).size
    cx, cz = 5.0 - sx / 2 - 0.01, sz / 2 + 0.01
    back_arm = cz - sz / 2 + COUNTER_ARM_DEPTH  # z of the back arm's inner edge
    can = load_catalog().asset(H.LOW_TARGET).size
    near = (cx - 0.5, back_arm + 0.3 + can[2] / 2)
    far = (cx - 0.5, back_arm + 0.8 + can[2] / 2)
    house = H.one_room((5.0, 5.0), objects=[H.Obj(L_COUNTER, cx, cz), H.Obj(H.LOW_TARGET, *near),
                                            H.Obj(H.LOW_TARGET, *far)], agent=(0.5, 4.5, 0.0))
    geometry = SceneGeometry.from_house(house)
    counter, a, b = geometry.floor_objects
    assert Polygon(counter.corners).covers(Polygon(b.corners)), "the far object stands inside the bounding box"
    assert counter.polygon.distance(b.polygon) > NEXT_TO_DISTANCE > counter.polygon.distance(a.polygon)
    g = build_scene_graph(house, geometry)
    assert g.has("next_to", counter.object_id, a.object_id)
    assert not g.has("next_to", counter.object_id, b.object_id)
