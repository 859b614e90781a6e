"""The map memory (``sim.egomap``): dead-reckoned pose, scan and bump marking, agreement with the
explorer's privileged-pose map, egocentric crops, per-agent reset and the Gymnasium ``map`` option."""

from __future__ import annotations

import math
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import adaptenv  # noqa: F401  (registers the ids)
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.teachers import ExplorerTeacher
from adaptenv.sim.egomap import (
    CELL,
    CROP,
    FREE,
    MAP_CHANNELS,
    OBSTACLE,
    SEEN,
    TARGET,
    VISITED,
    EgoMap,
    unpack,
)
from adaptenv.sim.env import NavEnv, NavVectorEnv, observation_space
from adaptenv.sim.spec import (
    END,
    MAX_RANGE,
    MOVE_AHEAD,
    MOVE_BACK,
    N_ACTIONS,
    N_RAYS,
    NO_ACTION,
    ROTATE_LEFT,
    ROTATE_RIGHT,
    class_id,
)
from adaptenv.sim.task import Episode
from adaptenv.sim.vector import BatchSim, EpisodeSampler
from adaptenv.sim.world import compile_world
from tests.sim.helpers import LOW_TARGET, Obj, one_room

BIN_CENTRE, BIN_HALF = (5.5, 1.5), (0.25, 0.17)
"""The garbage can of ``target_room``: centre and half extents (x, z) in metres."""


@pytest.fixture(scope="module")
def tiny_worlds():
    return load_house_set("preset:tiny").worlds


@pytest.fixture(scope="module")
def target_room():
    """A 6 x 3 m room with a garbage can at its east end."""
    return compile_world(one_room((6.0, 3.0), objects=[Obj(LOW_TARGET, *BIN_CENTRE)]), name="bin room")


@pytest.fixture(scope="module")
def long_room():
    """A 12 x 4 m empty room: from (6, 2.5) a wall 1.5 m north (+z), none within range east (+x)."""
    return compile_world(one_room((12.0, 4.0)), name="long room")


def _world_pose(pose: np.ndarray, start: tuple[float, float, float]) -> tuple[float, float, float]:
    """World (x, z, yaw) of a map-frame pose, given the true start pose (the frame of ``EgoMap.to_world``)."""
    t = math.radians(start[2])
    x = start[0] + pose[0] * math.cos(t) + pose[1] * math.sin(t)
    z = start[1] - pose[0] * math.sin(t) + pose[1] * math.cos(t)
    return x, z, (start[2] + pose[2]) % 360.0


def _angle_gap(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


def _cell_of(emap: EgoMap, x: float, z: float) -> tuple[int, int]:
    """(row, col) of the fine cell holding map-frame point (x, z)."""
    n = emap.size
    return int(math.floor(z / emap.cell)) + n // 2, int(math.floor(x / emap.cell)) + n // 2


def _sim(worlds, episodes: list[Episode], env_idx=None, max_steps: int = 1000) -> tuple[BatchSim, dict]:
    sim = BatchSim(worlds, max_steps=max_steps, threads=1)
    obs, _ = sim.reset(episodes, env_idx)
    return sim, obs


def _fine(emap: EgoMap, i: int = 0) -> np.ndarray:
    """uint8 (4, CROP, CROP): agent i's fine window channels (free, obstacle, target, visited)."""
    return unpack(emap.crop()[i], dtype=np.uint8)[:4]


# -- pose ------------------------------------------------------------------------------------------------


def test_integrated_pose_is_the_true_pose_along_random_actions(tiny_worlds):
    rng = np.random.default_rng(0)
    n = 8
    episodes, envs = EpisodeSampler(tiny_worlds).draw(rng, n)
    sim, obs = _sim(tiny_worlds, episodes, envs)
    emap = EgoMap(n)
    emap.update(obs, np.ones(n, bool))
    collisions = 0
    for _ in range(200):
        # moves twice as likely as each turn, so that many moves are blocked
        obs, *_ = sim.step(rng.choice([MOVE_AHEAD, MOVE_AHEAD, MOVE_BACK, 2, 3, 4, 5], size=n))
        emap.update(obs, np.zeros(n, bool))
        collisions += int(obs["collided"].sum())
        for i, ep in enumerate(episodes):
            x, z, yaw = _world_pose(emap.pose[i], ep.start)
            assert abs(x - sim.x[i]) < 1e-9 and abs(z - sim.z[i]) < 1e-9
            assert _angle_gap(yaw, sim.yaw[i]) < 1e-9
    assert collisions > 20, "the trajectory should include blocked moves"
    for i, ep in enumerate(episodes):  # to_world agrees: the agent's own cell holds its true position
        row, col = _cell_of(emap, *emap.pose[i, :2])
        centre = emap.to_world(i, ep.start)[row, col]
        assert math.hypot(centre[0] - sim.x[i], centre[1] - sim.z[i]) <= CELL / math.sqrt(2) + 1e-9
        assert emap.grid[i, row, col] & VISITED


def _drive_into_a_wall(worlds) -> tuple[BatchSim, EgoMap, dict]:
    """An agent moved ahead from a sampled start until a move is blocked (the sim and map after that step)."""
    rng = np.random.default_rng(3)
    episodes, envs = EpisodeSampler(worlds).draw(rng, 1)
    sim, obs = _sim(worlds, episodes, envs)
    emap = EgoMap(1)
    emap.update(obs, np.ones(1, bool))
    for _ in range(200):
        before_true, before_map = (sim.x[0], sim.z[0], sim.yaw[0]), emap.pose[0].copy()
        obs, *_ = sim.step(np.array([MOVE_AHEAD]))
        emap.update(obs, np.zeros(1, bool))
        if obs["collided"][0]:
            assert (sim.x[0], sim.z[0], sim.yaw[0]) == before_true
            np.testing.assert_array_equal(emap.pose[0], before_map)
            return sim, emap, obs
    raise AssertionError("no blocked move within 200 steps")


def test_a_blocked_move_keeps_the_pose_and_marks_the_bumped_cell(tiny_worlds):
    sim, emap, _ = _drive_into_a_wall(tiny_worlds)
    x, z, yaw = emap.pose[0]
    t = math.radians(yaw)
    row, col = _cell_of(emap, x + 0.3 * math.sin(t), z + 0.3 * math.cos(t))
    assert emap.grid[0, row, col] & OBSTACLE


@pytest.mark.parametrize("action, sign", [(MOVE_AHEAD, 1.0), (MOVE_BACK, -1.0)])
def test_the_bump_alone_marks_one_obstacle_cell_ahead_or_behind(action, sign):
    """With a scan that hits nothing, a blocked move is the only obstacle: 0.3 m ahead (or behind)."""
    emap = EgoMap(1)
    clear_scan = {"depth": np.ones((1, N_RAYS), np.float32), "semantic": np.zeros((1, N_RAYS), np.int64),
                  "target": np.array([4])}
    emap.update({**clear_scan, "prev_action": np.array([NO_ACTION]), "collided": np.array([0])}, np.ones(1, bool))
    emap.update({**clear_scan, "prev_action": np.array([ROTATE_RIGHT]), "collided": np.array([0])}, np.zeros(1, bool))
    assert not (emap.grid & OBSTACLE).any()
    emap.update({**clear_scan, "prev_action": np.array([action]), "collided": np.array([1])}, np.zeros(1, bool))
    np.testing.assert_array_equal(emap.pose[0], [0.0, 0.0, 30.0])
    rows, cols = np.nonzero(emap.grid[0] & OBSTACLE)
    t = math.radians(30.0)
    assert list(zip(rows, cols, strict=True)) == [_cell_of(emap, sign * 0.3 * math.sin(t), sign * 0.3 * math.cos(t))]
    assert np.count_nonzero(emap.coarse[0] & OBSTACLE) == 1


# -- the map against the explorer's --------------------------------------------------------------------


def _blocks(seen: np.ndarray, f: int = 4) -> np.ndarray:
    """bool: the explorer's seen 0.05 m cells as world-aligned 0.2 m blocks (any cell seen)."""
    h, w = seen.shape
    pad = np.zeros((-(-h // f) * f, -(-w // f) * f), dtype=bool)
    pad[:h, :w] = seen
    return pad.reshape(pad.shape[0] // f, f, pad.shape[1] // f, f).any(axis=(1, 3))


def _dilate(mask: np.ndarray) -> np.ndarray:
    """``mask`` grown by one cell (8-neighbourhood)."""
    p = np.pad(mask, 1)
    h, w = mask.shape
    return np.logical_or.reduce([p[1 + dr:1 + dr + h, 1 + dc:1 + dc + w] for dr in (-1, 0, 1) for dc in (-1, 0, 1)])


def _lookup(mask: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """mask[rows, cols], False off the mask."""
    inside = (rows >= 0) & (rows < mask.shape[0]) & (cols >= 0) & (cols < mask.shape[1])
    out = np.zeros(rows.shape, dtype=bool)
    out[inside] = mask[rows[inside], cols[inside]]
    return out


def _agreement(emap: EgoMap, i: int, start, seen: np.ndarray, grid) -> tuple[float, float]:
    """(share of the EgoMap's seen cells next to explorer-seen blocks, share of those blocks next to EgoMap-seen cells)."""
    mine = (emap.grid[i] & SEEN) != 0
    theirs = _blocks(seen)
    centres = emap.to_world(i, start)[mine]
    ours_in_theirs = _lookup(_dilate(theirs), np.floor((centres[:, 1] - grid.z0) / CELL).astype(int),
                             np.floor((centres[:, 0] - grid.x0) / CELL).astype(int))
    rows, cols = np.nonzero(theirs)
    dx, dz = grid.x0 + (cols + 0.5) * CELL - start[0], grid.z0 + (rows + 0.5) * CELL - start[1]
    t = math.radians(start[2])
    mx, mz = math.cos(t) * dx - math.sin(t) * dz, math.sin(t) * dx + math.cos(t) * dz
    n = emap.size
    theirs_in_ours = _lookup(_dilate(mine), np.floor(mz / CELL).astype(int) + n // 2,
                             np.floor(mx / CELL).astype(int) + n // 2)
    return float(ours_in_theirs.mean()), float(theirs_in_ours.mean())


def test_the_map_matches_the_explorers_map_of_the_same_trajectory(tiny_worlds):
    """Same observations into the EgoMap (dead-reckoned) and the explorer (true pose): the same cells seen,
    to one 0.2 m cell; with the start yaw off by 30 degrees the agreement collapses."""
    n = 6
    episodes, envs = EpisodeSampler(tiny_worlds).draw(np.random.default_rng(0), n)
    sim, obs = _sim(tiny_worlds, episodes, envs)  # no truncation: a finished agent keeps prev_action END
    teacher, emap, first = ExplorerTeacher(sim), EgoMap(n), np.ones(n, bool)
    for _ in range(120):
        emap.update(obs, first)
        actions = teacher.label(obs, first)
        first[:] = False
        obs, *_ = sim.step(actions)
    for i, ep in enumerate(episodes):
        seen, grid = teacher.explorer._mem[i].seen, tiny_worlds[envs[i]].grid
        assert seen.sum() > 1000 and (emap.grid[i] & SEEN).sum() > 100
        assert min(_agreement(emap, i, ep.start, seen, grid)) >= 0.95
        x, z, yaw = ep.start
        assert min(_agreement(emap, i, (x, z, yaw + 30.0), seen, grid)) < 0.85


# -- what the scan marks ---------------------------------------------------------------------------------


def test_target_sightings_are_marked_on_the_target(target_room):
    """Facing the garbage can from 2.5 m: TARGET cells (all obstacles) lie on the can, and only for its class."""
    start = (3.0, 1.5, 90.0)
    sim, obs = _sim([target_room], [Episode("GarbageCan", start)])
    assert (obs["semantic"][0] == class_id("GarbageCan")).sum() >= 3
    emap = EgoMap(1)
    emap.update(obs, np.ones(1, bool))
    targets = (emap.grid[0] & TARGET) != 0
    assert targets.sum() >= 1 and not (targets & ((emap.grid[0] & OBSTACLE) == 0)).any()
    centres = emap.to_world(0, start)[targets]
    gap_x = np.abs(centres[:, 0] - BIN_CENTRE[0]) - BIN_HALF[0]
    gap_z = np.abs(centres[:, 1] - BIN_CENTRE[1]) - BIN_HALF[1]
    assert (np.hypot(np.maximum(gap_x, 0), np.maximum(gap_z, 0)) <= CELL / math.sqrt(2)).all()
    other = EgoMap(1)
    other.update({**obs, "target": np.array([class_id("Fridge")])}, np.ones(1, bool))
    assert not (other.grid & TARGET).any()
    np.testing.assert_array_equal(other.grid & ~np.uint8(TARGET), emap.grid & ~np.uint8(TARGET))


def test_rays_mark_free_cells_up_to_the_hit_and_the_hit_as_obstacle():
    """Every ray hitting a wall at 1.5 m: the cells straight ahead are free up to it, an obstacle at it."""
    emap = EgoMap(1)
    depth = np.full((1, N_RAYS), 1.5 / MAX_RANGE, np.float32)
    emap.update({"depth": depth, "semantic": np.ones((1, N_RAYS), np.int64), "target": np.array([4]),
                 "prev_action": np.array([NO_ACTION]), "collided": np.array([0])}, np.ones(1, bool))
    column = emap.grid[0, :, emap.size // 2]  # x in [0, 0.2): just right of straight ahead
    ahead = column[emap.size // 2:]
    assert (ahead[:7] & FREE).all() and (ahead[7] & OBSTACLE) and not (ahead[8:] & SEEN).any()
    assert not (ahead[:7] & OBSTACLE).any()


# -- crops -----------------------------------------------------------------------------------------------


def test_the_crop_is_egocentric(long_room):
    """A wall straight ahead is in the upper half of the fine window, centre columns; after a right turn
    of 90 degrees it is on the left, beside the agent."""
    sim, obs = _sim([long_room], [Episode("GarbageCan", (6.0, 2.5, 0.0))])
    emap = EgoMap(1)
    emap.update(obs, np.ones(1, bool))
    wall = _fine(emap)[1]
    rows, cols = np.nonzero(wall)
    assert rows.size and (rows < CROP // 2).all()
    centre = np.nonzero(wall[:, CROP // 2 - 1:CROP // 2 + 1].any(axis=1))[0]
    assert centre.tolist() and set(centre.tolist()) <= {CROP // 2 - 8, CROP // 2 - 9}  # 1.5-1.8 m ahead
    for _ in range(3):
        obs, *_ = sim.step(np.array([ROTATE_RIGHT]))
        emap.update(obs, np.zeros(1, bool))
    wall = _fine(emap)[1]
    assert not wall[:CROP // 2, CROP // 2 - 2:CROP // 2 + 2].any()  # nothing within range ahead now
    left = np.nonzero(wall[CROP // 2 - 1:CROP // 2 + 1].any(axis=0))[0]
    assert left.tolist() and set(left.tolist()) <= {CROP // 2 - 8, CROP // 2 - 9}


def test_crops_at_right_angles_are_rotations_of_each_other(tiny_worlds):
    """Turning right by 90 degrees rotates the window a quarter turn counter-clockwise (fine and coarse)."""
    episodes, envs = EpisodeSampler(tiny_worlds).draw(np.random.default_rng(1), 1)
    sim, obs = _sim(tiny_worlds, episodes, envs)
    emap = EgoMap(1)
    emap.update(obs, np.ones(1, bool))
    for a in [ROTATE_LEFT] * 6 + [MOVE_AHEAD] * 4 + [ROTATE_RIGHT] * 3 + [MOVE_AHEAD] * 3:
        obs, *_ = sim.step(np.array([a]))
        emap.update(obs, np.zeros(1, bool))
    emap.pose[0] = [0.0, 0.0, 0.0]  # a cell corner, so every pixel centre falls inside a cell
    views = []
    for yaw in (0.0, 90.0, 180.0, 270.0):
        emap.pose[0, 2] = yaw
        views.append(emap.crop()[0])
    assert (views[0] & 0x0F).any() and (views[0] >> 4).any()
    for k in range(1, 4):
        np.testing.assert_array_equal(views[k], np.rot90(views[0], k))


def test_coarse_cells_are_or_of_fine_cells_and_the_coarse_window_matches_them(tiny_worlds):
    episodes, envs = EpisodeSampler(tiny_worlds).draw(np.random.default_rng(2), 2)
    sim, obs = _sim(tiny_worlds, episodes, envs)
    emap = EgoMap(2)
    emap.update(obs, np.ones(2, bool))
    for a in [MOVE_AHEAD, ROTATE_RIGHT] * 10:
        obs, *_ = sim.step(np.full(2, a))
        emap.update(obs, np.zeros(2, bool))
    f = emap.coarse_factor
    n = emap.size // f
    expected = np.bitwise_or.reduce(np.bitwise_or.reduce(emap.grid.reshape(2, n, f, n, f), axis=4), axis=2)
    np.testing.assert_array_equal(emap.coarse, expected)


def test_the_map_size_must_keep_the_coarse_grid_centred():
    """The coarse grid's centre is the fine grid's only when size / 2 is a multiple of coarse (fixed bug:
    size 40 with coarse 8 was accepted and drew the coarse window one cell off)."""
    with pytest.raises(ValueError, match="size"):
        EgoMap(1, size=40, coarse=8)
    emap = EgoMap(1, size=48, coarse=8, crop=8)
    emap.grid[0, 29, 23] = emap.coarse[0, 3, 2] = OBSTACLE  # x in [-0.2, 0), z in [1.0, 1.2): ahead, a bit left
    coarse = unpack(emap.crop()[0], dtype=np.uint8)[4 + 1]
    assert np.argwhere(coarse).tolist() == [[3, 3]]  # the coarse pixel ahead-left of the centre


# -- reset -------------------------------------------------------------------------------------------------


def test_reset_empties_only_the_given_agents(tiny_worlds):
    n = 4
    episodes, envs = EpisodeSampler(tiny_worlds).draw(np.random.default_rng(4), n)
    sim, obs = _sim(tiny_worlds, episodes, envs)
    emap = EgoMap(n)
    emap.update(obs, np.ones(n, bool))
    for _ in range(5):
        obs, *_ = sim.step(np.full(n, MOVE_AHEAD))
        emap.update(obs, np.zeros(n, bool))
    kept = emap.take([0, 2])
    emap.reset([1, 3])
    assert not emap.grid[[1, 3]].any() and not emap.coarse[[1, 3]].any() and not emap.pose[[1, 3]].any()
    np.testing.assert_array_equal(emap.grid[[0, 2]], kept.grid)
    np.testing.assert_array_equal(emap.coarse[[0, 2]], kept.coarse)
    np.testing.assert_array_equal(emap.pose[[0, 2]], kept.pose)
    assert kept.grid.any()


# -- the Gymnasium option -----------------------------------------------------------------------------------


def _fresh_map(obs: dict, i: int | None = None) -> np.ndarray:
    """The unpacked crop of a new map that saw only ``obs`` (slot i of a batch, or a single observation)."""
    one = {k: np.asarray(v)[None] if i is None else np.asarray(v)[i:i + 1] for k, v in obs.items() if k != "map"}
    emap = EgoMap(1)
    emap.update(one, np.ones(1, bool))
    return unpack(emap.crop()[0], dtype=np.uint8)


def test_the_default_observation_has_no_map():
    assert "map" not in observation_space().spaces
    assert observation_space(map=True)["map"] == gymnasium.spaces.Box(0, 1, (MAP_CHANNELS, CROP, CROP), np.uint8)


def test_env_map_observations_are_in_the_space_and_reset_with_the_episode(target_room):
    env = gymnasium.make("adaptenv/ObjectNav-v0", houses=[target_room], map=True, max_steps=30)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs) and obs["map"].dtype == np.uint8
    np.testing.assert_array_equal(obs["map"], _fresh_map(obs))
    for a in [MOVE_AHEAD, ROTATE_LEFT, MOVE_AHEAD, ROTATE_RIGHT] * 4:
        obs, *_ = env.step(a)
        assert env.observation_space.contains(obs)
    assert not np.array_equal(obs["map"], _fresh_map(obs))  # the map remembers earlier scans
    obs, _ = env.reset(seed=1)
    np.testing.assert_array_equal(obs["map"], _fresh_map(obs))


def test_env_check_passes_with_the_map(real_house_path):
    env = gymnasium.make("adaptenv/ObjectNav-v0", houses=[real_house_path], map=True, render_mode="rgb_array")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    assert [str(w.message) for w in caught] == []


def test_env_map_is_unchanged_by_steps_after_the_end(target_room):
    env = NavEnv(houses=[target_room], map=True, max_steps=2)
    env.reset(seed=0, options={"target_type": "GarbageCan", "start": (3.0, 1.5, 270.0)})  # 3 m free ahead
    env.step(MOVE_AHEAD)
    obs, _, _, truncated, _ = env.step(MOVE_AHEAD)
    assert truncated and obs["prev_action"] == MOVE_AHEAD and obs["collided"] == 0
    again, *_ = env.step(MOVE_AHEAD)  # ignored by the simulator: the map must not move either
    np.testing.assert_array_equal(again["map"], obs["map"])


def test_vector_env_autoreset_starts_the_slots_map_afresh(tiny_worlds):
    venv = gymnasium.make_vec("adaptenv/ObjectNav-v0", num_envs=3, vectorization_mode="vector_entry_point",
                              houses=tiny_worlds, map=True, max_steps=50)
    assert isinstance(venv.unwrapped, NavVectorEnv)
    obs, _ = venv.reset(seed=0)
    assert venv.observation_space.contains(obs) and obs["map"].shape == (3, MAP_CHANNELS, CROP, CROP)
    for i in range(3):
        np.testing.assert_array_equal(obs["map"][i], _fresh_map(obs, i))
    for _ in range(4):
        obs, *_ = venv.step(np.array([MOVE_AHEAD, ROTATE_LEFT, ROTATE_RIGHT]))
    obs, _, terminated, *_ = venv.step(np.array([END, ROTATE_LEFT, ROTATE_RIGHT]))
    assert terminated.tolist() == [True, False, False]
    obs, *_ = venv.step(np.array([MOVE_AHEAD, ROTATE_LEFT, ROTATE_RIGHT]))  # slot 0 autoresets
    assert obs["prev_action"][0] == NO_ACTION and venv.observation_space.contains(obs)
    np.testing.assert_array_equal(obs["map"][0], _fresh_map(obs, 0))
    for i in (1, 2):  # the others keep what they saw while turning
        assert obs["map"][i].sum() > _fresh_map(obs, i).sum()
    venv.close()


def random_obs(rng: np.random.Generator, batch: int, first: bool) -> dict[str, np.ndarray]:
    """Synthetic scans (depth in [0, 1] of the range) and actions; NO_ACTION at an episode's start."""
    return {"depth": rng.uniform(0.05, 1.0, (batch, N_RAYS)).astype(np.float32),
            "semantic": rng.integers(0, 4, (batch, N_RAYS)), "target": rng.integers(0, 4, batch),
            "prev_action": np.full(batch, NO_ACTION) if first else rng.integers(0, N_ACTIONS - 1, batch),
            "collided": rng.integers(0, 2, batch)}


def counted(emap: EgoMap) -> np.ndarray:
    return np.count_nonzero(emap.grid & SEEN, axis=(1, 2))


def test_seen_counts_match_the_marked_cells():
    rng = np.random.default_rng(0)
    emap = EgoMap(5)
    emap.update(random_obs(rng, 5, first=True), np.ones(5, bool))
    last = emap.seen_counts()
    for step in range(20):
        first = np.arange(5) == step % 7  # some agents start new episodes on the way
        emap.update(random_obs(rng, 5, first=False), first)
        seen = emap.seen_counts()
        assert np.array_equal(seen, counted(emap))
        assert (seen[~first] >= last[~first]).all()  # within an episode the count only grows
        last = seen
    emap.reset(np.array([1, 3]))
    assert np.array_equal(emap.seen_counts(), counted(emap)) and (emap.seen_counts()[[1, 3]] == 0).all()
    part = emap.take(np.array([4, 0]))
    assert np.array_equal(part.seen_counts(), emap.seen_counts()[[4, 0]])
    counts = emap.seen_counts()
    counts[:] = -1  # a copy: the map's own count is untouched
    assert np.array_equal(emap.seen_counts(), counted(emap))


def _reference_update(emap: EgoMap, obs: dict[str, np.ndarray], first: np.ndarray) -> None:
    """The module docstring's marking in plain Python: every half-cell sample of every (densified) ray marked,
    nothing skipped."""
    from adaptenv.sim.egomap import _BUMP, _MOVE, _OFFSETS, _YAW, COARSE, INTERPOLATE, SIZE

    def mark(i, x, z, bits):
        row, col = int(math.floor(z / CELL)) + SIZE // 2, int(math.floor(x / CELL)) + SIZE // 2
        if 0 <= row < SIZE and 0 <= col < SIZE:
            emap.seen[i] += int(emap.grid[i, row, col] & SEEN == 0 and bits & SEEN != 0)
            emap.grid[i, row, col] |= bits
            emap.coarse[i, row // COARSE, col // COARSE] |= bits

    for i in range(emap.batch):
        a = int(obs["prev_action"][i])
        if first[i] or a == NO_ACTION:
            emap.reset(np.array([i]))
        elif _MOVE[a] != 0.0:
            t, d = math.radians(emap.pose[i, 2]), _MOVE[a]
            if obs["collided"][i]:
                s = 1.0 if d > 0 else -1.0
                mark(i, emap.pose[i, 0] + s * _BUMP * math.sin(t), emap.pose[i, 1] + s * _BUMP * math.cos(t), OBSTACLE)
            else:
                emap.pose[i, :2] += (d * math.sin(t), d * math.cos(t))
        if not (first[i] or a == NO_ACTION):
            emap.pose[i, 2] = (emap.pose[i, 2] + _YAW[a]) % 360.0
        x, z, yaw = emap.pose[i]
        mark(i, x, z, VISITED | FREE)
        depth, sem = obs["depth"][i].astype(np.float64) * MAX_RANGE, obs["semantic"][i]
        for k in range(N_RAYS):
            for s in range(INTERPOLATE + 1 if k < N_RAYS - 1 else 1):
                fr = s / (INTERPOLATE + 1)
                dd = depth[k] if s == 0 else min(depth[k], depth[k + 1])
                off = _OFFSETS[k] + (fr * (_OFFSETS[k + 1] - _OFFSETS[k]) if s else 0.0)
                cls = sem[k] if s == 0 or sem[k] == sem[k + 1] else -1
                t = math.radians(yaw + off)
                for j in range(int(dd / (0.5 * CELL)) + 1):
                    mark(i, x + j * 0.5 * CELL * math.sin(t), z + j * 0.5 * CELL * math.cos(t), FREE)
                if dd < MAX_RANGE - 1e-6:
                    r = dd + 0.25 * CELL
                    mark(i, x + r * math.sin(t), z + r * math.cos(t), OBSTACLE | TARGET if cls == obs["target"][i]
                         else OBSTACLE)


def test_the_kernel_marks_exactly_what_every_sample_of_every_ray_would():
    """The compiled update skips samples whose cell it has just marked and cells that hold the bits already; the
    maps, coarse maps, seen counts and poses are those of marking every sample."""
    rng = np.random.default_rng(7)
    fast, slow = EgoMap(3), EgoMap(3)
    for k in range(12):
        obs, first = random_obs(rng, 3, first=k == 0), np.arange(3) == (k % 5) - 1
        fast.update(obs, first)
        _reference_update(slow, obs, first)
    for mine, theirs in ((fast.grid, slow.grid), (fast.coarse, slow.coarse), (fast.seen, slow.seen)):
        np.testing.assert_array_equal(mine, theirs)
    np.testing.assert_allclose(fast.pose, slow.pose, atol=1e-9)
    assert (fast.seen > 50).all()


def test_maps_and_crops_do_not_depend_on_the_thread_count():
    """The kernels run agents in parallel; one thread and all of numba's give the same maps, poses and crops."""
    import numba

    rng = np.random.default_rng(4)
    trace = [random_obs(rng, 7, first=k == 0) for k in range(15)]
    results = []
    before = numba.get_num_threads()
    try:
        for threads in (1, before):
            numba.set_num_threads(threads)
            emap = EgoMap(7)
            for k, obs in enumerate(trace):
                emap.update(obs, np.full(7, k == 0))
            results.append((emap.grid.copy(), emap.coarse.copy(), emap.pose.copy(), emap.seen.copy(), emap.crop()))
    finally:
        numba.set_num_threads(before)
    assert all(np.array_equal(a, b) for a, b in zip(*results, strict=True))
    assert results[0][0].any()
