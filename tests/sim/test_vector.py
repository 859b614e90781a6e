"""BatchSim: shapes, reward shaping, termination and truncation, freezing and reset_at, equivalences."""

from __future__ import annotations

import numpy as np
import pytest

from adaptenv.errors import AdaptenvError
from adaptenv.sim import geodesic, task
from adaptenv.sim.physics import PackedGrids, step_poses
from adaptenv.sim.scan import pack_semantic, scan
from adaptenv.sim.spec import (
    END,
    MOVE_AHEAD,
    N_RAYS,
    NO_ACTION,
    ROTATE_LEFT,
    ROTATE_RIGHT,
    class_id,
)
from adaptenv.sim.task import Episode
from adaptenv.sim.vector import STEP_PENALTY, SUCCESS_REWARD, BatchSim
from adaptenv.sim.world import compile_world
from tests.sim.helpers import LOW_TARGET, Obj, one_room


@pytest.fixture(scope="module")
def real_world():
    from adaptenv.scene.house import load_house
    from tests.conftest import REAL_HOUSE

    return compile_world(load_house(REAL_HOUSE, validate=False), name="real")


@pytest.fixture(scope="module")
def small_world():
    """A 6 x 3 m room with a garbage can at its far end (x = 5.5)."""
    return compile_world(one_room((6.0, 3.0), objects=[Obj(LOW_TARGET, 5.5, 1.5)]), name="small")


def test_reset_and_step_shapes_across_houses(real_world, small_world):
    rng = np.random.default_rng(0)
    worlds = [real_world, small_world]
    eps = [task.sample_episode(worlds[i % 2], rng) for i in range(6)]
    sim = BatchSim(worlds)
    obs, info = sim.reset(eps)
    assert obs["depth"].shape == (6, N_RAYS) and obs["depth"].dtype == np.float32
    assert obs["semantic"].shape == (6, N_RAYS) and obs["semantic"].dtype == np.int64
    assert obs["prev_action"].tolist() == [NO_ACTION] * 6 and obs["collided"].tolist() == [0] * 6
    assert obs["target"].tolist() == [class_id(e.target_type) for e in eps]
    assert np.all(np.isfinite(info["geodesic"]))
    obs, reward, terminated, truncated, info = sim.step(np.full(6, ROTATE_LEFT))
    assert reward.shape == terminated.shape == truncated.shape == (6,)
    np.testing.assert_allclose(reward, STEP_PENALTY)
    assert not terminated.any() and not truncated.any()
    assert obs["prev_action"].tolist() == [ROTATE_LEFT] * 6
    np.testing.assert_allclose(sim.yaw, [(e.start[2] - 30.0) % 360.0 for e in eps])
    assert np.isnan(info["spl"]).all()


def test_batch_equals_physics_scan_and_geodesic_references(real_world, small_world):
    """100 agents (the multi-threaded kernel) against step_poses, scan and geodesic_distance."""
    rng = np.random.default_rng(1)
    worlds = [real_world, small_world]
    env = rng.integers(2, size=100)
    eps = [task.sample_episode(worlds[e], rng) for e in env]
    sim = BatchSim(worlds)
    sim.reset(eps, env)
    grids, sem = PackedGrids.from_worlds(worlds), pack_semantic(worlds)
    x, z, yaw = sim.x.copy(), sim.z.copy(), sim.yaw.copy()
    for _ in range(20):
        actions = rng.integers(0, END, size=100)
        obs, *_ = sim.step(actions)
        moved = step_poses(grids, env, x, z, yaw, actions)
        np.testing.assert_array_equal(sim.x, x)
        np.testing.assert_array_equal(sim.yaw, yaw)
        np.testing.assert_array_equal(obs["collided"], (~moved).astype(np.int64))
    depth, classes = scan(grids, sem, env, x, z, yaw)
    np.testing.assert_array_equal(obs["depth"], depth)
    np.testing.assert_array_equal(obs["semantic"], classes)
    for i in range(100):
        ref = geodesic.geodesic_distance(worlds[env[i]], eps[i].target_type, x[i], z[i])
        assert sim.geodesic[i] == pytest.approx(ref, rel=1e-6)


def test_serial_and_parallel_kernels_agree(real_world):
    rng = np.random.default_rng(2)
    eps = [task.sample_episode(real_world, rng) for _ in range(80)]
    actions = rng.integers(0, END, size=(15, 80))
    out = []
    for kwargs in ({"parallel": False}, {"parallel": True}, {"threads": 1}, {"threads": 2}):
        sim = BatchSim([real_world], **kwargs)
        sim.reset(eps)
        for a in actions:
            obs, reward, *_ = sim.step(a)
        out.append((obs, reward, sim.x.copy()))
    for other in out[1:]:
        for key in out[0][0]:
            np.testing.assert_array_equal(out[0][0][key], other[0][key])
        np.testing.assert_array_equal(out[0][1], other[1])
        np.testing.assert_array_equal(out[0][2], other[2])


def test_thread_choice_is_explicit_and_auto_picks_serial_for_small_batches_or_one_thread(small_world):
    import numba

    from adaptenv.sim.vector import PARALLEL_MIN_BATCH

    assert BatchSim([small_world], threads=1).threads_for(4096) == 1
    assert BatchSim([small_world], parallel=False).threads_for(4096) == 1
    auto = BatchSim([small_world])
    assert auto.threads_for(PARALLEL_MIN_BATCH - 1) == 1
    previous = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        assert auto.threads_for(4096) == 1
        if numba.config.NUMBA_NUM_THREADS >= 2:
            numba.set_num_threads(2)
            assert auto.threads_for(4096) == 2
            assert BatchSim([small_world], threads=2).threads_for(1) == 2
    finally:
        numba.set_num_threads(previous)
    with pytest.raises(ValueError, match="threads"):
        BatchSim([small_world], threads=0)


def test_kernel_leaves_numba_thread_count_as_it_found_it(small_world):
    import numba

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs 2 numba threads")
    rng = np.random.default_rng(4)
    sim = BatchSim([small_world], threads=2)
    sim.reset([task.sample_episode(small_world, rng) for _ in range(3)])
    previous = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        sim.step(np.full(3, ROTATE_RIGHT))
        assert numba.get_num_threads() == 1
    finally:
        numba.set_num_threads(previous)


def test_reward_follows_the_best_so_far_distance(small_world):
    sim = BatchSim([small_world])
    sim.reset([Episode("GarbageCan", (0.5, 1.5, 90.0))])  # facing the can, 5 m away
    d0 = float(sim.geodesic[0])
    _, r, *_ = sim.step(np.array([MOVE_AHEAD]))
    d1 = float(sim.geodesic[0])
    assert d1 < d0 and r[0] == pytest.approx(STEP_PENALTY + (d0 - d1))
    for _ in range(6):  # turn around and walk back: no shaping, only the step penalty
        sim.step(np.array([ROTATE_RIGHT]))
    _, r, *_ = sim.step(np.array([MOVE_AHEAD]))
    assert sim.geodesic[0] > d1 and r[0] == pytest.approx(STEP_PENALTY)
    _, r, *_ = sim.step(np.array([MOVE_AHEAD]))
    assert r[0] == pytest.approx(STEP_PENALTY)
    for _ in range(6):  # back towards the can: regaining lost ground earns nothing either
        sim.step(np.array([ROTATE_RIGHT]))
    _, r, *_ = sim.step(np.array([MOVE_AHEAD]))
    assert r[0] == pytest.approx(STEP_PENALTY)
    assert sim.best[0] == pytest.approx(d1)


def test_end_terminates_with_success_only_near_a_visible_target(small_world):
    sim = BatchSim([small_world])
    near = Episode("GarbageCan", (4.0, 1.5, 90.0))  # 1.5 m from the can, facing it
    far = Episode("GarbageCan", (0.8, 1.5, 90.0))
    behind = Episode("GarbageCan", (4.0, 1.5, 270.0))  # near but facing away
    sim.reset([near, far, behind])
    _, reward, terminated, truncated, info = sim.step(np.full(3, END))
    assert terminated.tolist() == [True, True, True] and not truncated.any()
    assert info["success"].tolist() == [True, False, False]
    assert reward[0] == pytest.approx(STEP_PENALTY + SUCCESS_REWARD)
    np.testing.assert_allclose(reward[1:], STEP_PENALTY)
    assert info["spl"][0] == pytest.approx(1.0) and info["spl"][1] == 0.0
    for i, ep in enumerate((near, far, behind)):
        assert info["success"][i] == task.is_success(small_world, *ep.start, ep.target_type)


def test_max_steps_truncates_and_finished_agents_freeze_until_reset_at(small_world):
    sim = BatchSim([small_world], max_steps=3)
    ep = Episode("GarbageCan", (1.0, 1.5, 0.0))
    sim.reset([ep, ep])
    flags = [sim.step(np.array([END if k == 0 else ROTATE_LEFT, ROTATE_LEFT]))[2:4] for k in range(3)]
    (term0, trunc0), (term1, trunc1), (term2, trunc2) = flags
    assert term0.tolist() == [True, False] and not trunc0.any()
    assert not term1.any() and not trunc1.any()  # agent 0 is frozen: no second termination
    assert trunc2.tolist() == [False, True] and not term2.any()
    assert sim.done.all()
    yaw = sim.yaw.copy()
    _, reward, terminated, truncated, _ = sim.step(np.array([ROTATE_LEFT, ROTATE_LEFT]))
    assert reward.tolist() == [0.0, 0.0] and not terminated.any() and not truncated.any()
    np.testing.assert_array_equal(sim.yaw, yaw)
    obs = sim.reset_at([1], [Episode("GarbageCan", (2.0, 1.0, 180.0))])
    assert obs["prev_action"].tolist() == [END, NO_ACTION]
    assert sim.done.tolist() == [True, False] and sim.steps[1] == 0
    assert (sim.x[1], sim.z[1], sim.yaw[1]) == (2.0, 1.0, 180.0)
    _, reward, *_ = sim.step(np.array([MOVE_AHEAD, MOVE_AHEAD]))
    assert reward[0] == 0.0 and reward[1] != 0.0


def test_collisions_are_counted(small_world):
    sim = BatchSim([small_world])
    sim.reset([Episode("GarbageCan", (1.0, 0.45, 180.0))])  # facing the wall z = 0
    results = [sim.step(np.array([MOVE_AHEAD])) for _ in range(4)]
    assert results[-1][0]["collided"][0] == 1
    assert sim.collisions[0] >= 2 and results[-1][4]["collisions"][0] == sim.collisions[0]


def test_success_precheck_never_changes_the_verdict(real_world):
    rng = np.random.default_rng(3)
    sim = BatchSim([real_world])
    eps = [task.sample_episode(real_world, rng) for _ in range(150)]
    sim.reset(eps)
    hits = 0
    for i, ep in enumerate(eps):
        expected = task.is_success(real_world, *ep.start, ep.target_type)
        assert sim._judge(i) == expected
        hits += expected
    near = np.flatnonzero(sim.geodesic < 0.5)
    assert near.size > 0  # some starts are close enough for the full check to run


def test_bad_inputs_raise(small_world):
    sim = BatchSim([small_world])
    sim.reset([Episode("GarbageCan", (1.0, 1.0, 0.0))])
    with pytest.raises(ValueError, match="actions"):
        sim.step(np.array([0, 1]))
    with pytest.raises(ValueError, match="actions"):
        sim.step(np.array([9]))
    with pytest.raises(ValueError, match="env_idx"):
        sim.reset_at([0], [Episode("GarbageCan", (1.0, 1.0, 0.0))], [3])
    with pytest.raises(ValueError, match="unknown target type"):
        sim.reset([Episode("Unicorn", (1.0, 1.0, 0.0))])


def test_episode_sampler_draws_solvable_seeded_episodes(real_world, small_world):
    from adaptenv.sim.vector import EpisodeSampler

    worlds = [real_world, small_world]
    sampler = EpisodeSampler(worlds)
    eps, envs = sampler.draw(np.random.default_rng(5), 40)
    again, envs2 = EpisodeSampler(worlds).draw(np.random.default_rng(5), 40)
    assert eps == again and envs.tolist() == envs2.tolist()
    assert set(envs.tolist()) == {0, 1}
    for ep, e in zip(eps, envs.tolist(), strict=True):
        world = worlds[e]
        assert ep.target_type in task.available_targets(world)
        d = geodesic.geodesic_distance(world, ep.target_type, ep.start[0], ep.start[1])
        assert 0 < d < np.inf and ep.start[2] % 30.0 == 0.0
    fixed, _ = sampler.draw(np.random.default_rng(0), 5, np.ones(5, dtype=np.int64), target_type="GarbageCan")
    assert {ep.target_type for ep in fixed} == {"GarbageCan"}
    with pytest.raises(AdaptenvError, match="no episode can be drawn"):
        EpisodeSampler([small_world], target_types=["Bed"]).draw(np.random.default_rng(0), 1)


def test_a_world_with_task_targets_draws_only_those_types(real_world):
    from dataclasses import replace

    from adaptenv.sim.vector import EpisodeSampler

    avail = task.available_targets(real_world)
    focused = replace(real_world, task_targets=(avail[-1], "Unicorn"))  # an absent type is ignored
    eps, _ = EpisodeSampler([focused]).draw(np.random.default_rng(2), 30)
    assert {ep.target_type for ep in eps} == {avail[-1]}
    assert len({ep.target_type for ep in EpisodeSampler([real_world]).draw(np.random.default_rng(2), 30)[0]}) > 1
    nowhere = replace(real_world, task_targets=("Unicorn",))  # no focus type present: every type, as before
    assert EpisodeSampler([nowhere]).draw(np.random.default_rng(2), 30)[0] == \
        EpisodeSampler([real_world]).draw(np.random.default_rng(2), 30)[0]


def test_episode_sampler_floor_keeps_far_starts_and_falls_back_to_the_farthest(real_world, small_world):
    from adaptenv.sim.vector import EpisodeSampler

    def distances(sampler, world_idx, worlds):
        eps, envs = sampler.draw(np.random.default_rng(1), 60, np.full(60, world_idx, dtype=np.int64))
        return np.array([geodesic.geodesic_distance(worlds[e], ep.target_type, ep.start[0], ep.start[1])
                         for ep, e in zip(eps, envs.tolist(), strict=True)])

    worlds = [real_world]
    uniform = distances(EpisodeSampler(worlds), 0, worlds)
    floored = distances(EpisodeSampler(worlds, min_distance=4.0), 0, worlds)
    assert uniform.min() < 4.0 <= floored.min()
    # a floor no start reaches: the farthest quarter of each target's starts, never an error
    huge = distances(EpisodeSampler([small_world], min_distance=1e6), 0, [small_world])
    assert np.isfinite(huge).all() and np.median(huge) > np.median(distances(EpisodeSampler([small_world]), 0,
                                                                              [small_world]))
