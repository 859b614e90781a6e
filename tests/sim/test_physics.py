"""Physics edge cases: walls and corners, agent-wide doorways, turning, tunnelling, doors and empty walls."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import ndimage

from adaptenv.sim.physics import _YAW_DELTA, PackedGrids, _step, fits, step_poses
from adaptenv.sim.spec import (
    AGENT_RADIUS,
    MOVE_AHEAD,
    MOVE_BACK,
    ROTATE_LEFT,
    ROTATE_LEFT_SMALL,
    ROTATE_RIGHT,
    ROTATE_RIGHT_SMALL,
)
from adaptenv.sim.world import compile_world
from tests.sim.helpers import one_room, two_rooms

RES = 0.05


class Agent:
    """One agent in one world, stepped through ``step_poses``."""

    def __init__(self, world, x: float, z: float, yaw: float) -> None:
        self.grids = PackedGrids.from_worlds([world])
        self.env = np.zeros(1, dtype=np.int64)
        self.x, self.z, self.yaw = np.array([x]), np.array([z]), np.array([yaw])

    def act(self, action: int) -> bool:
        return bool(step_poses(self.grids, self.env, self.x, self.z, self.yaw, np.array([action]))[0])

    @property
    def pose(self) -> tuple[float, float, float]:
        return float(self.x[0]), float(self.z[0]), float(self.yaw[0])


def raw_move(grids: PackedGrids, x: float, z: float, yaw: float, distance: float) -> tuple[float, float, bool]:
    """Call the numba kernel directly with an arbitrary move length (beyond the spec's 0.2 m)."""
    xs, zs, ys = np.array([x]), np.array([z]), np.array([yaw])
    moved = np.empty(1, dtype=np.bool_)
    move_delta = np.array([distance, 0, 0, 0, 0, 0, 0], dtype=np.float64)
    _step(grids.clearance, grids.offset, grids.height, grids.width, grids.x0, grids.z0, grids.resolution,
          np.zeros(1, np.int64), xs, zs, ys, np.zeros(1, np.int64), AGENT_RADIUS, _YAW_DELTA, move_delta, moved)
    return float(xs[0]), float(zs[0]), bool(moved[0])


def raster_world(blocked: np.ndarray, res: float = RES) -> SimpleNamespace:
    """A bare world around a hand-drawn obstacle raster (clearance as ``occupancy.rasterize`` computes it)."""
    dist = ndimage.distance_transform_edt(~blocked)
    clearance = np.maximum(dist * res - 0.5 * res, 0.0).astype(np.float32)
    clearance[blocked] = 0.0
    return SimpleNamespace(grid=SimpleNamespace(clearance=clearance, shape=blocked.shape, x0=0.0, z0=0.0,
                                                resolution=res))


@pytest.fixture(scope="module")
def room():
    return compile_world(one_room((4.0, 4.0)))


# -- walls and corners ---------------------------------------------------------------------------


def test_move_into_wall_is_blocked_and_the_agent_stays(room):
    agent = Agent(room, 2.0, 0.7, 180.0)  # facing -z, the wall at z = 0
    results = [agent.act(MOVE_AHEAD) for _ in range(6)]
    assert results[:2] == [True, True]
    assert not any(results[3:])
    stop = agent.pose
    assert AGENT_RADIUS <= stop[1] < AGENT_RADIUS + 0.2 + RES
    assert [agent.act(MOVE_AHEAD) for _ in range(3)] == [False] * 3
    assert agent.pose == stop


def test_sliding_into_a_corner_stops_short_of_both_walls(room):
    agent = Agent(room, 1.0, 1.0, 225.0)  # towards the corner (0, 0)
    collisions = sum(not agent.act(MOVE_AHEAD) for _ in range(10))
    x, z, _ = agent.pose
    assert collisions >= 5
    assert x >= AGENT_RADIUS and z >= AGENT_RADIUS
    assert x < AGENT_RADIUS + 0.2 and z < AGENT_RADIUS + 0.2
    assert fits(agent.grids, agent.env, agent.x, agent.z).all()


def test_moving_along_a_wall_at_a_grazing_angle(room):
    agent = Agent(room, 0.4, 3.5, 186.0)  # mostly -z, drifting 0.1 m per metre towards the wall x = 0
    trace = []
    for _ in range(17):
        moved = agent.act(MOVE_AHEAD)
        trace.append((moved, *agent.pose[:2]))
        assert room.grid.clearance_at(agent.x, agent.z)[0] >= AGENT_RADIUS
    assert trace[0][0]  # free at first
    assert all(t[1] >= AGENT_RADIUS for t in trace)
    # parallel to the wall one radius plus a cell away: every move succeeds
    along = Agent(room, AGENT_RADIUS + RES, 0.5, 0.0)
    assert all(along.act(MOVE_AHEAD) for _ in range(14))
    assert along.pose[0] == pytest.approx(AGENT_RADIUS + RES)


def test_backing_into_a_wall_is_blocked(room):
    agent = Agent(room, 2.0, 0.35, 0.0)  # facing +z, the wall behind
    assert agent.act(MOVE_BACK) is False
    assert agent.pose == (2.0, 0.35, 0.0)


# -- doorways ------------------------------------------------------------------------------------


def _passing_offsets(width: float, center: float) -> list[float]:
    """Offsets from the door's centre line (within +-2 cells) from which walking straight passes the door."""
    world = compile_world(two_rooms(width, door_center=center))
    out = []
    for dz in np.arange(-2 * RES, 2 * RES + 1e-9, RES / 4):
        agent = Agent(world, 3.0, center + dz, 90.0)
        for _ in range(10):
            agent.act(MOVE_AHEAD)
        if agent.pose[0] > 4.0 + AGENT_RADIUS:
            out.append(float(dz))
    return out


@pytest.mark.parametrize("center", [2.0, 2.013, 2.031, 2.047])
def test_doorway_two_cells_wider_than_the_agent_passes(center):
    # Raster tolerance: the wall's end pixels may eat up to a cell of the hole on each side, so a
    # doorway 2 * radius + 2 cells wide keeps a passage at least one cell wide, within a cell of the
    # centre line.
    offsets = _passing_offsets(2 * AGENT_RADIUS + 2 * RES, center)
    assert offsets and min(abs(d) for d in offsets) <= RES
    assert max(offsets) - min(offsets) >= 0.75 * RES - 1e-9  # a cell-wide window, sampled every 1/4 cell


@pytest.mark.parametrize("center", [2.0, 2.013, 2.031, 2.047])
def test_doorway_narrower_than_the_agent_blocks(center):
    assert _passing_offsets(2 * AGENT_RADIUS - 2 * RES, center) == []
    assert _passing_offsets(2 * AGENT_RADIUS, center) == []


# -- rotation ------------------------------------------------------------------------------------


def test_rotation_wraps_around(room):
    agent = Agent(room, 2.0, 2.0, 0.0)
    agent.act(ROTATE_LEFT)
    assert agent.pose[2] == 330.0
    agent = Agent(room, 2.0, 2.0, 0.0)
    for _ in range(12):
        assert agent.act(ROTATE_RIGHT)
    assert agent.pose == (2.0, 2.0, 0.0)
    for _ in range(60):
        agent.act(ROTATE_LEFT_SMALL)
    assert agent.pose[2] == pytest.approx(0.0, abs=1e-9) or agent.pose[2] == pytest.approx(360.0)
    assert 0.0 <= agent.pose[2] < 360.0


def test_yaw_stays_in_range_under_random_turns(room):
    rng = np.random.default_rng(0)
    agent = Agent(room, 2.0, 2.0, 0.0)
    for a in rng.choice([ROTATE_LEFT, ROTATE_RIGHT, ROTATE_LEFT_SMALL, ROTATE_RIGHT_SMALL], size=500):
        agent.act(int(a))
        assert 0.0 <= agent.pose[2] < 360.0
    assert agent.pose[:2] == (2.0, 2.0)


# -- tunnelling ----------------------------------------------------------------------------------


@pytest.mark.parametrize("distance", [0.05, 0.2, 0.37, 1.0, 3.0, 10.0])
def test_no_tunnelling_through_a_wall(distance):
    world = compile_world(two_rooms(None))  # sealed wall at x = 4
    grids = PackedGrids.from_worlds([world])
    for yaw in (60.0, 75.0, 90.0, 105.0, 120.0):
        x, z, moved = raw_move(grids, 3.7, 2.0, yaw, distance)
        assert x < 4.0 - AGENT_RADIUS + 1e-9
        if not moved:
            assert (x, z) == (3.7, 2.0)


@pytest.mark.parametrize("distance", [0.05, 0.2, 0.37, 1.0, 3.0, 10.0])
def test_no_tunnelling_through_a_one_cell_line_or_a_pole(distance):
    blocked = np.zeros((200, 200), dtype=bool)
    blocked[[0, -1], :] = blocked[:, [0, -1]] = True
    blocked[20:180, 100] = True  # a one-cell line at x in [5.00, 5.05)
    blocked[150, 50] = True  # a one-cell pole at (2.525, 7.525)
    grids = PackedGrids.from_worlds([raster_world(blocked)])
    rng = np.random.default_rng(1)
    for _ in range(200):
        x0, z0 = rng.uniform(3.0, 4.7), rng.uniform(2.0, 8.0)
        yaw = rng.uniform(0.0, 360.0)
        x, z, moved = raw_move(grids, x0, z0, yaw, distance)
        assert x < 5.0 - AGENT_RADIUS + 1e-9, (x0, z0, yaw)
    pole = np.array([2.525, 7.525])
    for yaw in np.arange(0.0, 360.0, 15.0):
        start = pole - 0.6 * np.array([math.sin(math.radians(yaw)), math.cos(math.radians(yaw))])
        x, z, moved = raw_move(grids, *start, yaw, distance)
        through = np.dot(np.array([x, z]) - pole, pole - start) > 0
        assert not through and np.hypot(x - pole[0], z - pole[1]) >= AGENT_RADIUS


# -- doors and empty walls -----------------------------------------------------------------------


def test_exterior_door_is_closed(real_house):
    world = compile_world(real_house)
    door = next(d for d in world.geometry.doors if not d.passable)
    (ax, az), (bx, bz) = door.p0, door.p1
    mx, mz = (ax + bx) / 2, (az + bz) / 2
    normal = np.array([-(bz - az), bx - ax]) / math.hypot(bx - ax, bz - az)
    inside = normal if world.grid.room_at(mx + 0.5 * normal[0], mz + 0.5 * normal[1]) else -normal
    yaw_out = math.degrees(math.atan2(-inside[0], -inside[1])) % 360.0
    grids = PackedGrids.from_worlds([world])
    sx, sz = mx + 0.5 * inside[0], mz + 0.5 * inside[1]
    assert fits(grids, np.zeros(1, np.int64), np.array([sx]), np.array([sz])).all()
    for distance in (0.4, 1.0, 3.0):  # from 0.5 m away, past the door line
        assert raw_move(grids, sx, sz, yaw_out, distance)[2] is False
    agent = Agent(world, sx, sz, yaw_out)
    for _ in range(10):
        agent.act(MOVE_AHEAD)
    assert world.grid.room_at(*agent.pose[:2]) is not None


def test_empty_walls_are_passable():
    house = two_rooms(None)
    sealed = compile_world(house)
    for wall in house.walls:
        xs = {round(p.x, 6) for p in wall.polygon}
        if xs == {4.0}:
            wall.empty = True
    opened = compile_world(house)
    for world, expect_through in ((sealed, False), (opened, True)):
        agent = Agent(world, 3.0, 2.0, 90.0)
        for _ in range(10):
            agent.act(MOVE_AHEAD)
        assert (agent.pose[0] > 4.0) is expect_through
