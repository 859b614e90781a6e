"""The evaluation harness: determinism, user policies, statistics, outputs."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from adaptenv.agents.evaluate import (
    evaluate,
    run_episodes,
    sample_episodes,
    summarize,
    wilson,
    write_report,
)
from adaptenv.agents.network import NavNet, NetConfig, NeuralPolicy
from adaptenv.agents.policy import ExpertPolicy, RandomPolicy
from adaptenv.agents.registry import resolve_policy
from adaptenv.render.topdown import render_house

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "my_policy.py"


def test_expert_solves_tiny_episodes(tiny_set):
    eps = sample_episodes(tiny_set.worlds, 12, seed=0)
    results, recs = run_episodes(tiny_set.worlds, eps, ExpertPolicy(), batch=5)
    assert [r.index for r in results] == list(range(12))
    assert all(r.success for r in results)
    assert all(0.0 < r.spl <= 1.0 for r in results)
    assert recs == {}


def key(report):
    """Everything an evaluation measured, comparable (SEL is NaN without the expert run)."""
    return [(r.index, r.house, r.target_type, r.seed, r.success, r.spl, r.steps, r.collisions, r.path_length)
            for r in report.results]


def test_a_slice_of_the_episodes_is_sampled_on_its_own(tiny_set):
    whole = sample_episodes(tiny_set.worlds, 12, seed=3)
    assert sample_episodes(tiny_set.worlds, 9, seed=3, start=4) == whole[4:9]


def test_evaluation_is_deterministic_and_batch_independent(tiny_set):
    torch.manual_seed(0)
    net = NavNet(NetConfig(hidden=32, feature_dim=32, conv_channels=8))
    for make in (lambda: RandomPolicy(seed=2), lambda: NeuralPolicy(net)):
        a = evaluate(make(), tiny_set, episodes=10, seed=5, batch=4, with_expert=False, max_steps=80)
        b = evaluate(make(), tiny_set, episodes=10, seed=5, batch=4, with_expert=False, max_steps=80)
        c = evaluate(make(), tiny_set, episodes=10, seed=5, batch=10, with_expert=False, max_steps=80)
        assert key(a) == key(b) == key(c)
        d = evaluate(make(), tiny_set, episodes=10, seed=6, batch=4, with_expert=False, max_steps=80)
        assert [r.seed for r in a.results] != [r.seed for r in d.results]


def test_user_policy_runs_through_the_harness(tiny_set, tmp_path):
    policy = resolve_policy(f"{EXAMPLE}:policy")
    report = evaluate(policy, tiny_set, episodes=6, seed=0, batch=3, max_steps=120)
    assert report.policy == "reactive-example"
    assert report.summary["episodes"] == 6
    assert report.summary["expert_success"] == 1.0
    paths = write_report(report, tiny_set, tmp_path / "out", render=render_house)
    summary = json.loads(paths["summary"].read_text())
    assert summary["episodes"] == 6
    assert paths["episodes"].read_text().count("\n") == 7
    assert "house" in paths["houses"].read_text().splitlines()[0]
    if report.summary["successes"] < 6:  # failures are drawn and saved
        assert paths["failures"].is_file()
        assert any((tmp_path / "out" / "failed").glob("episode_*.json"))
    # without a renderer the failed trajectories are still saved, only the picture is left out
    bare = write_report(report, tiny_set, tmp_path / "bare")
    assert "failures" not in bare and not (tmp_path / "bare" / "failures.png").exists()
    assert (sorted(p.name for p in (tmp_path / "bare").glob("failed/*.json"))
            == sorted(p.name for p in (tmp_path / "out").glob("failed/*.json")))


def test_failed_episode_recordings_replay_the_poses(tiny_set):
    eps = sample_episodes(tiny_set.worlds, 4, seed=1)
    results, recs = run_episodes(tiny_set.worlds, eps, RandomPolicy(seed=0), batch=2, max_steps=30,
                                 record=lambda r: True)
    for r in results:
        rec = recs[r.index]
        assert len(rec.actions) == r.steps and len(rec.poses) == r.steps + 1
        assert rec.poses[0] == pytest.approx(eps[r.index][1].start[:2] + (eps[r.index][1].start[2] % 360,))
        assert sum(not m for m in rec.moved) == r.collisions


def test_statistics():
    lo, hi = wilson(8, 10)
    assert 0.44 < lo < 0.5 and 0.94 < hi < 0.97
    assert wilson(0, 10)[0] == 0.0

    class R:  # minimal result rows
        def __init__(self, s, spl):
            self.success, self.spl, self.sel, self.collisions, self.steps, self.path_length = s, spl, spl, 0, 10, 1.0

    s = summarize([R(True, 1.0), R(False, 0.0), R(True, 0.5), R(True, 0.5)])
    assert s["success"] == 0.75 and s["spl"] == 0.5
    assert math.isclose(s["spl_se"], np.std([1, 0, 0.5, 0.5], ddof=1) / 2)
    assert s["spl_ci95"][0] < 0.5 < s["spl_ci95"][1]


@pytest.mark.slow
def test_worker_processes_give_the_same_results(tiny_set):
    one = evaluate("random:3", tiny_set, episodes=6, seed=2, batch=3, workers=1, max_steps=40)
    two = evaluate("random:3", tiny_set, episodes=6, seed=2, batch=3, workers=2, max_steps=40)
    assert key(one) == key(two)
    assert [r.sel for r in one.results] == [r.sel for r in two.results]
    assert sorted(one.recordings) == sorted(two.recordings)
