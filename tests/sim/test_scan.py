"""The depth-and-semantics scan: known distances and classes, range, ray order, and a slow reference."""

from __future__ import annotations

import math

import numpy as np
import pytest

from adaptenv.sim.physics import PackedGrids
from adaptenv.sim.scan import (
    RAY_OFFSETS_DEG,
    free_runs,
    pack_runs,
    pack_semantic,
    scan,
    scan_world,
)
from adaptenv.sim.spec import (
    AGENT_RADIUS,
    CLASS_DOOR,
    CLASS_NONE,
    CLASS_WALL,
    FOV_DEG,
    MAX_RANGE,
    N_RAYS,
    class_id,
)
from adaptenv.sim.world import compile_world
from tests.sim.helpers import TALL_TARGET, Obj, one_room, two_rooms

RES = 0.05
CELL = RES + 1e-4
"""One cell, with float32 slack: the raster puts a wall line in one of the two cells it touches."""


def yaw_for_ray(k: int, direction: float) -> float:
    """The agent yaw that points ray k exactly at ``direction`` (degrees)."""
    return (direction - RAY_OFFSETS_DEG[k]) % 360.0


def reference_scan(world, x: float, z: float, yaw: float, step: float = 0.1 * RES) -> tuple[np.ndarray, np.ndarray]:
    """Plain NumPy: march every ray in tiny fixed steps to the first blocked cell."""
    g = world.grid
    ts = np.arange(0.0, MAX_RANGE + step, step)
    depth, classes = np.ones(N_RAYS), np.full(N_RAYS, CLASS_NONE)
    for k in range(N_RAYS):
        a = math.radians(yaw + FOV_DEG * (k / (N_RAYS - 1) - 0.5))
        row, col = g.to_cell(x + ts * math.sin(a), z + ts * math.cos(a))
        inside = g.in_bounds(row, col)
        hit = ~inside
        hit[inside] = g.blocked[row[inside], col[inside]]
        first = np.flatnonzero(hit)
        if first.size and ts[first[0]] <= MAX_RANGE:
            j = first[0]
            depth[k] = ts[j] / MAX_RANGE
            classes[k] = world.semantic[row[j], col[j]] if inside[j] else CLASS_WALL
    return depth, classes


@pytest.fixture(scope="module")
def room():
    return compile_world(one_room((4.0, 4.0)))


def test_ray_offsets_span_the_field_of_view_left_to_right():
    assert RAY_OFFSETS_DEG.shape == (N_RAYS,)
    assert RAY_OFFSETS_DEG[0] == pytest.approx(-FOV_DEG / 2)
    assert RAY_OFFSETS_DEG[-1] == pytest.approx(FOV_DEG / 2)
    assert np.all(np.diff(RAY_OFFSETS_DEG) > 0)


@pytest.mark.parametrize("k", [0, 13, 31])
@pytest.mark.parametrize("z", [0.6, 1.03, 2.77])
def test_ray_straight_at_a_wall_returns_its_distance_within_a_cell(room, k, z):
    depth, classes = scan_world(room, 2.0, z, yaw_for_ray(k, 0.0))  # ray k faces +z, the wall at z = 4
    assert depth[k] * MAX_RANGE == pytest.approx(4.0 - z, abs=CELL)
    assert classes[k] == CLASS_WALL
    depth, _ = scan_world(room, 2.0, z, yaw_for_ray(k, 270.0))  # faces -x, the wall at x = 0
    assert depth[k] * MAX_RANGE == pytest.approx(2.0, abs=CELL)


def test_ray_order_ray_zero_is_the_leftmost(room):
    # Facing +z next to the wall x = 0: the left (yaw - 45) ray meets it at 0.5 * sqrt(2) m.
    depth, _ = scan_world(room, 0.5, 2.0, 0.0)
    assert depth[0] * MAX_RANGE == pytest.approx(0.5 * math.sqrt(2), abs=1.5 * RES)
    assert depth[-1] * MAX_RANGE > 2.0
    assert np.all(np.diff(depth[:8]) > 0)


def test_rays_beyond_range_return_one_and_none():
    big = compile_world(one_room((12.0, 12.0)))
    for yaw in (0.0, 37.0, 90.0, 200.0):
        depth, classes = scan_world(big, 6.0, 6.0, yaw)
        assert np.all(depth == 1.0)
        assert np.all(classes == CLASS_NONE)
    depth, classes = scan_world(big, 6.0, 1.5, 180.0)  # facing -z, the wall 1.5 m ahead
    assert np.all(depth < 1.0) and np.all(classes == CLASS_WALL)


def test_semantic_class_of_a_door_frame_and_a_closed_door(real_house):
    world = compile_world(two_rooms(1.0))  # door hole z in [1.5, 2.5] on the wall x = 4
    for z in (1.45, 2.55):  # 10 cm frames on each side of the hole
        depth, classes = scan_world(world, 3.0, z, yaw_for_ray(5, 90.0))
        assert classes[5] == CLASS_DOOR
        assert depth[5] * MAX_RANGE == pytest.approx(1.0, abs=CELL)
    depth, classes = scan_world(world, 3.5, 2.0, yaw_for_ray(5, 90.0))  # through the hole to the wall x = 8
    assert classes[5] == CLASS_WALL
    assert depth[5] * MAX_RANGE == pytest.approx(4.5, abs=CELL)

    real = compile_world(real_house)
    door = next(d for d in real.geometry.doors if not d.passable)
    (ax, az), (bx, bz) = door.p0, door.p1
    mx, mz = (ax + bx) / 2, (az + bz) / 2
    normal = np.array([-(bz - az), bx - ax]) / math.hypot(bx - ax, bz - az)
    inside = normal if real.grid.room_at(mx + normal[0], mz + normal[1]) else -normal
    sx, sz = mx + inside[0], mz + inside[1]
    facing = math.degrees(math.atan2(-inside[0], -inside[1]))
    depth, classes = scan_world(real, sx, sz, yaw_for_ray(16, facing))
    assert classes[16] == CLASS_DOOR
    assert depth[16] * MAX_RANGE == pytest.approx(1.0, abs=CELL)


def test_semantic_class_of_a_known_object():
    world = compile_world(one_room((6.0, 6.0), objects=[Obj(TALL_TARGET, 3.0, 4.5)]))  # Fridge, 0.72 m deep
    depth, classes = scan_world(world, 3.0, 1.5, yaw_for_ray(16, 0.0))
    assert classes[16] == class_id("Fridge")
    assert depth[16] * MAX_RANGE == pytest.approx(4.5 - 0.36 - 1.5, abs=CELL)


def test_batched_scan_matches_single_scans_across_houses(real_house):
    worlds = [compile_world(real_house), compile_world(one_room((4.0, 4.0)))]
    grids, sem = PackedGrids.from_worlds(worlds), pack_semantic(worlds)
    env = np.array([0, 1, 0, 1])
    x, z = np.array([12.5, 2.0, 6.0, 1.0]), np.array([2.5, 2.0, 9.0, 3.0])
    yaw = np.array([90.0, 10.0, 200.0, 300.0])
    depth, classes = scan(grids, sem, env, x, z, yaw)
    assert depth.shape == (4, N_RAYS) and depth.dtype == np.float32 and classes.dtype == np.int64
    for i in range(4):
        d1, c1 = scan_world(worlds[env[i]], x[i], z[i], yaw[i])
        np.testing.assert_array_equal(depth[i], d1)
        np.testing.assert_array_equal(classes[i], c1)


def _agreement_with_reference(world, n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scan ``n`` random poses where the agent fits; per ray: depth within 2 cells of the reference,
    same class as the reference, and the depths."""
    rng = np.random.default_rng(seed)
    rows, cols = np.nonzero(world.grid.clearance >= AGENT_RADIUS)
    pick = rng.integers(len(rows), size=n)
    xs, zs = world.grid.cell_center(rows[pick], cols[pick])
    xs, zs = xs + rng.uniform(-0.02, 0.02, n), zs + rng.uniform(-0.02, 0.02, n)
    yaws = rng.uniform(0.0, 360.0, n)
    grids, sem = PackedGrids.from_worlds([world]), pack_semantic([world])
    depth, classes = scan(grids, sem, np.zeros(n, np.int64), xs, zs, yaws, runs=pack_runs([world]))
    close, same = [], []
    for i in range(n):
        ref_d, ref_c = reference_scan(world, xs[i], zs[i], yaws[i])
        close.append(np.abs(depth[i] - ref_d) * MAX_RANGE <= 2 * RES)
        same.append(classes[i] == ref_c)
    return np.concatenate(close), np.concatenate(same), depth


def test_numba_scan_agrees_with_a_slow_reference_on_random_poses(real_house):
    close, same, depth = _agreement_with_reference(compile_world(real_house), 60, 0)
    assert close.mean() >= 0.995, f"only {close.mean():.4f} of rays within 2 cells"
    assert same.mean() >= 0.99, f"only {same.mean():.4f} of rays agree on the class"
    assert np.all(depth >= 0) and np.all(depth <= 1)


def test_numba_scan_agrees_with_a_slow_reference_in_a_cluttered_house():
    from adaptenv.bench.sim import clutter_house

    world = compile_world(clutter_house(200, seed=0))
    close, same, depth = _agreement_with_reference(world, 60, 1)
    assert (depth < 1.0).mean() > 0.5, "the clutter should stop most rays within range"
    assert close.mean() >= 0.995, f"only {close.mean():.4f} of rays within 2 cells"
    assert same.mean() >= 0.99, f"only {same.mean():.4f} of rays agree on the class"


def _free(blocked: np.ndarray, c0: int, r0: int, c1: int, r1: int) -> bool:
    """Whether the cells [r0, r1) x [c0, c1) are on the raster and free (off the raster counts as blocked)."""
    h, w = blocked.shape
    return 0 <= r0 < r1 <= h and 0 <= c0 < c1 <= w and not blocked[r0:r1, c0:c1].any()


def test_free_runs_are_maximal_free_rectangles_through_each_cell():
    rng = np.random.default_rng(3)
    blocked = rng.random((13, 17)) < 0.15
    semantic = rng.integers(1, 60, size=(13, 17)).astype(np.int16)
    runs = free_runs(blocked, semantic)
    ids = runs.ids.reshape(13, 17, 2)
    table = runs.table.reshape(-1, 4).astype(int)
    assert runs.ids.dtype == np.uint16 and np.all(table[0] == 0)
    for r in range(13):
        for c in range(17):
            if blocked[r, c]:
                assert ids[r, c, 0] == 0 and ids[r, c, 1] == semantic[r, c]  # obstacle cells hold their class
                continue
            for along in (0, 1):  # 0: the row rectangle, 1: the column rectangle
                c0, r0, c1, r1 = table[ids[r, c, along]]
                assert c0 <= c < c1 and r0 <= r < r1 and _free(blocked, c0, r0, c1, r1), (r, c, along)
                if along == 0:  # the whole free run of the row, then as many rows as stay free
                    assert not _free(blocked, c0 - 1, r, c1, r + 1) and not _free(blocked, c0, r, c1 + 1, r + 1)
                else:
                    assert not _free(blocked, c, r0 - 1, c + 1, r1) and not _free(blocked, c, r0, c + 1, r1 + 1)
                assert not _free(blocked, c0, r0, c1, r1 + 1) and not _free(blocked, c0, r0, c1 + 1, r1)
                assert not _free(blocked, c0, r0 - 1, c1, r1) and not _free(blocked, c0 - 1, r0, c1, r1)


def test_free_runs_switch_to_uint32_ids_when_uint16_cannot_number_the_rectangles():
    blocked = (np.add.outer(np.arange(260), np.arange(260)) % 2).astype(bool)  # a checkerboard: 1x1 runs
    runs = free_runs(blocked, np.ones(blocked.shape, np.int16))
    assert runs.ids.dtype == np.uint32 and len(runs.table) // 4 == 1 + 2 * int((~blocked).sum())
    ids, table = runs.ids.reshape(260, 260, 2), runs.table.reshape(-1, 4)
    for r, c in [(0, 0), (17, 41), (259, 1)]:
        for along in (0, 1):
            assert tuple(table[ids[r, c, along]]) == (c, r, c + 1, r + 1)


def _exact_first_hit(blocked: np.ndarray, u: float, v: float, du: float, dv: float) -> tuple[float, int, int]:
    """Distance (cells) at which a ray enters its first blocked or off-raster cell, by an exact
    cell-by-cell walk (Amanatides and Woo), and that cell's (row, col)."""
    h, w = blocked.shape
    col, row = math.floor(u), math.floor(v)
    step_c, step_r = (1 if du > 0 else -1), (1 if dv > 0 else -1)
    next_c = ((col + (du > 0)) - u) / du if du != 0 else math.inf
    next_r = ((row + (dv > 0)) - v) / dv if dv != 0 else math.inf
    t = 0.0
    while 0 <= row < h and 0 <= col < w and not blocked[row, col]:
        if next_c < next_r:
            t, col, next_c = next_c, col + step_c, next_c + abs(1 / du)
        else:
            t, row, next_r = next_r, row + step_r, next_r + abs(1 / dv)
    return t, row, col


def test_scan_stops_exactly_where_a_cell_walk_enters_the_first_obstacle():
    """The jumps change speed, not results: depth and class equal an exact cell-by-cell walk's."""
    from adaptenv.bench.sim import clutter_house

    world = compile_world(clutter_house(200, seed=0))
    g = world.grid
    rng = np.random.default_rng(4)
    rows, cols = np.nonzero(g.clearance >= AGENT_RADIUS)
    pick = rng.integers(len(rows), size=40)
    for row, col in zip(rows[pick], cols[pick], strict=True):
        u, v = col + rng.random(), row + rng.random()
        yaw = float(rng.uniform(0.0, 360.0))
        depth, classes = scan_world(world, g.x0 + u * g.resolution, g.z0 + v * g.resolution, yaw)
        for k in range(N_RAYS):
            a = math.radians(yaw + RAY_OFFSETS_DEG[k])
            t, hr, hc = _exact_first_hit(g.blocked, u, v, math.sin(a), math.cos(a))
            if t * g.resolution > MAX_RANGE:
                assert depth[k] == 1.0 and classes[k] == CLASS_NONE
                continue
            assert abs(depth[k] * MAX_RANGE - t * g.resolution) < 1e-4 * g.resolution, (k, depth[k], t)
            inside = 0 <= hr < g.shape[0] and 0 <= hc < g.shape[1]
            assert classes[k] == (world.semantic[hr, hc] if inside else CLASS_WALL)
