"""Collision-aware placement: the paper's march, its stop reasons, and the fast path against the plain loop."""

from __future__ import annotations

import json

import numpy as np
import pytest
import shapely

from adaptenv.adapt.placement import (
    OVERLAP_EPS,
    ConvexSet,
    PlacementContext,
    place,
    place_units,
    poly_depth,
    rect_depth,
    reference_place,
)
from adaptenv.scene.assets import ASSETS_ENV, COUNTER_ARM_DEPTH, load_catalog, use_assets
from adaptenv.scene.geometry import Footprint, SceneGeometry, footprint_corners
from tests.sim import helpers as H

BED, CHAIR, TABLE = "Bed_1", "Chair_002_1", "Dining_Table_16_1"


def bedroom(chair_x: float = 1.0, chair_z: float = 1.5) -> PlacementContext:
    """A 6 x 4 m room and a 3 x 4 m room (door between them); a chair left of a bed (Fig. 3)."""
    house = H.make_house([(0.0, 0.0, 6.0, 4.0), (6.0, 0.0, 9.0, 4.0)], doors=[H.Door(0, 1, 2.0, 1.0)],
                         objects=[H.Obj(CHAIR, chair_x, chair_z), H.Obj(BED, 3.5, 2.0)], agent=(0.5, 3.5, 0.0))
    return PlacementContext.from_house(house)


def test_figure3_chair_stops_just_before_the_bed():
    ctx = bedroom()
    res = place_units(ctx, "Chair|0", 20, 5)  # 100 units = 9 m: 1.8 m right, 0.45 m up
    assert res.stop_reason == "blocked_by_object" and res.blocked_by == "Bed|1"
    assert 0 < res.achieved_units[0] < 20 and res.achieved_units[1] > 0
    assert res.achieved[1] / res.achieved[0] == pytest.approx(5 / 20)  # along the requested direction
    # The chair's right edge is within one step (delta = 0.05 m) of the bed's left edge.
    bed_left = 3.5 - 1.4668 / 2
    chair_right = 1.0 + res.achieved[0] + 0.4688 / 2
    assert 0 <= bed_left - chair_right < 0.05 * 20 / np.hypot(20, 5) + 1e-9
    assert res.steps == int(np.hypot(*res.achieved) / 0.05 + 0.5)


def test_free_move_reaches_the_target():
    res = place(bedroom(), "Chair|0", 0.0, 1.5)
    assert res.stop_reason == "reached" and res.achieved == pytest.approx((0.0, 1.5))


def test_wall_stop_and_flush_placement():
    res = place(bedroom(), "Chair|0", -3.0, 0.0)
    assert res.stop_reason == "blocked_by_wall" and res.blocked_by.startswith("wall|0|0.00")
    left = 1.0 + res.achieved[0] - 0.4688 / 2
    assert -1e-9 <= left < 0.05  # stopped within a step of the wall, never through it


def test_objects_stay_in_their_room_even_through_a_door():
    ctx = bedroom(chair_x=5.5, chair_z=2.0)
    res = place(ctx, "Chair|0", 2.0, 0.0)  # straight at the door between the rooms
    assert res.stop_reason == "left_room" and res.blocked_by == "door|0|1|0"
    assert 5.5 + res.achieved[0] + 0.4688 / 2 <= 6.0 + 0.01


def test_rotation_kept_when_free_and_rejected_when_it_collides():
    ctx = bedroom()
    ok = place(ctx, "Chair|0", 0.0, 0.0, yaw=45.0)
    assert ok.rotation_applied and ok.yaw_after == 45.0 and ok.stop_reason == "reached"
    # A chair flush against the bed cannot turn; the move is still attempted with the old yaw.
    tight = bedroom(chair_x=3.5 - 1.4668 / 2 - 0.4688 / 2, chair_z=2.0)
    res = place(tight, "Chair|0", 0.0, 0.5, yaw=45.0)
    assert not res.rotation_applied and res.yaw_after == 0.0
    assert res.stop_reason == "rotation_blocked" and res.rotation_blocked_by == "Bed|1"
    assert res.achieved == pytest.approx((0.0, 0.5))


def test_a_relocation_sets_the_object_down_in_another_room_and_the_context_follows():
    ctx = bedroom()  # chair at (1.0, 1.5) in room 0; room 1 spans x 6..9
    marched = place(ctx, "Chair|0", 6.5, 0.5)
    assert marched.stop_reason != "reached" and 1.0 + marched.achieved[0] < 6.0  # a march never leaves room 0
    res = place(ctx, "Chair|0", 6.5, 0.5, relocate=True)
    assert res.stop_reason == "reached" and res.achieved == pytest.approx((6.5, 0.5)) and res.steps == 1
    onto_bed = place(ctx, "Chair|0", 2.5, 0.5, relocate=True)
    assert onto_bed.stop_reason == "blocked_by_object" and onto_bed.blocked_by == "Bed|1"
    assert onto_bed.achieved == (0.0, 0.0) and not onto_bed.changed
    outside = place(ctx, "Chair|0", 10.0, 0.0, relocate=True)
    assert outside.stop_reason in ("blocked_by_wall", "left_room") and not outside.changed
    i = ctx.index["Chair|0"]
    ctx.commit(i, ctx.centers[i] + np.array(res.achieved), 0.0, relocated=True)
    assert ctx.room_ids[ctx.room_of[i]] == ctx.room_ids[1], "the chair now belongs to room 1"
    back = place(ctx, "Chair|0", -3.0, 0.0)  # a march from there stops at room 1's wall
    assert back.stop_reason in ("blocked_by_wall", "left_room") and 7.5 + back.achieved[0] - 0.4688 / 2 >= 6.0 - 1e-6


def test_invalid_requests():
    ctx = bedroom()
    assert place(ctx, "Nope|1", 1.0, 0.0).stop_reason == "invalid"
    assert place(ctx, "Chair|0", float("nan"), 0.0).stop_reason == "invalid"


def test_preexisting_overlap_does_not_block_moving_away(real_house):
    ctx = PlacementContext.from_house(real_house)
    i, j = ctx.index["Chair|3|0|1"], ctx.index["DiningTable|3|0|0"]
    assert (min(i, j), max(i, j)) in ctx.preexisting  # tucked under the table
    table = ctx.centers[j]
    away = ctx.centers[i] - table
    away = away / np.linalg.norm(away) * 0.4
    res = place(ctx, "Chair|3|0|1", *away)
    assert res.stop_reason != "blocked_by_object" or res.blocked_by != "DiningTable|3|0|0"
    assert np.hypot(*res.achieved) > 0.2
    # Pushing it deeper under the table is blocked by the table once the overlap grows too much.
    deeper = place(ctx, "Chair|3|0|1", *(-away * 2))
    assert deeper.stop_reason == "blocked_by_object"


def test_rect_depth_sign_matches_shapely():
    rng = np.random.default_rng(3)
    for _ in range(300):
        a = rng.uniform(-1, 1, 2), rng.uniform(0.2, 1.5, 2), rng.uniform(0, 360)
        b = rng.uniform(-1, 1, 2), rng.uniform(0.2, 1.5, 2), rng.uniform(0, 360)
        ca = footprint_corners(*a[0], *a[1], a[2])
        cb = footprint_corners(*b[0], *b[1], b[2])
        depth = rect_depth(a[0], (a[1][0] / 2, a[1][1] / 2), a[2], ConvexSet.build(cb[None]))[0, 0]
        area = shapely.Polygon(ca).intersection(shapely.Polygon(cb)).area
        assert (depth > OVERLAP_EPS) == (area > 1e-6) or abs(depth) < 1e-3


def _requests(ctx: PlacementContext, n: int, seed: int):
    rng = np.random.default_rng(seed)
    ids = [oid for oid, m in zip(ctx.ids, ctx.movable, strict=True) if m]
    for _ in range(n):
        yaw = float(rng.uniform(0, 360)) if rng.random() < 0.5 else None
        yield ids[int(rng.integers(len(ids)))], *rng.uniform(-3.0, 3.0, 2), yaw


@pytest.mark.parametrize("step", [0.05, 0.13])
def test_fast_march_equals_reference_loop(real_house, step):
    ctx = PlacementContext.from_house(real_house)
    for oid, dx, dz, yaw in _requests(ctx, 150, seed=int(step * 100)):
        assert place(ctx, oid, dx, dz, yaw, step=step) == reference_place(ctx, oid, dx, dz, yaw, step=step)


def test_fast_march_equals_reference_on_a_generated_house():
    from adaptenv.scene.procedural import GenerationConfig, generate_house

    ctx = PlacementContext.from_house(generate_house(3, GenerationConfig(n_rooms=5)))
    for oid, dx, dz, yaw in _requests(ctx, 150, seed=7):
        assert place(ctx, oid, dx, dz, yaw) == reference_place(ctx, oid, dx, dz, yaw)


def test_results_never_collide(real_house):
    """Every achieved pose is free of new overlaps and inside the object's room (checked with shapely)."""
    ctx = PlacementContext.from_house(real_house)
    polys = [shapely.Polygon(o) for o in ctx.outlines]  # true footprints (the L counter is not a box)
    rooms = list(SceneGeometry.from_house(real_house).rooms.values())
    for oid, dx, dz, yaw in _requests(ctx, 100, seed=11):
        res = place(ctx, oid, dx, dz, yaw)
        i = ctx.index[oid]
        c = ctx.centers[i] + np.array(res.achieved)
        poly = shapely.Polygon(ctx.outline(i, c, res.yaw_after))
        assert rooms[ctx.room_of[i]].buffer(0.003, join_style="mitre").covers(poly)
        for j, other in enumerate(polys):
            if j != i and (min(i, j), max(i, j)) not in ctx.preexisting:
                assert poly.intersection(other).area < 1e-4, (oid, ctx.ids[j])


L_COUNTER = "Countertop_L_10x10"


def l_kitchen(chair: tuple[float, float]) -> tuple[PlacementContext, Footprint]:
    """A 5 x 5 m room with a 3 x 3 m L counter in its back-right corner (arms along z = 0 and x = 5,
    wrapping the floor in front-left of them) and a chair; returns the context and the counter."""
    sx, _, sz = load_catalog().asset(L_COUNTER).size
    house = H.one_room((5.0, 5.0), objects=[H.Obj(L_COUNTER, 5.0 - sx / 2 - 0.01, sz / 2 + 0.01), H.Obj(CHAIR, *chair)],
                       agent=(0.5, 4.5, 0.0))
    geometry = SceneGeometry.from_house(house)
    counter = next(f for f in geometry.floor_objects if f.asset_id == L_COUNTER)
    return PlacementContext.from_house(house, geometry=geometry), counter


def _arms(counter: Footprint) -> tuple[float, float]:
    """World z of the back arm's inner edge and world x of the side arm's inner edge (yaw 0)."""
    z0, x1 = counter.corners[0][1], counter.corners[2][0]
    return z0 + COUNTER_ARM_DEPTH, x1 - COUNTER_ARM_DEPTH


def test_an_object_moves_into_the_floor_an_l_counter_wraps():
    ctx, counter = l_kitchen((1.0, 4.0))
    chair = next(oid for oid in ctx.ids if oid.startswith("Chair"))
    res = place(ctx, chair, 2.0, -2.2)  # to (3.0, 1.8): inside the L's bounding box, off its arms
    assert res.stop_reason == "reached" and res.achieved == pytest.approx((2.0, -2.2))
    assert res == reference_place(ctx, chair, 2.0, -2.2)
    i = ctx.index[chair]
    at = shapely.Polygon(ctx.outline(i, ctx.centers[i] + np.array(res.achieved), res.yaw_after))
    assert shapely.Polygon(counter.corners).intersection(at).area > 0.1  # a box counter would have stopped it
    assert counter.polygon.intersection(at).area == 0.0


@pytest.mark.parametrize("d", [(0.0, -1.5), (2.0, 0.0), (1.2, -1.2)])
def test_an_object_in_the_wrap_stops_at_the_l_counter_arms(d):
    ctx, counter = l_kitchen((3.0, 1.8))
    chair = next(oid for oid in ctx.ids if oid.startswith("Chair"))
    assert ctx.preexisting == {}, "standing in the wrap is no overlap with the counter"
    res = place(ctx, chair, *d)
    assert res.stop_reason == "blocked_by_object" and res.blocked_by == counter.object_id
    assert res == reference_place(ctx, chair, *d)
    i = ctx.index[chair]
    hx, hz = ctx.half(i)
    back_arm, side_arm = _arms(counter)
    left = 1.8 + res.achieved[1] - hz - back_arm  # gap to the back arm (>= 0: never on it)
    right = side_arm - (3.0 + res.achieved[0] + hx)  # gap to the side arm
    gaps = [g for g, moved in ((left, d[1] < 0), (right, d[0] > 0)) if moved]
    assert all(g >= -1e-9 for g in (left, right))
    assert min(gaps) < 0.05 + 1e-9, "stopped within one step of the arm it ran into"


def test_a_movable_l_shaped_asset_is_placed_by_its_outline(tmp_path, monkeypatch):
    """A user asset with an L outline that can move: the fast march equals the plain loop and never overlaps."""
    table = {"assets": {"ltable": {"type": "DiningTable", "size": [1.6, 0.75, 1.6],
                                   "footprint": [[-0.8, -0.8], [0.8, -0.8], [0.8, 0.8], [0.2, 0.8], [0.2, -0.2],
                                                 [-0.8, -0.2]]}}}
    (tmp_path / "t.json").write_text(json.dumps(table), encoding="utf-8")
    monkeypatch.setenv(ASSETS_ENV, "")
    use_assets(tmp_path / "t.json")
    house = H.one_room((5.0, 4.0), objects=[H.Obj("ltable", 1.5, 1.5), H.Obj(CHAIR, 1.0, 2.0), H.Obj(BED, 3.8, 2.0)],
                       agent=(0.4, 3.6, 0.0))
    ctx = PlacementContext.from_house(house)
    k = ctx.index[next(oid for oid in ctx.ids if oid.startswith("DiningTable"))]
    assert len(ctx.local_pieces[k]) > 1 and (min(k, ctx.index["Chair|1"]), max(k, ctx.index["Chair|1"])) \
        not in ctx.preexisting, "the chair stands in the table's cut-out corner, not on the table"
    polys = [shapely.Polygon(o) for o in ctx.outlines]
    rooms = list(SceneGeometry.from_house(house).rooms.values())
    for oid, dx, dz, yaw in _requests(ctx, 120, seed=5):
        res = place(ctx, oid, dx, dz, yaw)
        assert res == reference_place(ctx, oid, dx, dz, yaw)
        i = ctx.index[oid]
        poly = shapely.Polygon(ctx.outline(i, ctx.centers[i] + np.array(res.achieved), res.yaw_after))
        assert rooms[0].buffer(0.003, join_style="mitre").covers(poly)
        assert all(poly.intersection(o).area < 1e-4 for j, o in enumerate(polys) if j != i)


def test_poly_depth_matches_rect_depth_and_shapely():
    rng = np.random.default_rng(4)
    for _ in range(200):
        c, size, yaw = rng.uniform(-1, 1, 2), rng.uniform(0.2, 1.5, 2), rng.uniform(0, 360)
        obstacles = ConvexSet.build(np.array([footprint_corners(*rng.uniform(-1, 1, 2), *rng.uniform(0.2, 1.5, 2),
                                                                rng.uniform(0, 360)) for _ in range(3)]))
        offsets = footprint_corners(0.0, 0.0, *size, yaw)
        assert np.allclose(poly_depth(c, offsets, obstacles), rect_depth(c, tuple(size / 2), yaw, obstacles))
        tri = rng.uniform(-0.8, 0.8, (3, 2))
        depth = poly_depth(c, np.vstack([tri, tri[-1:]]), obstacles)[0]
        areas = [shapely.Polygon(tri + c).intersection(shapely.Polygon(v)).area for v in obstacles.verts]
        for dp, area in zip(depth, areas, strict=True):
            assert (dp > OVERLAP_EPS) == (area > 1e-6) or abs(dp) < 1e-3
