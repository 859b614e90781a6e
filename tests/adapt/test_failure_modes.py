"""G aimed at failure families: each family's objective gets harder, edits record their family and intent,
targets move only inside their room, and pi_t's rollout checks whether the aimed failure happened."""

from __future__ import annotations

import numpy as np
import pytest

from adaptenv.adapt.analysis import analyze_trajectory
from adaptenv.adapt.diagnosis import SceneDiagnosis
from adaptenv.adapt.generators import GenerationContext, make_generator
from adaptenv.adapt.generators.failure_modes import (
    DEFAULT_PLAN,
    FailureModeGenerator,
    distractor_pressure,
    hiddenness,
    mode_plan,
    mode_value,
)
from adaptenv.adapt.objectives import RouteSpec, measure, route_points, visibility_fraction
from adaptenv.adapt.placement_model import PlacementModel
from adaptenv.adapt.validation import EditValidator, validate_scene
from adaptenv.agents.policy import ExpertPolicy, StepFunctionPolicy
from adaptenv.scene.assets import load_catalog
from adaptenv.scene.geometry import SceneGeometry
from adaptenv.sim.rollout import expert_policy, run_episode
from adaptenv.sim.spec import ACTIONS
from adaptenv.sim.world import compile_world
from tests.adapt.scenes import procedural_scene

#: These tests are about each family's moves on one small house; most of those moves stand where no house of the
#: placement model's reference puts such furniture (the rule ``unlike_reference``), so they run without it.
#: ``test_offline_generators_pass_the_audit`` checks the failure-mode G with it.
NO_REFERENCE = PlacementModel({})


@pytest.fixture(scope="module")
def scene():
    """A procedural 4-room house, an episode of at least 2.5 m and the expert's rollout and analysis."""
    return procedural_scene(5, 4, [1, 1])


def _diagnosis(*families: str) -> SceneDiagnosis:
    return SceneDiagnosis(house="h", episodes=[], dominant=list(families), success_rate=0.0, expert_success_rate=1.0,
                          regret=1.0, worst=0)


def _run(scene, family: str, steps: int = 2, policy=None):
    house, world, ep, traj, analysis = scene
    ctx = GenerationContext(episode=ep, trajectory=traj, policy=policy, render=False, diagnosis=_diagnosis(family),
                            placement_model=NO_REFERENCE)
    res = FailureModeGenerator(max_candidates=10).generate(house, analysis, steps=steps, context=ctx,
                                                           rng=np.random.default_rng(0))
    return res, compile_world(res.house, "after")


def _valid_and_solvable(scene, res, after):
    house, world, ep, *_ = scene
    assert validate_scene(res.house, episode_targets=[ep.target_type], start=ep.start[:2], original=house) == []
    assert run_episode(after, ep, expert_policy(), record=False).metrics.success


@pytest.mark.parametrize("family,measure_fn", [("search", hiddenness), ("premature_end", distractor_pressure)])
def test_each_family_makes_its_own_objective_harder(scene, family, measure_fn):
    house, world, ep, traj, _ = scene
    res, after = _run(scene, family)
    route = RouteSpec.from_episode(ep.target_type, ep.start, traj)
    applied = [s for s in res.steps if s.status == "applied"]
    assert applied, "at least one edit for the family"
    assert all(s.failure_mode == family and s.edit.intent.startswith(f"{family}:") and s.gain > 0 for s in applied)
    assert measure_fn(after, route) > measure_fn(world, route)
    _valid_and_solvable(scene, res, after)


def test_a_search_edit_lowers_the_targets_visibility_from_the_route(scene):
    house, world, ep, traj, _ = scene
    res, after = _run(scene, "search", steps=3)
    route = RouteSpec.from_episode(ep.target_type, ep.start, traj)
    pts_before, pts_after = route_points(world, route), route_points(after, route)
    vis_before = visibility_fraction(world, ep.target_type, pts_before)
    vis_after = visibility_fraction(after, ep.target_type, pts_after)
    assert hiddenness(after, route) > hiddenness(world, route)
    assert vis_after < vis_before, "the target is seen from fewer route points"


def test_looping_edits_raise_symmetry_or_route_length(scene):
    house, world, ep, traj, _ = scene
    res, after = _run(scene, "looping")
    route = RouteSpec.from_episode(ep.target_type, ep.start, traj)
    assert mode_value("looping", after, route, measure(after, route)) > \
        mode_value("looping", world, route, measure(world, route))
    _valid_and_solvable(scene, res, after)


def test_target_moves_only_when_asked_and_never_away_from_what_it_faces(scene):
    house, world, ep, traj, _ = scene  # the target is a Television facing the living room's sofa
    gen = FailureModeGenerator(max_candidates=12, relocate_targets=True)
    v = EditValidator(house, episode_targets=[ep.target_type], start=ep.start[:2], move_targets=True)
    targets = {t.object_id for t in world.instances_of(ep.target_type)}
    route = RouteSpec.from_episode(ep.target_type, ep.start, traj)
    plain = FailureModeGenerator(max_candidates=12)._mode_candidates("search", v, world, route, targets,
                                                                     np.random.default_rng(3))
    assert not [c for c in plain if c.object_id in targets], "targets move only with relocate_targets"
    cands = [c for c in gen._mode_candidates("search", v, world, route, targets, np.random.default_rng(3))
             if c.kind == "target_late"]
    assert cands and all(c.object_id in targets for c in cands)
    for c in cands:  # carried to a far corner, the television would no longer face the sofa
        problems = v.propose(c.object_id, c.dx_units, c.dy_units, c.rotation).problems
        assert any(p.message.startswith("implausible (facing_broken)") for p in problems)


def test_relocated_targets_go_to_a_far_plausible_room_only_when_asked():
    house, world, ep, traj, _ = procedural_scene(2, 4, [1, 1])  # one HousePlant, in the living room
    v = EditValidator(house, episode_targets=[ep.target_type], start=ep.start[:2], move_targets=True,
                      placement_model=NO_REFERENCE)
    targets = {t.object_id for t in world.instances_of(ep.target_type)}
    route = RouteSpec.from_episode(ep.target_type, ep.start, traj)

    def candidates(gen):
        return gen._mode_candidates("search", v, world, route, targets, np.random.default_rng(3))

    assert not [c for c in candidates(FailureModeGenerator(max_candidates=12)) if c.kind == "target_room"]
    gen = FailureModeGenerator(max_candidates=12, relocate_targets=True)
    cands = [c for c in candidates(gen) if c.kind == "target_room"]
    assert cands and all(c.relocate and c.object_id in targets for c in cands)
    geometry = SceneGeometry.from_house(v.house)
    kept = [c for c in (gen._evaluate(v, geometry, c, route, house, ep) for c in cands) if c is not None]
    assert kept, "some relocation passes placement, validation and the expert check"
    g = world.geometry
    home = g.room_of_point(*g.footprint(kept[0].object_id).center)
    moved = kept[0].world.geometry.room_of_point(*kept[0].world.geometry.footprint(kept[0].object_id).center)
    assert moved != home and load_catalog().type_info(ep.target_type).weight_in(g.room_types[moved]) > 0
    ctx = GenerationContext(episode=ep, trajectory=traj, policy=None, render=False, diagnosis=_diagnosis("search"),
                            placement_model=NO_REFERENCE)
    res = gen.generate(house, analyze_trajectory(traj, world), steps=3, context=ctx, rng=np.random.default_rng(0))
    assert any(s.edit is not None and s.edit.relocate and "(target_room move)" in s.edit.intent for s in res.steps)
    after = compile_world(res.house, "after")
    assert hiddenness(after, route) > hiddenness(world, route)
    assert validate_scene(res.house, episode_targets=[ep.target_type], start=ep.start[:2], original=house) == []
    assert run_episode(after, ep, expert_policy(), record=False).metrics.success


def test_verification_rolls_pi_t_out_and_records_the_aimed_failure(scene):
    stop = StepFunctionPolicy(lambda world, episode, x, z, yaw, collided, step: ACTIONS.index("end"))
    res, after = _run(scene, "premature_end", steps=1, policy=stop)
    [step] = res.steps
    assert step.status == "applied" and step.produced_failure is True
    assert step.policy_score_before == 0.0 and step.policy_score_after == 0.0


def test_mode_plan_falls_back_to_the_analysed_episode_then_the_default(scene):
    *_, analysis = scene
    assert mode_plan(_diagnosis("looping", "stuck"), analysis) == ["looping", "stuck"]
    assert mode_plan(_diagnosis(), analysis) == list(DEFAULT_PLAN), "the expert's solved episode has no failure"
    assert make_generator("failure-modes").name == "failure-modes"


def test_rollouts_in_several_worlds_match_one_world_at_a_time(scene):
    from adaptenv.agents.rollout import checking_episodes, run_in_worlds, run_policy

    house, world, ep, *_ = scene
    res, after = _run(scene, "premature_end", steps=1)
    eps = checking_episodes(ep, 2)
    together = run_in_worlds([world, after], eps, ExpertPolicy())
    alone = [run_policy(w, eps, ExpertPolicy()) for w in (world, after)]
    assert [[t.model_dump() for t in ts] for ts in together] == [[t.model_dump() for t in ts] for ts in alone]


def test_adapt_scene_with_episodes_diagnoses_before_and_after(scene):
    from adaptenv.adapt.analysis import BuiltinAnalyzer
    from adaptenv.adapt.diagnosis import hard_episodes
    from adaptenv.adapt.step import adapt_scene

    house, world, *_ = scene
    stop = StepFunctionPolicy(lambda world, episode, x, z, yaw, collided, step: ACTIONS.index("end"))
    eps = hard_episodes(world, np.random.default_rng(3), 2)  # episodes where a plausible edit makes pi_t fail
    res = adapt_scene(house, eps[1], policy=stop, analyzer=BuiltinAnalyzer(),
                      generator=make_generator("failure-modes", max_candidates=8), steps=1,
                      rng=np.random.default_rng(0), episodes=eps)
    assert res.valid and res.diagnosis.dominant == ["premature_end"] and res.diagnosis.regret > 0
    assert res.episode == eps[res.diagnosis.worst] and res.before is not None
    assert [e.target_type for e in res.diagnosis_after.episodes] == [e.target_type for e in eps]
    [step] = res.generation.steps
    assert step.failure_mode == "premature_end" and step.status == "applied" and step.produced_failure


def test_a_family_that_cannot_get_harder_falls_back_to_the_builtin_objectives(scene, monkeypatch):
    """F found no failure (the expert solved every episode) and nothing moves the family's objective: G still makes
    the house harder, by the built-in G's objectives, and says so in the step's reason."""
    from adaptenv.adapt.generators import failure_modes
    from adaptenv.adapt.objectives import OBJECTIVE_KINDS

    monkeypatch.setattr(failure_modes, "mode_value", lambda *a, **k: 0.0)  # no candidate makes any family harder
    house, world, ep, traj, analysis = scene
    ctx = GenerationContext(episode=ep, trajectory=traj, policy=ExpertPolicy(), render=False, diagnosis=_diagnosis())
    res = FailureModeGenerator(max_candidates=10).generate(house, analysis, steps=2, context=ctx,
                                                           rng=np.random.default_rng(0))
    applied = [s for s in res.steps if s.status == "applied"]
    assert applied, "a strong agent's scene still gets an edit"
    for s in applied:
        assert s.suggestion_kind in OBJECTIVE_KINDS and "the built-in G's" in s.reason and s.gain > 0
        assert s.edit.intent.startswith("search: built-in") or s.edit.intent.startswith("premature_end: built-in")
    _valid_and_solvable(scene, res, compile_world(res.house, "after"))
