"""The depth-and-semantics scan: known distances and classes, range, ray order, and a slow reference."""

from __future__ import annotations

import math

import numpy as np
import pytest

from adaptenv.sim.physics import PackedGrids
from adaptenv.sim.scan import (
    RAY_OFFSETS_DEG,
    free_squares,
    pack_semantic,
    pack_squares,
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
    depth, classes = scan(grids, sem, np.zeros(n, np.int64), xs, zs, yaws, squares=pack_squares([world]))
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


def _square_is_free(blocked: np.ndarray, r: int, c: int, su: int, sv: int, side: int) -> bool:
    """Whether the side x side square of cells cornered at (r, c), extending by (su, sv), is on the raster and free."""
    rs = [r + sv * k for k in range(side)]
    cs = [c + su * k for k in range(side)]
    if min(rs + cs) < 0 or max(rs) >= blocked.shape[0] or max(cs) >= blocked.shape[1]:
        return False  # cells off the raster count as obstacles
    return not blocked[np.ix_(rs, cs)].any()


def test_free_squares_are_the_largest_free_squares_in_each_quadrant():
    rng = np.random.default_rng(3)
    blocked = rng.random((13, 17)) < 0.15
    sq = free_squares(blocked)
    assert sq.shape == (4, 13, 17) and sq.dtype == np.uint8
    for q in range(4):
        su, sv = (-1 if q & 1 else 1), (-1 if q & 2 else 1)
        for r in range(13):
            for c in range(17):
                s = int(sq[q, r, c])
                if blocked[r, c]:
                    assert s == 0
                else:
                    assert _square_is_free(blocked, r, c, su, sv, s), (q, r, c, s)
                    assert not _square_is_free(blocked, r, c, su, sv, s + 1), (q, r, c, s)
