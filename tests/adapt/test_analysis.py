"""The built-in analyzer F on scripted episodes in small synthetic houses."""

from __future__ import annotations

import pytest

from adaptenv.adapt.analysis import (
    MAX_ADDRESSED,
    Analysis,
    Analyzer,
    BuiltinAnalyzer,
    analyze_trajectory,
    make_analyzer,
)
from adaptenv.errors import ConfigError
from adaptenv.sim.rollout import expert_policy, random_policy, run_episode
from adaptenv.sim.spec import END, MOVE_AHEAD, ROTATE_LEFT
from adaptenv.sim.task import Episode
from adaptenv.sim.world import compile_world
from tests.sim import helpers as H


def _const(action: int):
    return lambda world, episode, x, z, yaw, collided, step: action


@pytest.fixture(scope="module")
def desk_room():
    """A 5 x 4 m room: a tall desk low on the left, a garbage can (the target) lower right."""
    house = H.one_room((5.0, 4.0), objects=[H.Obj(H.TALL_FURNITURE, 1.5, 1.0), H.Obj(H.LOW_TARGET, 3.5, 0.8)],
                       agent=(1.5, 2.2, 150.0))
    return compile_world(house, "desk-room")


@pytest.fixture(scope="module")
def long_room():
    """A 10 x 4 m room with the garbage can at the far end (beyond the 5 m sight range from x < 4)."""
    house = H.one_room((10.0, 4.0), objects=[H.Obj(H.LOW_TARGET, 9.5, 2.0)], agent=(1.0, 2.0, 90.0))
    return compile_world(house, "long-room")


def test_stuck_against_desk_names_the_desk(desk_room):
    ep = Episode("GarbageCan", (1.5, 1.6, 150.0))  # 0.25 m from the desk's top edge, facing it
    traj = run_episode(desk_room, ep, _const(MOVE_AHEAD), max_steps=60)
    a = analyze_trajectory(traj, desk_room)
    assert not a.outcome.success
    assert a.outcome.failure_mode == "stuck"
    collisions = [c for c in a.concerns if c.kind == "collision"]
    assert collisions and "Desk|0" in collisions[0].objects
    assert collisions[0].steps == [0, 59] and collisions[0].where is not None
    close = [c for c in a.concerns if c.kind == "close_proximity"]
    assert close and close[0].objects == ["Desk|0"]
    narrow = next(s for s in a.suggestions if s.kind == "narrow_passage")
    assert {c.id for c in collisions + close} <= set(narrow.addresses)


def test_ended_too_far_is_a_premature_end(long_room):
    traj = run_episode(long_room, Episode("GarbageCan", (1.0, 2.0, 90.0)), _const(END))
    a = analyze_trajectory(traj, long_room)
    assert a.outcome.failure_mode == "ended_too_far"
    assert any(c.kind == "premature_end" for c in a.concerns)


def test_never_saw_target_when_out_of_range(long_room):
    traj = run_episode(long_room, Episode("GarbageCan", (1.0, 2.0, 90.0)), _const(ROTATE_LEFT), max_steps=40)
    a = analyze_trajectory(traj, long_room)
    assert a.outcome.failure_mode == "never_saw_target"
    late = next(c for c in a.concerns if c.kind == "late_sight")
    assert late.severity == 1.0 and late.objects == ["GarbageCan|0"]
    assert "late_sight" not in {c.kind for c in a.concerns if c.id in _addressed(a, "occlude_target")}


def test_timeout_when_target_seen_but_never_reached(long_room):
    traj = run_episode(long_room, Episode("GarbageCan", (6.0, 2.0, 90.0)), _const(ROTATE_LEFT), max_steps=40)
    a = analyze_trajectory(traj, long_room)
    assert traj.metrics.first_sight_step is not None
    assert a.outcome.failure_mode == "timeout"
    assert "timeout" in a.outcome.summary


def test_random_walk_has_detour_and_revisits(long_room):
    traj = run_episode(long_room, Episode("GarbageCan", (1.0, 2.0, 90.0)), random_policy(3), max_steps=400)
    a = analyze_trajectory(traj, long_room)
    kinds = {c.kind for c in a.concerns}
    assert {"detour", "revisit"} <= kinds
    detour = next(c for c in a.concerns if c.kind == "detour")
    assert detour.steps == [0, len(traj.steps) - 1]
    lengthen = next(s for s in a.suggestions if s.kind == "lengthen_route")
    assert detour.id in lengthen.addresses


def test_suggestions_refer_to_existing_concerns_and_are_sorted(desk_room, long_room):
    for world, ep, pol in [(desk_room, Episode("GarbageCan", (1.5, 1.6, 150.0)), _const(MOVE_AHEAD)),
                           (long_room, Episode("GarbageCan", (1.0, 2.0, 90.0)), random_policy(3))]:
        a = analyze_trajectory(run_episode(world, ep, pol, max_steps=200), world)
        ids = {c.id for c in a.concerns}
        assert ids == {f"c{k + 1}" for k in range(len(a.concerns))}
        assert all(set(s.addresses) <= ids for s in a.suggestions)
        assert [s.priority for s in a.suggestions] == sorted((s.priority for s in a.suggestions), reverse=True)


def test_success_has_no_failure_mode_and_text_mentions_everything(long_room):
    traj = run_episode(long_room, Episode("GarbageCan", (1.0, 2.0, 90.0)), expert_policy())
    a = analyze_trajectory(traj, long_room)
    assert a.outcome.success and a.outcome.failure_mode is None and a.outcome.spl == traj.metrics.spl
    text = a.to_text()
    assert "Outcome: success" in text
    for item in a.concerns + a.suggestions:
        assert f"[{item.id}]" in text


def test_deterministic_and_round_trips(long_room):
    traj = run_episode(long_room, Episode("GarbageCan", (1.0, 2.0, 90.0)), random_policy(5), max_steps=200)
    a, b = analyze_trajectory(traj, long_room), BuiltinAnalyzer().analyze(traj, long_room)
    assert a.model_dump() == b.model_dump()
    assert Analysis.model_validate_json(a.model_dump_json()) == a


def test_analyzer_protocol_and_factory():
    assert isinstance(BuiltinAnalyzer(), Analyzer)
    assert isinstance(make_analyzer("builtin"), BuiltinAnalyzer)
    with pytest.raises(ConfigError, match="unknown analyzer"):
        make_analyzer("oracle")


def _addressed(a: Analysis, kind: str) -> set[str]:
    return {cid for s in a.suggestions if s.kind == kind for cid in s.addresses}


def test_concerns_are_aggregated_per_kind_and_object(desk_room):
    """A long failed walk gives one concern per (kind, object) with its bouts, and suggestions cite a handful."""
    traj = run_episode(desk_room, Episode("GarbageCan", (1.5, 1.6, 150.0)), random_policy(0), max_steps=500)
    a = analyze_trajectory(traj, desk_room)
    keys = [(c.kind, tuple(c.objects)) for c in a.concerns]
    assert len(keys) == len(set(keys))
    assert any(c.count > 1 for c in a.concerns), "this walk bumps into the desk in several bouts"
    for c in a.concerns:
        assert c.count == max(1, len(c.occurrences))
        if c.occurrences:
            assert c.steps == [c.occurrences[0][0], c.occurrences[-1][1]]
    blocked = [i for i, s in enumerate(traj.steps) if s.action in ("m", "b") and not s.moved]
    spans = [o for c in a.concerns if c.kind == "collision" for o in c.occurrences]
    assert blocked and all(any(lo <= i <= hi for lo, hi in spans) for i in blocked)
    assert all(len(s.addresses) <= MAX_ADDRESSED for s in a.suggestions)
    assert max(len(s.addresses) for s in a.suggestions) == MAX_ADDRESSED  # capped, not merely small
