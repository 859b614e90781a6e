"""The map explorer: it finds targets from its own EgoMap alone (no bind), is deterministic and batch
independent, and labels DAgger states as the map-explorer teacher."""

from __future__ import annotations

import numpy as np

from adaptenv.agents.evaluate import run_episodes, sample_episodes, summarize
from adaptenv.agents.map_explorer import MapExplorerPolicy
from adaptenv.agents.registry import resolve_policy
from adaptenv.agents.teachers import TEACHERS, make_teacher
from adaptenv.sim.egomap import EgoMap
from adaptenv.sim.spec import N_ACTIONS


def test_map_explorer_finds_most_tiny_targets(tiny_set):
    eps = sample_episodes(tiny_set.worlds, 16, 0)
    results, _ = run_episodes(tiny_set.worlds, eps, MapExplorerPolicy(), batch=16)
    assert summarize(results)["success"] >= 0.8
    assert resolve_policy("map-explorer").name == "map-explorer"


def test_map_explorer_is_deterministic_and_batch_independent(tiny_set):
    eps = sample_episodes(tiny_set.worlds, 8, 1)
    one, _ = run_episodes(tiny_set.worlds, eps, MapExplorerPolicy(), batch=1)
    many, _ = run_episodes(tiny_set.worlds, eps, MapExplorerPolicy(), batch=8)
    again, _ = run_episodes(tiny_set.worlds, eps, MapExplorerPolicy(), batch=8)
    key = [(r.success, r.steps, r.path_length) for r in one]
    assert key == [(r.success, r.steps, r.path_length) for r in many] == [(r.success, r.steps, r.path_length)
                                                                          for r in again]


def test_map_explorer_needs_no_context(tiny_set):
    """No ``bind``: the runners' context never reaches it, and it runs through run_episodes all the same."""
    policy = MapExplorerPolicy()
    assert not hasattr(policy, "bind")
    eps = sample_episodes(tiny_set.worlds, 4, 2)
    results, _ = run_episodes(tiny_set.worlds, eps, policy, batch=4)
    assert len(results) == 4 and any(r.success for r in results)
    assert isinstance(policy.emap, EgoMap) and policy.emap.batch == 4


def test_map_explorer_teacher_labels_every_agent(tiny_set):
    from adaptenv.sim.vector import BatchSim

    assert "map-explorer" in TEACHERS
    eps = sample_episodes(tiny_set.worlds, 4, 0)
    sim = BatchSim(tiny_set.worlds, max_steps=50)
    obs, _ = sim.reset([ep for _, ep in eps], [e for e, _ in eps])
    teacher = make_teacher("map-explorer", sim)
    policy = MapExplorerPolicy()
    first = np.ones(4, dtype=bool)
    for _ in range(12):
        labels = teacher.label(obs, first)
        assert labels.shape == (4,) and ((labels >= 0) & (labels < N_ACTIONS)).all()
        assert labels.tolist() == policy.act(obs, None, first)[0].tolist()
        obs, *_ = sim.step(labels)
        first = np.zeros(4, dtype=bool)


def test_map_explorer_teacher_on_the_students_map_labels_as_on_its_own(tiny_set):
    """Planning on the student's MapObserver map (what DAgger does) gives the labels of the explorer's own map,
    across episode ends, and the map it plans on is the student's."""
    import pytest

    from adaptenv.agents.network import MapObserver
    from adaptenv.sim.vector import BatchSim, EpisodeSampler

    rng = np.random.default_rng(3)
    sampler = EpisodeSampler(tiny_set.worlds)
    sim = BatchSim(tiny_set.worlds, max_steps=40)
    obs, _ = sim.reset(*sampler.draw(rng, 6))
    observer = MapObserver(6)
    shared, own = make_teacher("map-explorer", sim, emap=observer.emap), make_teacher("map-explorer", sim)
    first, ends = np.ones(6, dtype=bool), 0
    for _ in range(90):
        obs = observer(obs, first)
        labels = shared.label(obs, first)
        assert labels.tolist() == own.label(obs, first).tolist()
        obs, _, terminated, truncated, _ = sim.step(np.where(rng.random(6) < 0.5, labels, rng.integers(0, 3, 6)))
        done = np.flatnonzero(terminated | truncated)
        first = np.zeros(6, dtype=bool)
        if done.size:
            ends += done.size
            obs = sim.reset_at(done, *sampler.draw(rng, done.size))
            first[done] = True
    assert ends > 0 and shared.explorer.emap is observer.emap
    assert (own.explorer.emap.grid == observer.emap.grid).all()
    with pytest.raises(ValueError, match="act_on needs an EgoMap of 6 agents"):
        MapExplorerPolicy().act_on(EgoMap(5), obs, first)


def test_labelling_benchmark_times_both_teachers_on_the_same_states():
    from adaptenv.bench.teachers import bench_labelling

    out = bench_labelling("preset:tiny", agents=8, steps=8, block=4, warmup=2)
    assert out["blocks"] == 2 and out["explorer_fps"] > 0 and out["map_explorer_fps"] > 0
    assert out["ratio"] == out["map_explorer_fps"] / out["explorer_fps"]
