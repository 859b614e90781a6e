"""The adaptation step end to end (rollout, F, G with pi_t, validation, after-rollout) and its one copy."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from adaptenv.adapt.analysis import BuiltinAnalyzer
from adaptenv.adapt.generators import make_generator
from adaptenv.adapt.step import adapt_scene, summarize, write_outputs
from adaptenv.agents.policy import ExpertPolicy, StepFunctionPolicy, as_policy
from adaptenv.agents.registry import load_pretrained
from adaptenv.agents.rollout import (
    checking_episodes,
    draw_episode,
    find_solved_episode,
    rollout,
    run_policy,
    run_recorded,
    total_steps,
)
from adaptenv.cli import app
from adaptenv.curriculum.jobs import GenerateJob, PolicyWeights, Rollout, run_generate
from adaptenv.scene.house import load_house, save_house
from adaptenv.scene.validate import validate_house_file
from adaptenv.sim.rollout import expert_policy
from adaptenv.sim.task import Episode
from adaptenv.sim.world import compile_world


@pytest.fixture(scope="module")
def house():
    from adaptenv.scene.procedural import GenerationConfig, generate_house

    return generate_house(5, GenerationConfig(n_rooms=4))


def test_adapt_scene_writes_a_valid_house_and_reports(house, tmp_path):
    world = compile_world(house, "h")
    ep = draw_episode(world, np.random.default_rng([1, 1]))
    res = adapt_scene(house, ep, policy=ExpertPolicy(), analyzer=BuiltinAnalyzer(),
                      generator=make_generator("builtin", max_candidates=10), steps=2, rng=np.random.default_rng(1),
                      name="h")
    summary = summarize(res, analyzer=BuiltinAnalyzer(), seed=1)
    # summarize reuses both compiled houses; compiling them afresh gives the same figures
    assert res.original_world is not None and res.world is not None
    fresh = summarize(dataclasses.replace(res, world=None, original_world=None), analyzer=BuiltinAnalyzer(), seed=1)
    assert json.dumps(fresh, sort_keys=True, default=str) == json.dumps(summary, sort_keys=True, default=str)
    write_outputs(res, summary, tmp_path)
    names = {"house.json", "before.png", "after.png", "analysis.json", "edits.json", "summary.json",
             "trajectory_before.json", "trajectory_after.json"}
    assert names <= {p.name for p in tmp_path.iterdir()}
    assert validate_house_file(tmp_path / "house.json") == []
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert saved["valid"] and saved["expert_solvable"] and saved["expert_success_after"]
    assert saved["edits_applied"] == len(res.generation.applied) >= 1
    assert set(saved["objective_before"]) == {"narrow_passage", "lengthen_route", "occlude_target", "add_clutter"}
    edits = json.loads((tmp_path / "edits.json").read_text())
    assert len(edits["steps"]) == 2 and edits["generator"] == "builtin"
    assert json.loads((tmp_path / "analysis.json").read_text())["outcome"]["success"] is True
    assert {o.id: o.position.x for o in load_house(tmp_path / "house.json").objects} == \
        {o.id: o.position.x for o in res.house.objects}
    assert res.original is house and res.before.metrics.success
    # the after-rollout is pi_t's own episode in the edited house, from the same start
    assert res.after.start == res.before.start and res.after.target_type == ep.target_type


def test_g_sees_the_policy_and_verifies_its_edits(house):
    world = compile_world(house, "h")
    ep = draw_episode(world, np.random.default_rng([1, 1]))
    res = adapt_scene(house, ep, policy=ExpertPolicy(), analyzer=BuiltinAnalyzer(),
                      generator=make_generator("builtin", max_candidates=10), steps=2, rng=np.random.default_rng(1))
    applied = [s for s in res.generation.steps if s.status == "applied"]
    assert applied and all(s.policy_score_before is not None for s in applied)
    assert res.edits_verified == sum(1 for s in applied if s.verified) >= 1


def test_per_step_callables_become_one_policy_at_the_edge(house):
    world = compile_world(house, "h")
    found = find_solved_episode(world, ExpertPolicy(), np.random.default_rng(0))
    assert found is not None
    ep, batched = found
    wrapped = as_policy(expert_policy())
    assert isinstance(wrapped, StepFunctionPolicy) and as_policy(wrapped) is wrapped
    per_step = rollout(world, ep, wrapped)
    assert batched.metrics.success and per_step.metrics.success
    assert [s.pose for s in batched.steps] == [s.pose for s in per_step.steps]


def test_random_generator_through_the_step(house):
    world = compile_world(house, "h")
    ep = draw_episode(world, np.random.default_rng([2, 1]))
    res = adapt_scene(house, ep, policy=expert_policy(), analyzer=BuiltinAnalyzer(),
                      generator=make_generator("random"), steps=1, rng=np.random.default_rng(2))
    assert res.valid and res.generation.generator == "random"


def test_checking_episodes_keep_start_and_target():
    eps = checking_episodes(Episode("Bed", (1.0, 2.0, 30.0), seed=4), 3)
    assert [e.start for e in eps] == [(1.0, 2.0, 30.0), (1.0, 2.0, 150.0), (1.0, 2.0, 270.0)]
    assert {e.target_type for e in eps} == {"Bed"}


def test_a_jobs_env_steps_count_every_step_pi_t_takes_for_g(house):
    """The loop's budget counts G's rollout checks of candidate edits, and the diagnosis episodes when there are some."""
    world = compile_world(house, "h")
    weights = PolicyWeights.of(load_pretrained("pretrained-scan"))
    episode = draw_episode(world, np.random.default_rng([0, 1]))
    [(res, traj)] = run_recorded(world, [episode], weights.policy())
    made = run_generate(GenerateJob("builtin", house, "h", 1, (0,), weights=weights,
                                    rollout=Rollout([episode], [res], [traj], [True])))
    checks = [s["check_steps"] for s in made.edit_log["steps"]]
    own = total_steps([run_policy(world, checking_episodes(episode, 3), weights.policy())])
    assert made.rollout_steps == sum(checks) and checks[0] > own, "the scene's own check episodes plus its candidates'"

    made = run_generate(GenerateJob("failure-modes", house, "h", 1, (0,), weights=weights, diagnose_episodes=2))
    diagnosis = sum(e["steps"] for key in ("diagnosis", "diagnosis_after") for e in made.edit_log[key]["episodes"])
    checks = [s["check_steps"] for s in made.edit_log["steps"]]
    # with the placement model the failure-mode G finds no move in this house a person would believe, so it may
    # check none; the budget still counts the diagnosis and whatever it checked
    assert made.rollout_steps == diagnosis + sum(checks)


@pytest.mark.slow
def test_loop_generate_job_and_adapt_cli_make_the_same_house_and_log(house, tmp_path):
    """The closed loop's `ours` runs exactly `adaptenv adapt`: same pi_t, episode and seed give the same child."""
    path = save_house(house, tmp_path / "h.json")
    out = tmp_path / "adapt"
    result = CliRunner().invoke(app, ["adapt", str(path), "--policy", "pretrained-scan", "--steps", "3", "--seed", "0",
                                      "-o", str(out), "--json"])
    assert result.exit_code == 0, result.output
    cli_edits = json.loads((out / "edits.json").read_text())

    world = compile_world(house, "h")
    episode = draw_episode(world, np.random.default_rng([0, 1]))  # the CLI's episode draw for --seed 0
    weights = PolicyWeights.of(load_pretrained("pretrained-scan"))
    [(res, traj)] = run_recorded(world, [episode], weights.policy())
    made = run_generate(GenerateJob("builtin", house, "h", 3, (0,), weights=weights,
                                    rollout=Rollout([episode], [res], [traj], [True])))
    assert made.house.to_dict() == load_house(out / "house.json").to_dict()

    def steps(log):
        return [{k: v for k, v in s.items() if k != "render"} for s in log["steps"]]

    assert steps(made.edit_log) == steps(cli_edits)
    assert made.edit_log["edit_log"] == cli_edits["edit_log"]
    verified = [s["verified"] for s in cli_edits["steps"] if s["status"] == "applied"]
    assert verified and [s["verified"] for s in made.edit_log["steps"] if s["status"] == "applied"] == verified
    assert made.edits == sum(1 for s in cli_edits["steps"] if s["status"] == "applied")


@pytest.mark.parametrize("generator", ["builtin", "learned"])
def test_the_world_generation_hands_back_is_the_edited_house_compiled(house, generator):
    """The step reuses the world G compiled for its last edit: the same arrays as compiling the edited house, the
    step's name, and the same validation as without any world handed in."""
    from adaptenv.adapt.validation import validate_scene, world_fits
    from adaptenv.scene.geometry import SceneGeometry

    world = compile_world(house, "h")
    ep = draw_episode(world, np.random.default_rng([1, 1]))
    gen = make_generator(generator, **({"max_candidates": 10} if generator == "builtin" else {}))
    res = adapt_scene(house, ep, policy=ExpertPolicy(), analyzer=BuiltinAnalyzer(), generator=gen, steps=2,
                      rng=np.random.default_rng(1), name="h")
    assert res.edits_applied >= 1 and res.generation.world is not None
    fresh = compile_world(res.house, "h")
    assert res.world.name == "h" and world_fits(res.world, SceneGeometry.from_house(res.house))
    for a, b in ((res.world.grid.clearance, fresh.grid.clearance), (res.world.grid.label, fresh.grid.label),
                 (res.world.occluder, fresh.occluder), (res.world.semantic, fresh.semantic)):
        assert np.array_equal(a, b)
    assert not world_fits(world, SceneGeometry.from_house(res.house)), "the original's world fits the original only"
    plain = validate_scene(res.house, episode_targets=[ep.target_type], start=ep.start[:2], original=house)
    handed = validate_scene(res.house, episode_targets=[ep.target_type], start=ep.start[:2], original=house,
                            world=world, original_world=res.world)  # both the wrong way round: neither is used
    assert [str(p) for p in handed] == [str(p) for p in plain] == res.problems


def test_the_edits_line_says_what_g_made_and_why_fewer():
    from collections import Counter

    from adaptenv.adapt.step import edits_line, missed_edit_reasons

    log = {"steps": [{"status": "applied", "reason": "search objective 0.1 -> 0.2"},
                     {"status": "skipped", "reason": "no candidate move passed placement and validation"},
                     {"status": "skipped", "reason": "no candidate move passed placement and validation"}]}
    reasons = missed_edit_reasons(log)
    assert reasons == Counter({"no candidate move passed placement and validation": 2})
    assert edits_line(3, 1, reasons) == ("G made 1 of 3 edits; fewer because: no candidate move passed placement "
                                         "and validation (2 steps)")
    assert edits_line(2, 2, Counter()) == "G made 2 of 2 edits"
    line = edits_line(4, 0, Counter(), scenes=2, refused=2, no_failure=(2, 6))
    assert line.startswith("G made 0 of 4 edits in 2 scenes; fewer because: the final validation refused")
    assert "F found no failure in 6 episodes of 2 scenes" in line
    assert edits_line(2, 1, Counter(), stopped=["the LLM budget is used up", ""]) == (
        "G made 1 of 2 edits; fewer because: G stopped early: the LLM budget is used up")
    random_log = {"edits": [{"accepted": False, "problems": ["overlaps Sofa|1"]}, {"accepted": True, "changed": True}]}
    assert missed_edit_reasons(random_log) == Counter({"overlaps Sofa|1": 1})
