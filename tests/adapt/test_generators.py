"""The built-in and random generators, the objectives and the verification loop."""

from __future__ import annotations

import math

import numpy as np
import pytest

from adaptenv.adapt.edits import replay
from adaptenv.adapt.generators import GenerationContext, Generator, make_generator
from adaptenv.adapt.generators.builtin import BuiltinGenerator
from adaptenv.adapt.generators.random_perturbation import RandomPerturbation, random_single_edits
from adaptenv.adapt.objectives import (
    ObjectiveValues,
    RouteSpec,
    gain,
    measure,
    resample,
    shortest_route,
)
from adaptenv.adapt.validation import validate_scene
from adaptenv.adapt.verification import Check, check_objective, revise_until_verified
from adaptenv.agents.policy import ExpertPolicy
from adaptenv.errors import ConfigError
from adaptenv.scene.validate import validate_house
from adaptenv.sim.geodesic import distance_field, field_at
from adaptenv.sim.rollout import expert_policy, run_episode
from adaptenv.sim.world import compile_world
from tests.adapt.scenes import procedural_scene
from tests.sim import helpers as H


@pytest.fixture(scope="module")
def scene():
    """A procedural 5-room house, an episode of at least 2.5 m, the expert (pi), its rollout and analysis."""
    house, world, ep, traj, analysis = procedural_scene(0, 5, [0, 1])
    return house, world, ep, ExpertPolicy(), traj, analysis


@pytest.fixture(scope="module")
def builtin_run(scene):
    house, world, ep, policy, traj, analysis = scene
    before = house.model_dump()
    ctx = GenerationContext(episode=ep, trajectory=traj, policy=policy, render=False)
    result = BuiltinGenerator(max_candidates=12).generate(house, analysis, steps=3, context=ctx,
                                                          rng=np.random.default_rng(7))
    assert house.model_dump() == before, "generate must not modify its input"
    return result


def test_builtin_edits_are_valid_verified_and_harder(scene, builtin_run):
    house, world, ep, *_ = scene
    res = builtin_run
    applied = [s for s in res.steps if s.status == "applied"]
    assert len(res.steps) == 3 and applied
    for s in applied:
        assert s.verified is True and s.verification == "objective" and 0 <= s.revisions <= 2
        assert s.gain is not None and s.gain > 0
        kind = s.suggestion_kind
        sign = 1 if kind in ("lengthen_route", "add_clutter") else -1
        assert sign * (s.objective_after[kind] - s.objective_before[kind]) > 0
        assert s.edit.accepted and s.edit.source == "builtin" and s.candidates > 0
        assert s.policy_score_before is not None
        assert 0 < s.passed <= min(s.candidates, 12) and 0 < s.checked <= s.passed  # the search's cost is recorded
    assert len(res.objective_trace) == 1 + len(applied)
    assert validate_scene(res.house, episode_targets=[ep.target_type], start=ep.start[:2], original=house) == []
    assert validate_house(res.house) == []
    new_world = compile_world(res.house, "after")
    assert run_episode(new_world, ep, expert_policy()).metrics.success


def test_policy_checks_moves_of_distinct_objects():
    from adaptenv.adapt.generators.builtin import Candidate, _distinct_head

    ranked = [Candidate(oid, 1.0, 0.0, None, "toward") for oid in ("a", "a", "b", "a", "c", "d")]
    assert [c.object_id for c in _distinct_head(ranked, 3)] == ["a", "b", "c"]
    head = _distinct_head(ranked, 6)  # too few objects: the next best fill it
    assert [c.object_id for c in head] == ["a", "b", "c", "d", "a", "a"] and head[4] is ranked[1]


def test_builtin_never_moves_targets_and_replays(scene, builtin_run):
    house, world, ep, *_ = scene
    targets = {t.object_id for t in world.instances_of(ep.target_type)}
    assert not targets & {e.object_id for e in builtin_run.applied}
    replayed = replay(house, builtin_run.applied)
    pos = {o.id: (o.position.x, o.position.z, o.rotation.y) for o in replayed.objects}
    for o in builtin_run.house.objects:
        assert pos[o.id] == pytest.approx((o.position.x, o.position.z, o.rotation.y), abs=1e-9)


def test_builtin_is_deterministic(scene):
    house, world, ep, policy, traj, analysis = scene
    ctx = GenerationContext(episode=ep, trajectory=traj, render=False)
    runs = [BuiltinGenerator(max_candidates=8).generate(house, analysis, steps=2, context=ctx,
                                                        rng=np.random.default_rng(11)) for _ in range(2)]
    assert [s.model_dump() for s in runs[0].steps] == [s.model_dump() for s in runs[1].steps]


def test_builtin_renders_after_each_applied_edit(scene, tmp_path):
    house, world, ep, policy, traj, analysis = scene
    ctx = GenerationContext(episode=ep, trajectory=traj, render=True, render_size=384, out_dir=tmp_path)
    res = BuiltinGenerator(max_candidates=8).generate(house, analysis, steps=1, context=ctx,
                                                      rng=np.random.default_rng(1))
    applied = [s for s in res.steps if s.status == "applied"]
    assert len(res.renders) == len(applied) == len(res.render_paths)
    for s in applied:
        assert s.render is not None and (tmp_path / f"step-{s.step:02d}.png").is_file()


def test_random_perturbation_touches_every_movable_object(scene):
    house, world, ep, *_ = scene
    ctx = GenerationContext(episode=ep, render=False)
    res = RandomPerturbation().generate(house, None, steps=5, context=ctx, rng=np.random.default_rng(0))
    movable = {f.object_id for f in world.geometry.floor_objects if f.movable}
    assert {s.edit.object_id for s in res.steps} == movable
    assert sum(e.changed for e in res.applied) >= len(movable) // 2
    assert validate_scene(res.house, episode_targets=[ep.target_type], start=ep.start[:2], original=house) == []


def test_random_moves_that_change_nothing_are_noops_not_applied(scene):
    house, world, ep, *_ = scene
    ctx = GenerationContext(episode=ep, render=False)
    res = RandomPerturbation(max_units=0.0, rotate_p=0.0).generate(house, None, steps=5, context=ctx,
                                                                     rng=np.random.default_rng(0))
    assert res.steps and {s.status for s in res.steps} == {"no-op"}
    assert res.applied == [] and all(s.verified is None for s in res.steps)
    assert res.house.model_dump() == house.model_dump()


def test_builtin_steps_are_applied_only_when_they_change_the_scene(builtin_run):
    for s in builtin_run.steps:
        assert (s.status == "applied") == (s.edit is not None and s.edit.changed and s.status != "no-op")


def test_random_single_edits_makes_k_valid_changes(scene):
    house, world, ep, *_ = scene
    new, log = random_single_edits(house, 4, np.random.default_rng(2), episode_targets=[ep.target_type],
                                   start=ep.start[:2])
    assert sum(e.accepted and e.changed for e in log) == 4
    assert validate_scene(new, episode_targets=[ep.target_type], start=ep.start[:2], original=house) == []
    assert replay(house, log).model_dump() == new.model_dump()


def test_make_generator_and_protocol():
    assert isinstance(make_generator("builtin"), Generator)
    assert isinstance(make_generator("random"), Generator)
    with pytest.raises(ConfigError, match="unknown generator"):
        make_generator("genetic")


# ----------------------------------------------------------------------------- objectives

def test_shortest_route_runs_from_start_into_the_success_region():
    house = H.corridor_house()
    world = compile_world(house, "corridor")
    route = shortest_route(world, "GarbageCan", (1.0, 0.5))
    assert np.allclose(route[0], (1.0, 0.5))
    field = distance_field(world, "GarbageCan")
    assert field_at(world, field, route[-1:, 0], route[-1:, 1])[0] <= 0.1
    steps = np.hypot(*np.diff(route, axis=0).T)
    assert steps.max() <= 0.25 + 1e-9
    assert steps.sum() == pytest.approx(field_at(world, field, 1.0, 0.5), rel=0.1)


def test_blocking_the_door_lengthens_or_cuts_the_route():
    """A desk in the only door of a two-room house: the target becomes unreachable (gain -inf)."""
    open_house = H.two_rooms(objects=[H.Obj(H.LOW_TARGET, 7.0, 2.0)], agent=(1.0, 2.0, 90.0))
    shut = H.two_rooms(objects=[H.Obj(H.LOW_TARGET, 7.0, 2.0), H.Obj(H.TALL_FURNITURE, 4.5, 2.0, 90.0)],
                       agent=(1.0, 2.0, 90.0))
    spec = RouteSpec.from_episode("GarbageCan", (1.0, 2.0, 90.0))
    a, b = measure(compile_world(open_house, "a"), spec), measure(compile_world(shut, "b"), spec)
    assert math.isfinite(a.lengthen_route) and not math.isfinite(b.lengthen_route)
    assert gain("lengthen_route", a, b) == -math.inf
    assert 0.0 <= a.occlude_target <= 1.0 and 0.0 <= a.add_clutter <= 1.0


def test_gain_signs():
    before = ObjectiveValues(0.6, 4.0, 0.5, 0.2)
    harder = ObjectiveValues(0.4, 5.0, 0.3, 0.4)
    for kind in ("narrow_passage", "lengthen_route", "occlude_target", "add_clutter"):
        assert gain(kind, before, harder) > 0 > gain(kind, harder, before)
    assert gain("lengthen_route", before, harder) == pytest.approx(0.25)
    assert gain("narrow_passage", before, before) == 0.0


def test_resample_spacing():
    pts = resample(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]), 0.25)
    assert np.allclose(pts[0], (0, 0)) and np.allclose(pts[-1], (1, 1))
    assert np.hypot(*np.diff(pts, axis=0).T).max() <= 0.25 + 1e-9


# ----------------------------------------------------------------------------- verification

def test_check_objective_direction():
    before = ObjectiveValues(0.6, 4.0, 0.5, 0.2)
    assert check_objective("narrow_passage", before, ObjectiveValues(0.5, 4.0, 0.5, 0.2)).passed
    chk = check_objective("narrow_passage", before, ObjectiveValues(0.7, 4.0, 0.5, 0.2))
    assert not chk.passed and chk.delta < 0 and "did not improve" in chk.reason
    assert not check_objective("lengthen_route", before, ObjectiveValues(0.6, math.inf, 0.5, 0.2)).passed


def test_revision_loop_is_bounded_and_stops_on_success():
    applied = []

    def apply(p):
        applied.append(p)
        return p * 10

    never = revise_until_verified(0, apply, lambda p, r: Check(False, "no"), lambda p, r, c: p + 1, max_revisions=2)
    assert applied == [0, 1, 2] and never.revisions == 2 and not never.check.passed and never.result == 20
    applied.clear()
    second = revise_until_verified(0, apply, lambda p, r: Check(r >= 10, "ok?"), lambda p, r, c: p + 1)
    assert applied == [0, 1] and second.revisions == 1 and second.check.passed
    applied.clear()
    stop = revise_until_verified(0, apply, lambda p, r: Check(False, "no"), lambda p, r, c: None)
    assert applied == [0] and stop.revisions == 0


def test_builtin_rollout_checks_score_each_scene_as_one_run_at_a_time():
    """G rolls pi out on the scene and its candidates in one batch; the scores are each scene's own runs."""
    from adaptenv.agents.registry import load_pretrained
    from adaptenv.agents.rollout import checking_episodes, mean_spl, run_policy

    house, world, ep, traj, analysis = procedural_scene(0, 5, [0, 7])  # one where plausible moves verify
    policy = load_pretrained("pretrained-scan")  # stochastic motions, seeded per episode
    ctx = GenerationContext(episode=ep, trajectory=traj, policy=policy, render=False, rollout_episodes=3)
    res = BuiltinGenerator(max_candidates=8).generate(house, analysis, steps=2, context=ctx,
                                                      rng=np.random.default_rng(3))
    eps = checking_episodes(ep, 3)
    assert res.steps[0].policy_score_before == mean_spl(run_policy(world, eps, policy))
    current = house
    for s in res.steps:
        if s.status != "applied":
            continue
        current = replay(current, [s.edit])
        alone = mean_spl(run_policy(compile_world(current, "child"), eps, policy))
        assert s.policy_score_after == alone
    scores = [s.policy_score_before for s in res.steps] + [s.policy_score_after for s in res.steps]
    assert any(s.status == "applied" for s in res.steps)
    assert len({x for x in scores if x is not None}) > 1, "the check should see different SPLs"


def _plain_to_wall(v, oid, aim):
    """``to_wall`` as one wall at a time, the definition its array form keeps."""
    from adaptenv.scene.geometry import heading

    ref, ctx = v.plausible, v.ctx
    i = ctx.index[oid]
    c, yaw = ctx.centers[i], float(ctx.yaws[i])
    h, half_w, half_d = heading(yaw), float(ctx.sizes[i, 0]) / 2.0, float(ctx.sizes[i, 1]) / 2.0
    room = v.geometry.room_of_point(float(c[0]), float(c[1]))
    best, best_d = None, np.inf
    for p0, p1 in zip(ref.walls.p0, ref.walls.p1, strict=True):
        length = float(np.hypot(*(p1 - p0)))
        if length < 2.0 * half_w + 0.1:
            continue
        u = (p1 - p0) / length
        n = np.array([-u[1], u[0]])
        if np.dot(n, aim - p0) < 0:
            n = -n
        if abs(float(np.dot(n, h))) < 0.99:
            continue
        t = float(np.clip(np.dot(aim - p0, u), half_w + 0.05, length - half_w - 0.05))
        center = p0 + t * u + n * (half_d + 0.03)
        dist = float(np.hypot(*(center - aim)))
        if dist < best_d and v.geometry.room_of_point(float(center[0]), float(center[1])) == room:
            best, best_d = (center - c, math.degrees(math.atan2(n[0], n[1])) % 360.0), dist
    return best


def test_to_wall_gives_what_one_wall_at_a_time_gives(real_house):
    """The array form of ``to_wall`` picks the same wall, displacement and yaw, bit for bit, as the per-wall loop,
    for every wall-standing object of a real house aimed at random points."""
    from adaptenv.adapt.generators.builtin import to_wall
    from adaptenv.adapt.validation import EditValidator

    v = EditValidator(real_house)
    rng = np.random.default_rng(0)
    found = 0
    for oid in sorted(v.plausible.anchored):
        c = v.ctx.centers[v.ctx.index[oid]]
        for aim in c + rng.uniform(-3.0, 3.0, (10, 2)):
            got, want = to_wall(v, oid, aim), _plain_to_wall(v, oid, aim)
            assert (got is None) == (want is None)
            if want is not None:
                found += 1
                assert np.array_equal(got[0], want[0]) and got[1] == want[1]
    assert found >= 20, "walls were found"
