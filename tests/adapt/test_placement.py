"""Collision-aware placement: the paper's march, its stop reasons, and the fast path against the plain loop."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from adaptenv.adapt.placement import (
    OVERLAP_EPS,
    ConvexSet,
    PlacementContext,
    place,
    place_units,
    rect_depth,
    reference_place,
)
from adaptenv.scene.geometry import SceneGeometry, footprint_corners
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
    polys = shapely.polygons(ctx.objects.verts)
    rooms = list(SceneGeometry.from_house(real_house).rooms.values())
    for oid, dx, dz, yaw in _requests(ctx, 100, seed=11):
        res = place(ctx, oid, dx, dz, yaw)
        i = ctx.index[oid]
        c = ctx.centers[i] + np.array(res.achieved)
        poly = shapely.Polygon(ctx.corners(i, c, res.yaw_after))
        assert rooms[ctx.room_of[i]].buffer(0.003, join_style="mitre").covers(poly)
        for j, other in enumerate(polys):
            if j != i and (min(i, j), max(i, j)) not in ctx.preexisting:
                assert poly.intersection(other).area < 1e-4, (oid, ctx.ids[j])
