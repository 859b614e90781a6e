"""Door edits: G opens or shuts interior doors through the validator's own door check."""

from __future__ import annotations

import math

import numpy as np
import pytest

from adaptenv.adapt.analysis import analyze_trajectory
from adaptenv.adapt.edits import Edit, EditLog, apply_edit, replay
from adaptenv.adapt.generators import GenerationContext
from adaptenv.adapt.generators.failure_modes import FailureModeGenerator, search_space
from adaptenv.adapt.objectives import RouteSpec
from adaptenv.adapt.validation import EditValidator, validate_scene
from adaptenv.agents.policy import ExpertPolicy
from adaptenv.agents.rollout import draw_episode, rollout
from adaptenv.errors import AdaptenvError
from adaptenv.scene.house import is_interior_leaf_door, set_door_openness
from adaptenv.scene.procedural import GenerationConfig, generate_house
from adaptenv.sim.geodesic import geodesic_distance
from adaptenv.sim.rollout import expert_policy, run_episode
from adaptenv.sim.world import compile_world
from tests.adapt.scenes import procedural_scene
from tests.adapt.test_failure_modes import _diagnosis


def _scene(seed: int, cfg: GenerationConfig):
    house = generate_house(seed, cfg)
    world = compile_world(house, "h")
    ep = draw_episode(world, np.random.default_rng([1, 1]))
    return house, world, ep, rollout(world, ep, ExpertPolicy())


def _generate(scene, family: str, *, door_edits: bool, steps: int = 2):
    house, world, ep, traj = scene
    ctx = GenerationContext(episode=ep, trajectory=traj, policy=None, render=False, diagnosis=_diagnosis(family))
    gen = FailureModeGenerator(max_candidates=10, door_edits=door_edits)
    return gen.generate(house, analyze_trajectory(traj, world), steps=steps, context=ctx, rng=np.random.default_rng(0))


def _valid_and_solvable(scene, res):
    house, _, ep, _ = scene
    assert validate_scene(res.house, episode_targets=[ep.target_type], start=ep.start[:2], original=house) == []
    assert run_episode(compile_world(res.house, "after"), ep, expert_policy(), record=False).metrics.success
    assert replay(house, res.edit_log).model_dump() == res.house.model_dump()


def test_the_validator_shuts_a_door_only_when_the_target_stays_reachable():
    house, world, ep, _, _ = procedural_scene(5, 4, [1, 1])
    v = EditValidator(house, episode_targets=[ep.target_type], start=ep.start[:2])
    verdicts = {}
    for door in [d for d in house.doors if is_interior_leaf_door(d)]:
        shut = house.model_copy(deep=True)
        set_door_openness(shut, door.id, 0.0)  # the plain reference: a finite geodesic distance to the target
        reachable = math.isfinite(geodesic_distance(compile_world(shut, "s"), ep.target_type, *ep.start[:2]))
        _, problems = v.propose_door(door.id, 0.0)
        assert (not problems) == reachable
        assert all(p.kind == "target_unreachable" for p in problems)
        verdicts[door.id] = reachable
    assert set(verdicts.values()) == {True, False}, "the house has a door of each kind"
    cut = next(d for d, ok in verdicts.items() if not ok)
    rejected = v.set_door(cut, 0.0, source="test")
    assert not rejected.accepted and rejected.problems and not rejected.changed
    assert v.house.model_dump() == house.model_dump()
    shut_id = next(d for d, ok in verdicts.items() if ok)
    edit = v.set_door(shut_id, 0.0, source="test")
    assert edit.accepted and edit.is_door and edit.changed and edit.openness_before == 1.0
    assert next(d for d in v.house.doors if d.id == shut_id).openness == 0.0
    # later object moves are validated against the scene with the shut door
    mover = next(oid for oid, m in zip(v.ctx.ids, v.ctx.movable, strict=True) if m)
    assert v.try_edit(mover, 3.0, 0.0, source="test").accepted
    assert validate_scene(v.house, episode_targets=[ep.target_type], start=ep.start[:2], original=house) == []
    assert [e.is_door for e in v.log] == [True, True, False]


def test_doors_that_cannot_move_and_door_edits_that_replay():
    house, _, ep, _, _ = procedural_scene(5, 4, [1, 1])
    v = EditValidator(house, episode_targets=[ep.target_type], start=ep.start[:2])
    front = next(d for d in house.doors if not is_interior_leaf_door(d))
    assert v.propose_door(front.id, 1.0)[1][0].kind == "invalid"
    assert v.propose_door("door|none", 0.0)[1][0].kind == "invalid"
    door = next(d for d in house.doors if is_interior_leaf_door(d))
    log = EditLog(edits=[Edit(object_id=door.id, openness=0.0, openness_before=1.0)])
    again = EditLog.from_json(log.to_json())
    assert again == log and next(d for d in replay(house, again).doors if d.id == door.id).openness == 0.0
    with pytest.raises(AdaptenvError, match="no door"):
        apply_edit(house, Edit(object_id="door|none", openness=0.0, openness_before=1.0))


def test_search_edits_open_shut_doors_only_when_asked():
    scene = _scene(0, GenerationConfig(n_rooms=6, closed_door_prob=0.4))
    house, world, ep, traj = scene
    assert not any(s.edit is not None and s.edit.is_door for s in _generate(scene, "search", door_edits=False).steps)
    res = _generate(scene, "search", door_edits=True)
    opened = [s.edit for s in res.steps if s.status == "applied" and s.edit.is_door]
    assert opened and all(e.openness == 1.0 and e.openness_before == 0.0 for e in opened)
    assert all(next(d for d in res.house.doors if d.id == e.object_id).openness == 1.0 for e in opened)
    route = RouteSpec.from_episode(ep.target_type, ep.start, traj)
    assert search_space(compile_world(res.house, "after"), route) > search_space(world, route)
    _valid_and_solvable(scene, res)


def test_timeout_edits_shut_a_door_that_forces_a_detour():
    scene = _scene(2, GenerationConfig(n_rooms=7, extra_door_prob=1.0, doorframe_prob=0.0, open_kitchen_prob=0.0))
    house, world, ep, _ = scene
    res = _generate(scene, "timeout", door_edits=True)
    shut = [s.edit for s in res.steps if s.status == "applied" and s.edit.is_door]
    assert shut and all(e.openness == 0.0 for e in shut)
    before = geodesic_distance(world, ep.target_type, *ep.start[:2])
    after = geodesic_distance(compile_world(res.house, "after"), ep.target_type, *ep.start[:2])
    assert math.isfinite(after) and after > before
    _valid_and_solvable(scene, res)


def test_a_validator_over_a_door_edited_scene_judges_moves_with_the_doors_as_they_are():
    house, _, ep, _, _ = procedural_scene(5, 4, [1, 1])
    v = EditValidator(house, episode_targets=[ep.target_type], start=ep.start[:2])
    door = next(d.id for d in house.doors if is_interior_leaf_door(d) and not v.propose_door(d.id, 0.0)[1])
    assert v.set_door(door, 0.0).accepted
    again = EditValidator(v.house, episode_targets=[ep.target_type], start=ep.start[:2], original=house)
    mover = next(oid for oid, m in zip(again.ctx.ids, again.ctx.movable, strict=True) if m)
    edit = again.try_edit(mover, 3.0, 0.0)
    assert edit.accepted and not any("can no longer be reached" in p for p in edit.problems)
