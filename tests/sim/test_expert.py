"""The shortest-path expert: it succeeds, near-optimally, and its batched form agrees with the single one."""

from __future__ import annotations

import numpy as np
import pytest

from adaptenv.sim.expert import ShortestPathExpert
from adaptenv.sim.rollout import expert_policy, run_episode
from adaptenv.sim.spec import END
from adaptenv.sim.task import Episode, is_success, sample_episode
from adaptenv.sim.world import compile_world
from tests.sim import helpers as H


def check_expert(world, episode):
    traj = run_episode(world, episode, expert_policy())
    m = traj.metrics
    assert m.solvable and m.success, (episode, m)
    assert traj.steps[-1].action == "end"
    assert m.path_length <= 1.25 * m.optimal_path_length + 0.5, (episode, m)
    assert m.collisions == 0
    return m


@pytest.mark.parametrize("house", [H.corridor_house, lambda: H.two_rooms(0.8, objects=[H.Obj(H.TALL_TARGET, 7.0, 3.5)])])
def test_expert_solves_synthetic_houses_near_optimally(house):
    w = compile_world(house())
    for seed in range(8):
        check_expert(w, sample_episode(w, seed))


def test_expert_solves_the_real_house(real_house):
    w = compile_world(real_house, "real")
    spl = [check_expert(w, sample_episode(w, seed)).spl for seed in range(12)]
    assert np.mean(spl) > 0.8


def test_expert_ends_only_on_success():
    w = compile_world(H.corridor_house())
    e = ShortestPathExpert()
    rng = np.random.default_rng(1)
    rows, cols = np.nonzero(w.grid.navigable(0.2))
    for k in rng.choice(len(rows), 300, replace=False):
        x, z = w.grid.cell_center(rows[k], cols[k])
        yaw = float(rng.integers(60) * 6)
        if e.act(w, "GarbageCan", x, z, yaw) == END:
            assert is_success(w, x, z, yaw, "GarbageCan")


def test_act_batch_matches_act(real_house):
    worlds = [compile_world(real_house, "real"), compile_world(H.corridor_house(), "corridor")]
    rng = np.random.default_rng(3)
    env = rng.integers(2, size=64)
    eps = [sample_episode(worlds[i], rng) for i in env]
    targets = [ep.target_type for ep in eps]
    x = np.array([ep.start[0] for ep in eps]) + rng.uniform(-0.02, 0.02, 64)
    z = np.array([ep.start[1] for ep in eps]) + rng.uniform(-0.02, 0.02, 64)
    yaw = rng.integers(60, size=64) * 6.0
    e = ShortestPathExpert()
    batch = e.act_batch(worlds, env, targets, x, z, yaw)
    single = [e.act(worlds[i], t, a, b, c) for i, t, a, b, c in zip(env, targets, x, z, yaw, strict=True)]
    assert batch.tolist() == single


def test_unsolvable_episode_is_detected_not_failed():
    w = compile_world(H.sealed_target_house())
    ep = Episode("GarbageCan", (2.0, 2.0, 90.0))
    assert ShortestPathExpert().act(w, "GarbageCan", 2.0, 2.0, 90.0) == END
    m = run_episode(w, ep, expert_policy()).metrics
    assert not m.solvable and not m.success and m.optimal_path_length is None
