"""F over several episodes: hard episode draws, aggregation of failure modes, regret and the worst episode."""

from __future__ import annotations

import numpy as np
import pytest

from adaptenv.adapt.analysis import Analysis, Outcome
from adaptenv.adapt.diagnosis import (
    NoAnalyzer,
    aggregate,
    diagnose_scene,
    hard_episodes,
    other_room,
)
from adaptenv.agents.policy import StepFunctionPolicy
from adaptenv.sim.geodesic import optimal_path_length
from adaptenv.sim.spec import ACTIONS
from adaptenv.sim.task import Episode, sample_episode
from adaptenv.sim.trajectory import EpisodeMetrics, Pose, Step, Trajectory
from adaptenv.sim.world import compile_world


@pytest.fixture(scope="module")
def world():
    from adaptenv.scene.procedural import GenerationConfig, generate_house

    return compile_world(generate_house(3, GenerationConfig(n_rooms=5)), "h")


def _traj(success: bool, spl: float, n: int) -> Trajectory:
    pose = Pose(x=0.0, z=0.0, yaw=0.0)
    m = EpisodeMetrics(success=success, spl=spl, sel=spl, episode_length=n, path_length=1.0, final_geodesic=0.0,
                       collisions=0, min_clearance=None, rooms_visited=1, first_sight_step=None,
                       optimal_path_length=1.0)
    return Trajectory(house="h", target_type="Bed", start=pose, steps=[Step(pose=pose, action="m")] * n, metrics=m)


def _analysis(mode: str | None) -> Analysis:
    return Analysis(task="t", outcome=Outcome(success=mode is None, failure_mode=mode, summary="", steps=1))


def test_aggregate_counts_modes_families_dominance_regret_and_worst():
    modes = ["never_saw_target", "never_saw_target", "never_saw_target", "ended_too_far", "ended_without_sight",
             "looping", None, None]
    trajs = [_traj(m is None, 0.9 if m is None else 0.0, 50 + k) for k, m in enumerate(modes)]
    expert = [True] * 7 + [False]
    expert[5] = False  # the looping failure is one the expert fails too: no regret for it
    eps = [Episode("Bed", (0.0, 0.0, 0.0), k) for k in range(8)]
    analyses = {k: _analysis(m) for k, m in enumerate(modes) if m}
    d = aggregate("h", eps, trajs, expert, analyses, keep=2)
    assert d.mode_counts == {"never_saw_target": 3, "ended_too_far": 1, "ended_without_sight": 1, "looping": 1}
    assert d.family_counts == {"search": 3, "premature_end": 2, "looping": 1}
    assert d.dominant == ["search", "premature_end"], "looping has 1 of 6 failures, under the 30% share"
    assert d.regret == pytest.approx(5 / 8) and d.success_rate == pytest.approx(2 / 8)
    assert d.worst == 5, "failed, SPL 0, and the longest of those"
    assert len(d.analyses) == 2 and d.analyses[0].outcome.failure_mode == "looping"
    assert d.failures == 6 and "dominant: search, premature_end" in d.summary()


def test_aggregate_of_a_solved_scene_has_no_mode_and_no_regret():
    trajs = [_traj(True, 0.5 + 0.1 * k, 40) for k in range(3)]
    d = aggregate("h", [Episode("Bed", (0.0, 0.0, 0.0))] * 3, trajs, [True] * 3, {0: _analysis(None)})
    assert d.dominant == [] and d.family_counts == {} and d.regret == 0.0 and d.worst == 0


def test_hard_episodes_prefer_other_rooms_and_long_routes(world):
    eps = hard_episodes(world, np.random.default_rng(0), 4)
    plain = [sample_episode(world, np.random.default_rng([1, k])) for k in range(24)]
    assert len(eps) == 4
    assert sum(other_room(world, e) for e in eps) >= sum(other_room(world, e) for e in plain) * 4 / 24
    hard_len = np.mean([optimal_path_length(world, e) for e in eps])
    assert hard_len > np.mean([optimal_path_length(world, e) for e in plain])


def _always(action: str) -> StepFunctionPolicy:
    code = ACTIONS.index(action)
    return StepFunctionPolicy(lambda world, episode, x, z, yaw, collided, step: code)


def test_diagnosis_names_premature_ends_of_an_agent_that_stops_at_once(world):
    eps = hard_episodes(world, np.random.default_rng(1), 3)
    d = diagnose_scene(world, eps, _always("end"))
    assert d.diagnosis.success_rate == 0.0 and d.diagnosis.dominant == ["premature_end"]
    assert d.diagnosis.family_counts == {"premature_end": 3}
    assert d.diagnosis.regret == pytest.approx(d.diagnosis.expert_success_rate) and d.diagnosis.regret > 0
    assert d.worst_trajectory is d.trajectories[d.diagnosis.worst] and d.analysis.outcome.failure_mode


def test_diagnosis_without_f_keeps_the_regret_and_drops_the_modes(world):
    eps = hard_episodes(world, np.random.default_rng(1), 2)
    d = diagnose_scene(world, eps, _always("end"), analyzer=NoAnalyzer())
    assert d.diagnosis.regret > 0 and d.diagnosis.mode_counts == {} and d.diagnosis.dominant == []
    assert {s.kind for s in d.analysis.suggestions} == {"narrow_passage", "occlude_target", "lengthen_route",
                                                         "add_clutter"}
