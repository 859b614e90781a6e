"""The searching teacher: it solves episodes without knowing the target, reads only its pose and grid
geometry, is batch independent, and labels DAgger states as expert, explorer or mix."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from adaptenv.agents.evaluate import run_episodes, sample_episodes, summarize
from adaptenv.agents.explorer import ExplorerPolicy
from adaptenv.agents.policy import ExpertPolicy, PolicyContext
from adaptenv.agents.registry import resolve_policy
from adaptenv.agents.teachers import make_teacher
from adaptenv.errors import ConfigError
from adaptenv.sim.spec import N_ACTIONS


def test_explorer_solves_tiny_episodes_with_longer_paths_than_the_expert(tiny_set):
    eps = sample_episodes(tiny_set.worlds, 12, 0)
    explorer, _ = run_episodes(tiny_set.worlds, eps, ExplorerPolicy(), batch=12)
    expert, _ = run_episodes(tiny_set.worlds, eps, ExpertPolicy(), batch=12)
    assert summarize(explorer)["success"] >= 0.8
    assert summarize(explorer)["spl"] <= summarize(expert)["spl"] + 1e-9
    assert resolve_policy("explorer").name == "explorer"


def test_explorer_is_batch_independent(tiny_set):
    eps = sample_episodes(tiny_set.worlds, 6, 1)
    one, _ = run_episodes(tiny_set.worlds, eps, ExplorerPolicy(), batch=1)
    many, _ = run_episodes(tiny_set.worlds, eps, ExplorerPolicy(), batch=4)
    assert [(r.success, r.steps) for r in one] == [(r.success, r.steps) for r in many]


class _Recorder:
    """Wraps a policy and keeps every (observation, pose, done, action) it was called with."""

    def __init__(self, policy):
        self.policy, self.calls, self.ctx = policy, [], None

    def bind(self, ctx):
        self.ctx = ctx
        self.policy.bind(ctx)

    def initial_state(self, batch):
        return None

    def act(self, obs, state, done):
        actions, state = self.policy.act(obs, state, done)
        c = self.ctx
        self.calls.append(({k: np.array(v) for k, v in obs.items()}, int(c.env_idx[0]), float(c.x[0]),
                           float(c.z[0]), float(c.yaw[0]), np.array(done), actions.copy()))
        return actions, state


def test_explorer_reads_only_its_pose_and_the_grid_geometry(tiny_set):
    """Replaying the same observations and poses against worlds that expose nothing but the grid's
    frame and clearance gives the same actions: no target instance, region or field is read."""
    eps = sample_episodes(tiny_set.worlds, 2, 2)
    rec = _Recorder(ExplorerPolicy())
    run_episodes(tiny_set.worlds, eps, rec, batch=1)
    bare = [SimpleNamespace(grid=SimpleNamespace(x0=w.grid.x0, z0=w.grid.z0, resolution=w.grid.resolution,
                                                 shape=w.grid.shape, clearance=w.grid.clearance), cache={})
            for w in tiny_set.worlds]
    ctx = PolicyContext.empty(bare, 1)
    replay = ExplorerPolicy()
    replay.bind(ctx)
    for obs, e, x, z, yaw, done, actions in rec.calls:
        ctx.env_idx[0], ctx.x[0], ctx.z[0], ctx.yaw[0] = e, x, z, yaw
        again, _ = replay.act(obs, None, done)
        assert again.tolist() == actions.tolist()
    assert len(rec.calls) > 5


@pytest.mark.parametrize("kind", ["expert", "explorer", "mix"])
def test_teachers_label_every_agent(tiny_set, kind):
    from adaptenv.sim.vector import BatchSim

    eps = sample_episodes(tiny_set.worlds, 4, 0)
    sim = BatchSim(tiny_set.worlds, max_steps=50)
    obs, _ = sim.reset([ep for _, ep in eps], [e for e, _ in eps])
    teacher = make_teacher(kind, sim, mix=0.5, seed=0)
    first = np.ones(4, dtype=bool)
    for _ in range(10):
        labels = teacher.label(obs, first)
        assert labels.shape == (4,) and ((labels >= 0) & (labels < N_ACTIONS)).all()
        if kind == "expert":
            ctx = PolicyContext(sim.worlds, sim.env, sim.target_types, np.zeros(4, np.int64), sim.x, sim.z, sim.yaw)
            policy = ExpertPolicy()
            policy.bind(ctx)
            assert labels.tolist() == policy.act(obs, None, first)[0].tolist()
        obs, *_ = sim.step(labels)
        first = np.zeros(4, dtype=bool)


def test_unknown_teacher_is_a_config_error(tiny_set):
    with pytest.raises(ConfigError, match="--teacher"):
        make_teacher("oracle", SimpleNamespace(worlds=tiny_set.worlds, x=np.zeros(2)))
