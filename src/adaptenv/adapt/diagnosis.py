"""F over several episodes of one scene: where pi_t is weak, which failure modes dominate, and the regret.

One episode says little (pi_t solved 87.5% of the single episodes F saw in the full experiment).
:func:`diagnose_scene` plays several episodes drawn for difficulty (:func:`hard_episodes`: long
routes, targets in another room than the start), runs the shortest-path expert on the same
episodes, analyses the failed and worst ones with the built-in F
(:func:`~adaptenv.adapt.analysis.analyze_trajectory`) and aggregates them into a
:class:`SceneDiagnosis`::

    diag = diagnose_scene(world, hard_episodes(world, rng, 6), policy)
    diag.dominant        # e.g. ["search", "premature_end"]
    diag.regret          # expert success minus agent success over the episodes

Failure modes are grouped into families G acts on (:data:`MODE_FAMILY`): ``search`` (never saw the
target), ``premature_end`` (ended too far or without sight), ``looping``, ``stuck`` and
``timeout``. The worst episode (failed, lowest SPL, longest) and its analysis are what G's
route-based objectives and rollout checks use.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import BaseModel, Field

from adaptenv.adapt.analysis import (
    Analysis,
    Analyzer,
    BuiltinAnalyzer,
    FailureMode,
    Outcome,
    Suggestion,
)
from adaptenv.agents.evaluate import run_episodes
from adaptenv.agents.policy import ExpertPolicy, Policy
from adaptenv.agents.regret import success_regret
from adaptenv.agents.rollout import run_policy
from adaptenv.sim.geodesic import optimal_path_length
from adaptenv.sim.task import Episode, sample_episode
from adaptenv.sim.trajectory import Trajectory
from adaptenv.sim.world import NavWorld

ModeFamily = Literal["search", "premature_end", "looping", "stuck", "timeout"]

#: F's failure modes grouped into the families G has edits for.
MODE_FAMILY: dict[str, ModeFamily] = {
    "never_saw_target": "search", "ended_too_far": "premature_end", "ended_without_sight": "premature_end",
    "looping": "looping", "stuck": "stuck", "timeout": "timeout"}
MODE_FAMILIES: tuple[ModeFamily, ...] = ("search", "premature_end", "looping", "stuck", "timeout")
#: A family dominates when it holds at least this share of the failures (the most frequent one always does).
DOMINANT_SHARE = 0.3
#: Episodes analysed in full (the failed ones first, then the lowest SPL).
MAX_ANALYSED = 4
#: Candidate episodes drawn per episode kept by :func:`hard_episodes`.
DRAWS_PER_EPISODE = 6


class EpisodeDiagnosis(BaseModel):
    """One episode of the diagnosis: the task, pi_t's outcome and failure mode, and the expert's success."""

    target_type: str
    start: tuple[float, float, float]
    seed: int | None = None
    success: bool
    spl: float
    steps: int
    expert_success: bool
    failure_mode: FailureMode | None = None
    family: ModeFamily | None = None
    first_sight_step: int | None = None
    optimal: float | None = None
    """Geodesic length (m) of the shortest route."""
    other_room: bool = False
    """The nearest target instance stands in another room than the start."""


class SceneDiagnosis(BaseModel):
    """F's multi-episode verdict on one scene: counts per failure mode, dominant families, regret, worst episode."""

    house: str
    episodes: list[EpisodeDiagnosis]
    mode_counts: dict[str, int] = Field(default_factory=dict)
    """Failed episodes per F failure mode (``never_saw_target``, ``ended_too_far``, ...)."""
    family_counts: dict[str, int] = Field(default_factory=dict)
    """Failed episodes per family (``search``, ``premature_end``, ``looping``, ``stuck``, ``timeout``)."""
    dominant: list[ModeFamily] = Field(default_factory=list)
    """Families with at least :data:`DOMINANT_SHARE` of the failures, most frequent first (empty: no failure)."""
    success_rate: float
    expert_success_rate: float
    regret: float
    """Mean over episodes of max(0, expert success - agent success)."""
    worst: int
    """Index of the worst episode (failed, lowest SPL, longest): the one G's route objectives use."""
    analyses: list[Analysis] = Field(default_factory=list)
    """F's analyses of the failed and worst episodes (worst first), at most :data:`MAX_ANALYSED`."""
    concern_counts: dict[str, int] = Field(default_factory=dict)
    """Concerns per kind over the analysed episodes."""

    @property
    def failures(self) -> int:
        return sum(1 for e in self.episodes if not e.success)

    def summary(self) -> str:
        """One line a person reads: regret, success and the dominant failure families."""
        fam = ", ".join(f"{k} {v}" for k, v in sorted(self.family_counts.items(), key=lambda kv: -kv[1])) or "none"
        return (f"{self.house}: regret {self.regret:.2f}, pi_t {self.success_rate:.0%} vs expert "
                f"{self.expert_success_rate:.0%} over {len(self.episodes)} episodes; failures: {fam}"
                + (f"; dominant: {', '.join(self.dominant)}" if self.dominant else ""))


@dataclass
class Diagnosed:
    """A diagnosis with the trajectories it was built from (what a generator needs besides the typed verdict)."""

    diagnosis: SceneDiagnosis
    episodes: list[Episode]
    trajectories: list[Trajectory]

    @property
    def worst_episode(self) -> Episode:
        return self.episodes[self.diagnosis.worst]

    @property
    def worst_trajectory(self) -> Trajectory:
        return self.trajectories[self.diagnosis.worst]

    @property
    def analysis(self) -> Analysis:
        """F's analysis of the worst episode."""
        return self.diagnosis.analyses[0]


def _nearest_target_room(world: NavWorld, episode: Episode) -> str | None:
    insts = world.instances_of(episode.target_type)
    if not insts:
        return None
    x, z = episode.start[0], episode.start[1]
    near = min(insts, key=lambda t: (t.center[0] - x) ** 2 + (t.center[1] - z) ** 2)
    return world.geometry.room_of_point(*near.center)


def other_room(world: NavWorld, episode: Episode) -> bool:
    """Whether the nearest instance of the target stands in another room than the start."""
    start_room = world.geometry.room_of_point(episode.start[0], episode.start[1])
    target_room = _nearest_target_room(world, episode)
    return start_room is not None and target_room is not None and start_room != target_room


def hard_episodes(world: NavWorld, rng: np.random.Generator, n: int, *, draws: int = DRAWS_PER_EPISODE
                  ) -> list[Episode]:
    """``n`` solvable episodes drawn for difficulty: of ``n * draws`` draws, targets in other rooms first, then longest.

    Target types are kept diverse: an episode whose target type is already chosen ranks after one
    of a new type with the same room relation.
    """
    pool = []
    for k in range(max(n, 1) * draws):
        ep = sample_episode(world, rng)
        d = float(optimal_path_length(world, ep))
        if np.isfinite(d):
            pool.append((other_room(world, ep), d, k, ep))
    pool.sort(key=lambda p: (not p[0], -p[1], p[2]))
    chosen: list[Episode] = []
    types: Counter[str] = Counter()
    while pool and len(chosen) < n:
        best = min(range(len(pool)), key=lambda i: (not pool[i][0], types[pool[i][3].target_type], -pool[i][1]))
        ep = pool.pop(best)[3]
        chosen.append(ep)
        types[ep.target_type] += 1
    return chosen


def expert_successes(world: NavWorld, episodes: list[Episode]) -> list[bool]:
    """The shortest-path expert's measured success on each episode (0 regret where it fails too)."""
    results, _ = run_episodes([world], [(0, ep) for ep in episodes], ExpertPolicy(), batch=max(len(episodes), 1))
    return [bool(r.success) for r in results]


def _worst(trajs: list[Trajectory]) -> int:
    """Failed before succeeded, then lowest SPL, then longest."""
    return min(range(len(trajs)), key=lambda i: (bool(trajs[i].metrics.success), trajs[i].metrics.spl,
                                                 -len(trajs[i].steps), i))


def aggregate(house: str, episodes: list[Episode], trajs: list[Trajectory], expert: list[bool],
              analyses: dict[int, Analysis], world: NavWorld | None = None, *,
              keep: int = MAX_ANALYSED) -> SceneDiagnosis:
    """Counts per failure mode and family, dominant families, regret and the worst episode (pure; see module doc).

    ``analyses`` maps episode index to F's analysis; the failure mode of an episode is its
    analysis's (episodes not analysed count by their success only). The worst episode's analysis
    and then the others by index are kept, ``keep`` in all; concerns are counted over those kept.
    """
    rows = []
    for k, (ep, tr, ex) in enumerate(zip(episodes, trajs, expert, strict=True)):
        m = tr.metrics
        mode = analyses[k].outcome.failure_mode if k in analyses and not m.success else None
        rows.append(EpisodeDiagnosis(
            target_type=ep.target_type, start=tuple(float(v) for v in ep.start), seed=ep.seed, success=bool(m.success),
            spl=float(m.spl), steps=len(tr.steps), expert_success=bool(ex), failure_mode=mode,
            family=MODE_FAMILY.get(mode) if mode else None, first_sight_step=m.first_sight_step,
            optimal=m.optimal_path_length, other_room=other_room(world, ep) if world is not None else False))
    modes = Counter(r.failure_mode for r in rows if r.failure_mode)
    fams = Counter(r.family for r in rows if r.family)
    total = sum(fams.values())
    ranked = sorted(fams, key=lambda f: (-fams[f], MODE_FAMILIES.index(f)))
    dominant = [f for i, f in enumerate(ranked) if i == 0 or fams[f] >= DOMINANT_SHARE * total]
    worst = _worst(trajs)
    order = ([worst] if worst in analyses else []) + [k for k in sorted(analyses) if k != worst]
    order = order[:max(1, keep)]
    concerns = Counter(c.kind for k in order if k in analyses for c in analyses[k].concerns)
    return SceneDiagnosis(
        house=house, episodes=rows, mode_counts=dict(modes), family_counts=dict(fams), dominant=dominant,
        success_rate=float(np.mean([r.success for r in rows])), expert_success_rate=float(np.mean(expert)),
        regret=success_regret([float(r.success) for r in rows], [float(e) for e in expert]), worst=worst,
        analyses=[analyses[k] for k in order], concern_counts=dict(concerns))


def generic_analysis(trajectory: Trajectory) -> Analysis:
    """F's output without F: every built-in objective at equal priority, no concerns, no failure mode."""
    kinds = ("narrow_passage", "occlude_target", "lengthen_route", "add_clutter")
    m = trajectory.metrics
    return Analysis(task=f"Find a {trajectory.target_type} (ObjectNav) in house {trajectory.house}.",
                    outcome=Outcome(success=bool(m and m.success), summary="not analysed (G on regret alone)",
                                    steps=len(trajectory.steps), spl=m.spl if m else None),
                    suggestions=[Suggestion(id=f"s{k + 1}", kind=kind, description=f"generic objective {kind}",
                                            priority=0.5) for k, kind in enumerate(kinds)], source="none")


class NoAnalyzer:
    """The ablation without F (``ours-nof``): :func:`generic_analysis` for every episode, so G sees regret only."""

    name = "none"

    def analyze(self, trajectory: Trajectory, world: NavWorld) -> Analysis:
        return generic_analysis(trajectory)


def diagnose_scene(world: NavWorld, episodes: list[Episode], policy: Policy, *, analyzer: Analyzer | None = None,
                   trajectories: list[Trajectory] | None = None, max_analysed: int = MAX_ANALYSED) -> Diagnosed:
    """Roll pi_t (and the expert) out on every episode, analyse the failed and worst ones, aggregate.

    Every failed episode is analysed (its failure mode is counted); ``max_analysed`` analyses are kept.

    Args:
        world: the compiled scene.
        episodes: the tasks (e.g. :func:`hard_episodes`); at least one.
        policy: pi_t.
        analyzer: F (built-in by default).
        trajectories: pi_t's trajectories on ``episodes`` when the caller already has them.
    """
    if not episodes:
        raise ValueError("diagnose_scene: pass at least one episode")
    analyzer = analyzer or BuiltinAnalyzer()
    trajs = trajectories if trajectories is not None else run_policy(world, episodes, policy)
    expert = expert_successes(world, episodes)
    worst = _worst(trajs)
    failed = [k for k, t in enumerate(trajs) if not t.metrics.success]
    analyses = {k: analyzer.analyze(trajs[k], world) for k in dict.fromkeys([worst] + failed)}
    return Diagnosed(aggregate(world.name, episodes, trajs, expert, analyses, world, keep=max_analysed),
                     list(episodes), trajs)


__all__ = ["DOMINANT_SHARE", "MODE_FAMILIES", "MODE_FAMILY", "Diagnosed", "EpisodeDiagnosis", "ModeFamily",
           "NoAnalyzer", "SceneDiagnosis", "aggregate", "diagnose_scene", "expert_successes", "generic_analysis",
           "hard_episodes", "other_room"]
