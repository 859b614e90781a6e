"""adapt_house end to end: rollout, F, G, validation, outputs; both policy interfaces."""

from __future__ import annotations

import json

import numpy as np
import pytest

from adaptenv.adapt.analysis import BuiltinAnalyzer
from adaptenv.adapt.generators import make_generator
from adaptenv.adapt.pipeline import (
    adapt_house,
    checking_episodes,
    find_solved_episode,
    resolve_policy_spec,
    rollout,
)
from adaptenv.scene.house import load_house
from adaptenv.scene.validate import validate_house_file
from adaptenv.sim.rollout import expert_policy
from adaptenv.sim.task import Episode
from adaptenv.sim.world import compile_world


@pytest.fixture(scope="module")
def house():
    from adaptenv.scene.procedural import GenerationConfig, generate_house

    return generate_house(5, GenerationConfig(n_rooms=4))


def test_adapt_house_writes_a_valid_house_and_reports(house, tmp_path):
    res = adapt_house(house, policy=resolve_policy_spec("expert"), analyzer=BuiltinAnalyzer(),
                      generator=make_generator("builtin", max_candidates=10), steps=2, seed=1, out_dir=tmp_path,
                      name="h")
    names = {"house.json", "before.png", "after.png", "analysis.json", "edits.json", "summary.json",
             "trajectory_before.json", "trajectory_after.json"}
    assert names <= {p.name for p in tmp_path.iterdir()}
    assert validate_house_file(tmp_path / "house.json") == []
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["valid"] and summary["expert_solvable"] and summary["expert_success_after"]
    assert summary["edits_applied"] == len(res.generation.applied) >= 1
    assert set(summary["objective_before"]) == {"narrow_passage", "lengthen_route", "occlude_target", "add_clutter"}
    edits = json.loads((tmp_path / "edits.json").read_text())
    assert len(edits["steps"]) == 2 and edits["generator"] == "builtin"
    assert json.loads((tmp_path / "analysis.json").read_text())["outcome"]["success"] is True
    saved = load_house(tmp_path / "house.json")
    assert {o.id: o.position.x for o in saved.objects} == {o.id: o.position.x for o in res.house.objects}
    assert res.original is house and res.before.metrics.success


def test_both_policy_interfaces_give_the_same_expert_episode(house):
    world = compile_world(house, "h")
    ep, _ = find_solved_episode(world, expert_policy(), np.random.default_rng(0))
    batched = rollout(world, ep, resolve_policy_spec("expert"))
    per_step = rollout(world, ep, expert_policy())
    assert batched.metrics.success and per_step.metrics.success
    assert batched.start == per_step.start and batched.metrics.spl > 0.5


def test_random_generator_through_the_pipeline(house):
    res = adapt_house(house, policy=expert_policy(), analyzer=BuiltinAnalyzer(), generator=make_generator("random"),
                      steps=1, seed=2, render=False)
    assert res.summary["valid"] and res.summary["expert_success_after"]
    assert res.summary["generator"] == "random" and res.files == {}


def test_checking_episodes_keep_start_and_target():
    eps = checking_episodes(Episode("Bed", (1.0, 2.0, 30.0), seed=4), 3)
    assert [e.start for e in eps] == [(1.0, 2.0, 30.0), (1.0, 2.0, 150.0), (1.0, 2.0, 270.0)]
    assert {e.target_type for e in eps} == {"Bed"}
