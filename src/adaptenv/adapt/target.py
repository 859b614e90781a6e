"""Difficulty on request: edit a house until the agent's measured success on it is near a target P.

The agent's success on a house is measured on a fixed set of ``N`` episodes (seeded draws, the same
episodes after every edit: paired). Each round asks G for one single-object edit, aimed at one of
the measured episodes (one the agent solves when success is above P, one it fails when below),
measures the edited house again and keeps the edit only when it brings success closer to P (or
leaves success where it was and moves the mean SPL the way P lies); an edit that overshoots P by
more than it gained is dropped and G is asked again, aimed at the next episode. It stops when
``|success - P| <= tolerance``, when ``max_edits`` edits are kept, or after ``patience`` rounds in a
row without a kept edit. Since only edits that come closer are kept, the house returned is the
closest the run reached. With ``choices=K`` a round asks G for K edits instead, each aimed at the next
episode in turn, measures every valid one and keeps the closest to P (smallest gap, then the SPL moved
furthest the way P lies) when it comes closer.

The agent samples its actions, so success on the measured draws moves by an episode or two with any
edit, and a run that keeps only the edits that come closer selects on that noise too. A run ends by
measuring the original and the returned house again on ``fresh_draws`` fresh action draws per episode
(the same starts and targets, new sampling seeds), which nothing was selected on. With ``draws=D``
each measured episode is run D times with its own sampling seeds, and success is the mean over all
N x D runs, which one edit's noise moves less. With ``confirm=True`` an edit that comes closer is measured
again on a second set of action draws (the same episodes, other sampling seeds) and kept only when it comes
closer there too, so an edit whose gain was one draw's noise is dropped. With ``refresh=True`` the house is
measured again on new action draws after every kept edit, and those draws become the ones the next edits are
measured on: the kept edit was chosen for measuring closer, so its own measurement is biased toward the target,
and the next edits would otherwise be compared with that biased figure::

    result = adapt_to_success(house, policy, make_generator("builtin"), 0.5, episodes=20, max_edits=10)
    result.success_trace   # [1.0, 0.95, 0.85, ...]: success before and after each kept edit
    result.edits, result.gap, result.stopped
    result.fresh_after.success   # the returned house on fresh draws: the difficulty a user gets

Every G works by name: the loop only calls :meth:`~adaptenv.adapt.generators.Generator.generate`.
A G that makes no edit in one step is asked for one more step the next time (up to ``MAX_G_STEPS``;
the failure-mode G, for one, aims its second step at another failure family), and only the first
edit of a call is kept, so each kept edit moves one object (or one door), for every G.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from adaptenv.adapt.analysis import Analyzer, BuiltinAnalyzer
from adaptenv.adapt.edits import Edit, replay
from adaptenv.adapt.generators import GenerationContext, Generator, StepRecord
from adaptenv.adapt.llm.accounting import scene_usage
from adaptenv.adapt.llm.usage import Usage
from adaptenv.adapt.validation import validate_scene
from adaptenv.agents.policy import Policy, as_policy
from adaptenv.agents.rollout import draw_episode, run_policy
from adaptenv.errors import ConfigError
from adaptenv.scene.house import House
from adaptenv.scene.validate import validate_house
from adaptenv.sim.geodesic import is_solvable
from adaptenv.sim.task import Episode
from adaptenv.sim.trajectory import Trajectory
from adaptenv.sim.world import NavWorld, compile_world

#: Defaults of the command line and the loop: episodes measured, tolerance, rounds without a kept edit.
EPISODES = 20
TOLERANCE = 0.10
PATIENCE = 6
#: Most steps one G call is asked for when G keeps making no edit.
MAX_G_STEPS = 4
#: A change of mean SPL smaller than this is no change.
SPL_TOL = 1e-3
#: Fresh action draws per measured episode in the check that ends a run.
FRESH_DRAWS = 3
#: Fresh action draws of the one episode an adaptation step works on (``adaptenv adapt``, ``adaptenv bench adapt``).
EPISODE_FRESH_DRAWS = 8
#: Seed offsets per measured, per fresh, per confirming and per refreshed draw (multiples of 1000, so ``seed % 1000``
#: still names the episode; the four primes keep the measured, fresh, confirming and refreshed seeds apart).
DRAW_SEED_STRIDE, FRESH_SEED_STRIDE, CONFIRM_SEED_STRIDE = 1000 * 1009, 1000 * 7919, 1000 * 3011
REFRESH_SEED_STRIDE = 1000 * 5003
#: Most action draws per measured episode.
MAX_DRAWS = 16
#: The default stop gap as a share of the tolerance: a run's own measurement is biased toward the target by the
#: selection of its edits, so stopping at the tolerance's edge leaves fresh draws outside it (chosen on training
#: houses, docs/results/target-success/DECLARED-13.md).
STOP_SHARE = 0.5


def check_target(target: float, tolerance: float = TOLERANCE, *, what: str = "--target-success",
                 tol_what: str = "--target-tolerance") -> None:
    """Raise one ConfigError line unless 0 < target < 1 and 0 <= tolerance < 1 (both finite)."""
    if not (isinstance(target, (int, float)) and np.isfinite(target) and 0.0 < float(target) < 1.0):
        raise ConfigError(f"{what} {target}: the target success rate must lie strictly between 0 and 1, "
                          "e.g. 0.5")
    if not (isinstance(tolerance, (int, float)) and np.isfinite(tolerance) and 0.0 <= float(tolerance) < 1.0):
        raise ConfigError(f"{tol_what} {tolerance}: the tolerance must lie in [0, 1), e.g. 0.1")


def stop_gap_of(stop_gap: float | None, tolerance: float) -> float:
    """The gap at which editing stops: ``stop_gap``, or STOP_SHARE of the tolerance when it is None."""
    return STOP_SHARE * float(tolerance) if stop_gap is None else float(stop_gap)


def check_stop_gap(stop_gap: float | None, tolerance: float = TOLERANCE, *,
                   what: str = "--target-stop-gap") -> None:
    """Raise one ConfigError line unless ``stop_gap`` is None or lies in [0, tolerance]."""
    if stop_gap is not None and not (isinstance(stop_gap, (int, float)) and np.isfinite(stop_gap)
                                     and 0.0 <= float(stop_gap) <= float(tolerance) + 1e-12):
        raise ConfigError(f"{what} {stop_gap}: editing must stop within the tolerance, so the stop gap must lie "
                          f"in [0, {tolerance:g}], e.g. {tolerance / 2:g}")


@dataclass(frozen=True)
class Measurement:
    """The agent on the measured episodes of one house: per-episode success and SPL."""

    successes: tuple[bool, ...]
    spls: tuple[float, ...]
    steps: int
    """Environment steps the measurement took."""

    @property
    def success(self) -> float:
        return float(np.mean(self.successes))

    @property
    def spl(self) -> float:
        return float(np.mean(self.spls))


@dataclass(frozen=True)
class TargetRound:
    """One of G's proposed edits (one per round, or ``choices`` per round), whether it was kept and what the house
    measured with it."""

    round: int
    """The round it was proposed in (from 1)."""
    episode: int
    """Index of the measured run G aimed at: episode ``k % N`` (of N), its draw ``k // N``."""
    edit: Edit | None
    """G's edit (None when G made none)."""
    kept: bool
    reason: str
    success: float | None = None
    """Measured success with the edit (None when there was nothing to measure)."""
    spl: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"round": self.round, "episode": self.episode, "kept": self.kept, "reason": self.reason,
                "success": self.success, "spl": self.spl,
                "edit": self.edit.model_dump(mode="json") if self.edit is not None else None}


@dataclass
class TargetResult:
    """What :func:`adapt_to_success` reached: the house, the success before and after each kept edit, why it stopped."""

    house: House
    original: House
    generator: str
    target: float
    tolerance: float
    episodes: list[Episode]
    before: Measurement
    after: Measurement
    rounds: list[TargetRound] = field(default_factory=list)
    stopped: str = ""
    """``within the stop gap G`` (``within tolerance`` when G is the tolerance), ``edit budget used`` or ``no kept edit in
    N rounds``."""
    trajectories_before: list[Trajectory] = field(default_factory=list)
    trajectories_after: list[Trajectory] = field(default_factory=list)
    check_steps: int = 0
    """pi_t's environment steps in G's own rollout checks."""
    measure_steps: int = 0
    """pi_t's environment steps in every measurement (the first, and one per measured edit)."""
    usage: Usage = field(default_factory=Usage)
    """F's and G's LLM calls over all rounds (empty for the built-ins)."""
    draws: int = 1
    """Action draws per measured episode: ``before`` and ``after`` hold ``draws`` runs of each episode."""
    fresh_before: Measurement | None = None
    """The original house on fresh action draws (:func:`fresh_measurement`; None when ``fresh_draws`` is 0)."""
    fresh_after: Measurement | None = None
    """The returned house on the same fresh draws."""
    confirm: bool = False
    """Whether each edit that came closer was kept only when it also came closer on the confirming draws."""
    refresh: bool = False
    """Whether the house was measured on new draws after each kept edit (``after`` is then that measurement)."""
    stop_gap: float | None = None
    """Editing stopped once the measured gap was at most this (None: half the tolerance)."""

    @property
    def fresh_draws(self) -> int:
        """Fresh action draws per episode in the check that ended the run (0: none made)."""
        return len(self.fresh_before.successes) // len(self.episodes) if self.fresh_before else 0

    @property
    def edits(self) -> list[Edit]:
        """The kept edits, in order (replaying them on ``original`` gives ``house``)."""
        return [r.edit for r in self.rounds if r.kept and r.edit is not None]

    @property
    def success(self) -> float:
        return self.after.success

    @property
    def gap(self) -> float:
        """``|success - target|`` of the house returned (the closest the run reached)."""
        return abs(self.after.success - self.target)

    @property
    def reached(self) -> bool:
        return self.gap <= self.tolerance + 1e-9

    @property
    def fresh_gap(self) -> float | None:
        """``|success - target|`` of the returned house on the fresh draws (None when none were made)."""
        return abs(self.fresh_after.success - self.target) if self.fresh_after else None

    @property
    def fresh_reached(self) -> bool | None:
        """Whether the returned house is within the tolerance of the target on the fresh draws (None without them)."""
        return None if self.fresh_gap is None else self.fresh_gap <= self.tolerance + 1e-9

    @property
    def success_trace(self) -> list[float]:
        """Measured success before the first edit and after each kept edit."""
        return [self.before.success] + [r.success for r in self.rounds if r.kept and r.success is not None]

    @property
    def round_count(self) -> int:
        """Rounds run (each proposed ``choices`` edits at most)."""
        return len({r.round for r in self.rounds})

    @property
    def env_steps(self) -> int:
        """pi_t's environment steps in all measurements and G's checks."""
        return self.measure_steps + self.check_steps

    def to_dict(self) -> dict[str, Any]:
        """Plain figures for JSON: target, reached success, gap, edits, rounds and the trace."""
        return {"target": self.target, "tolerance": self.tolerance, "generator": self.generator,
                "episodes": len(self.episodes), "draws": self.draws, "confirm": self.confirm,
                "refresh": self.refresh,
                "stop_gap": stop_gap_of(self.stop_gap, self.tolerance),
                "success_before": self.before.success,
                "spl_before": self.before.spl, "success": self.after.success, "spl": self.after.spl,
                "gap": self.gap, "reached": self.reached, "edits": len(self.edits), "rounds": self.round_count,
                "proposed": len(self.rounds),
                "stopped": self.stopped, "success_trace": self.success_trace,
                "fresh_draws": self.fresh_draws,
                "fresh_success_before": self.fresh_before.success if self.fresh_before else None,
                "fresh_success": self.fresh_after.success if self.fresh_after else None,
                "fresh_gap": self.fresh_gap, "fresh_reached": self.fresh_reached,
                "trace": [r.to_dict() for r in self.rounds]}

    def generation_log(self) -> dict[str, Any]:
        """The proposals as a generator's log (``edits.json``: one step per proposed edit, kept edits ``applied``, the
        others ``rejected`` or ``skipped``) with the figures of :meth:`to_dict` beside them."""
        steps = [StepRecord(step=i, status="applied" if r.kept else "rejected" if r.edit else "skipped",
                            edit=r.edit, reason=r.reason).model_dump(mode="json") for i, r in enumerate(self.rounds)]
        return {"generator": self.generator, "steps": steps,
                "target_success": {k: v for k, v in self.to_dict().items() if k != "trace"}}

    def line(self) -> str:
        """The one-line summary: target, reached success, gap and edits."""
        fresh = (f"; on fresh draws {self.fresh_before.success:.2f} -> {self.fresh_after.success:.2f}"
                 if self.fresh_before and self.fresh_after else "")
        return (f"target success {self.target:.2f} (tolerance {self.tolerance:.2f}): reached {self.after.success:.2f} "
                f"from {self.before.success:.2f}, gap {self.gap:.2f}, {len(self.edits)} edit(s) kept of "
                f"{len(self.rounds)} proposed, {len(self.episodes)} episodes; {self.stopped}{fresh}")


def measurement_episodes(world: NavWorld, n: int, seed: int | Sequence[int],
                         target_type: str | None = None) -> list[Episode]:
    """``n`` seeded episodes of ``world`` (:func:`~adaptenv.agents.rollout.draw_episode`), the same for a seed
    (an int, or seed words such as the loop's (seed, iteration, job)); episode ``k``'s seed ends in ``k``."""
    words = _words(seed)
    base = words[0] if len(words) == 1 else int(np.random.default_rng([*words, 4]).integers(1, 2**20))
    return [replace(draw_episode(world, np.random.default_rng([*words, 3, k]), target_type), seed=base * 1000 + k)
            for k in range(n)]


def _words(seed: int | Sequence[int]) -> list[int]:
    return [int(seed)] if isinstance(seed, (int, np.integer)) else [int(w) for w in seed]


def measure(world: NavWorld, episodes: list[Episode], policy: Policy) -> tuple[Measurement, list[Trajectory]]:
    """Roll the policy out on every episode: the measurement and the trajectories."""
    trajs = run_policy(world, episodes, policy)
    return (Measurement(tuple(bool(t.metrics.success) for t in trajs), tuple(float(t.metrics.spl) for t in trajs),
                        sum(len(t.steps) for t in trajs)), trajs)


def fresh_measurement(world: NavWorld, episodes: list[Episode], policy: Policy,
                      draws: int = FRESH_DRAWS) -> Measurement:
    """The policy on each episode ``draws`` times with fresh action-sampling seeds (the same start and target):
    a measurement no kept edit was selected on."""
    return measure(world, drawn(episodes, draws, FRESH_SEED_STRIDE, first=1), policy)[0]


def drawn(episodes: list[Episode], draws: int, stride: int = DRAW_SEED_STRIDE, first: int = 0) -> list[Episode]:
    """Each episode ``draws`` times, draw by draw, with its sampling seed offset by ``stride`` per draw (from the
    ``first``-th offset; the first draw of the measured ones is the episode itself). An episode without a seed is
    run with seed 0, as the harness runs it."""
    return [replace(e, seed=int(e.seed or 0) + stride * (first + d)) if first + d else e
            for d in range(draws) for e in episodes]


def closer(target: float, before: Measurement, after: Measurement) -> tuple[bool, str]:
    """Whether ``after`` is closer to the target than ``before``, and why: a smaller gap, or the same success
    with the mean SPL moved the way the target lies."""
    g0, g1 = abs(before.success - target), abs(after.success - target)
    if g1 < g0 - 1e-9:
        return True, f"success {before.success:.2f} -> {after.success:.2f}: closer to {target:.2f}"
    if after.success == before.success:
        d = after.spl - before.spl
        if (before.success > target and d < -SPL_TOL) or (before.success < target and d > SPL_TOL):
            return True, f"success unchanged at {after.success:.2f}, SPL {before.spl:.3f} -> {after.spl:.3f} toward the target"
        return False, f"success unchanged at {after.success:.2f} and SPL {before.spl:.3f} -> {after.spl:.3f}: no closer"
    return False, (f"success {before.success:.2f} -> {after.success:.2f}: "
                   f"{'overshoots' if (before.success - target) * (after.success - target) < 0 else 'moves away from'} "
                   f"{target:.2f} (gap {g0:.2f} -> {g1:.2f})")


def rank(target: float, before: Measurement, after: Measurement) -> tuple[float, float]:
    """Sort key of a measured edit among a round's choices (smaller is better): the gap to the target, then the
    mean SPL moved the way the target lies."""
    toward = before.spl - after.spl if before.success > target else after.spl - before.spl
    return abs(after.success - target), -toward


def focus_order(target: float, m: Measurement) -> list[int]:
    """Episodes G aims at, in turn: the solved ones (lowest SPL first) when success is above the target, the
    failed ones when below; every episode when none qualifies."""
    harder = m.success > target
    pick = [i for i, s in enumerate(m.successes) if s == harder]
    pick = pick or list(range(len(m.successes)))
    return sorted(pick, key=lambda i: (m.spls[i], i)) if harder else pick


def adapt_to_success(house: House, policy: Policy, generator: Generator, target: float, *,
                     tolerance: float = TOLERANCE, episodes: int | list[Episode] = EPISODES, max_edits: int = 10,
                     patience: int = PATIENCE, analyzer: Analyzer | None = None, seed: int | Sequence[int] = 0,
                     target_type: str | None = None, name: str = "house",
                     rollout_episodes: int = 3, choices: int = 1, draws: int = 1,
                     fresh_draws: int = FRESH_DRAWS, confirm: bool = False,
                     stop_gap: float | None = None, refresh: bool = False) -> TargetResult:
    """Edit ``house`` with ``generator`` until the policy's success on fixed episodes is within ``tolerance`` of
    ``target`` (see the module docstring).

    Args:
        house: the house (not modified).
        policy: the agent whose success is measured (and that G checks its candidates with).
        generator: any G (``make_generator(name)``).
        target: the success rate asked for, in (0, 1).
        tolerance: stop when ``|success - target|`` is at most this.
        episodes: how many episodes to measure on (seeded draws), or the episodes themselves.
        max_edits: most edits kept (the edit budget).
        patience: rounds in a row without a kept edit before giving up.
        analyzer: F for the episode G aims at (default the built-in).
        seed: seed (an int or seed words) of the episode draw and of G's random stream.
        target_type: draw only episodes of this target type.
        rollout_episodes: headings of G's own rollout check of a candidate (for the G that make one).
        choices: edits G is asked for per round, each aimed at the next episode in turn; every valid one is
            measured and the closest to the target is kept (1: the first edit, kept when closer).
        draws: action draws per measured episode (each with its own sampling seed); success is the mean over all
            of them, which an edit's noise moves less (1 to ``MAX_DRAWS``).
        fresh_draws: fresh action draws per episode on which the original and the returned house are measured
            once the run ends (``fresh_before``, ``fresh_after``); 0 skips it.
        confirm: measure an edit that comes closer again on ``draws`` confirming draws per episode (other sampling
            seeds, apart from the fresh ones) and keep it only when it comes closer there too.
        stop_gap: stop editing once ``|success - target|`` is at most this (0 to ``tolerance``; None: half the
            tolerance, :data:`STOP_SHARE`). Whether P was reached is still judged by ``tolerance``.
        refresh: after each kept edit, measure the house on new action draws (``draws`` per episode, seeds apart from
            every other set) and measure the next edits on those, so they are compared with a figure no edit was
            selected on.
    """
    check_target(target, tolerance, what="target", tol_what="tolerance")
    if max_edits < 0 or patience < 1 or not isinstance(choices, (int, np.integer)) or choices < 1:
        raise ConfigError(f"max_edits must be >= 0, patience and choices >= 1, got {max_edits}, {patience} and {choices}")
    if not isinstance(draws, (int, np.integer)) or not 1 <= draws <= MAX_DRAWS:
        raise ConfigError(f"draws {draws}: must be a whole number from 1 to {MAX_DRAWS}")
    if not isinstance(fresh_draws, (int, np.integer)) or fresh_draws < 0:
        raise ConfigError(f"fresh_draws {fresh_draws}: must be a whole number >= 0 (0 skips the fresh check)")
    check_stop_gap(stop_gap, tolerance)
    stop = stop_gap_of(stop_gap, tolerance)
    policy = as_policy(policy)
    analyzer = analyzer or BuiltinAnalyzer()
    world = world0 = compile_world(house, name)
    eps = list(episodes) if not isinstance(episodes, int) else measurement_episodes(world, episodes, seed, target_type)
    if not eps:
        raise ConfigError("episodes: measure on at least one episode")
    runs = drawn(eps, int(draws))
    first, trajs = measure(world, runs, policy)
    result = TargetResult(house, house, getattr(generator, "name", type(generator).__name__), float(target),
                          float(tolerance), eps, first, first, trajectories_before=trajs, trajectories_after=trajs,
                          draws=int(draws), confirm=bool(confirm), stop_gap=stop,
                          refresh=bool(refresh))
    result.measure_steps = first.steps
    confirming = drawn(eps, int(draws), CONFIRM_SEED_STRIDE, first=1) if confirm else []
    cur_c: Measurement | None = None
    current, cur, turn, misses, g_steps = house, first, 0, 0, 1
    while True:
        if abs(cur.success - target) <= stop + 1e-9:
            result.stopped = "within tolerance" if stop == tolerance else f"within the stop gap {stop:.3g}"
            break
        if len(result.edits) >= max_edits:
            result.stopped = "edit budget used"
            break
        if misses >= patience:
            result.stopped = f"no kept edit in {patience} rounds in a row"
            break
        order, n = focus_order(target, cur), result.round_count + 1
        best: tuple | None = None
        for _ in range(choices):
            k = order[turn % len(order)]
            turn += 1
            edit, reason, steps = _propose(result.usage, current, world, runs[k], trajs[k], policy, analyzer, generator,
                                           g_steps, np.random.default_rng([*_words(seed), 5, len(result.rounds)]),
                                           rollout_episodes)
            result.check_steps += steps
            if edit is None:
                g_steps = min(g_steps + 1, MAX_G_STEPS)
                result.rounds.append(TargetRound(n, k, None, False, reason))
                continue
            candidate = replay(current, [edit])
            problems, cworld = _checked(candidate, house, eps, k % len(eps), name)
            if problems:
                result.rounds.append(TargetRound(n, k, edit, False, "invalid: " + "; ".join(problems[:3])))
                continue
            m, ctrajs = measure(cworld, runs, policy)
            result.measure_steps += m.steps
            keep, why = closer(target, cur, m)
            mc = None
            if keep and confirm:
                if cur_c is None:
                    cur_c = measure(world, confirming, policy)[0]
                    result.measure_steps += cur_c.steps
                mc = measure(cworld, confirming, policy)[0]
                result.measure_steps += mc.steps
                keep, also = closer(target, cur_c, mc)
                why = f"{why}; {'and' if keep else 'not'} on the confirming draws ({also})"
            result.rounds.append(TargetRound(n, k, edit, False, why, m.success, m.spl))
            key = rank(target, cur, m)
            if keep and (best is None or key < best[0]):
                best = (key, len(result.rounds) - 1, candidate, cworld, m, ctrajs, mc)
        if best is None:
            misses += 1
            continue
        _, i, current, world, cur, trajs, cur_c = best
        result.rounds[i] = replace(result.rounds[i], kept=True)
        misses, turn = 0, 0
        if refresh:
            runs = drawn(eps, int(draws), REFRESH_SEED_STRIDE, first=1 + (len(result.edits) - 1) * int(draws))
            cur, trajs = measure(world, runs, policy)
            result.measure_steps += cur.steps
    result.house, result.after, result.trajectories_after = current, cur, trajs
    if fresh_draws:
        result.fresh_before = fresh_measurement(world0, eps, policy, fresh_draws)
        result.fresh_after = (fresh_measurement(world, eps, policy, fresh_draws) if result.edits
                              else result.fresh_before)
        result.measure_steps += result.fresh_before.steps + (result.fresh_after.steps if result.edits else 0)
    return result


def _propose(usage: Usage, house: House, world: NavWorld, episode: Episode, traj: Trajectory, policy: Policy, analyzer: Analyzer,
             generator: Generator, steps: int, rng: np.random.Generator,
             rollout_episodes: int) -> tuple[Edit | None, str, int]:
    """G's first applied edit on ``house`` aimed at ``episode`` (or None and why), and G's check steps; F's and
    G's LLM calls are added to ``usage``."""
    analysis = analyzer.analyze(traj, world)
    context = GenerationContext(episode=episode, trajectory=traj, policy=policy, rollout_episodes=rollout_episodes,
                                render=False)
    gen = generator.generate(house, analysis, steps=steps, context=context, rng=rng)
    usage.merge(scene_usage(analysis, gen))
    check = sum(s.check_steps for s in gen.steps)
    applied = gen.applied
    if applied:
        return applied[0], "", check
    why = gen.stopped or "; ".join(dict.fromkeys(s.reason for s in gen.steps if s.reason)) or "no edit"
    return None, f"G made no edit: {why}", check


def _checked(candidate: House, original: House, episodes: list[Episode], aimed: int,
             name: str) -> tuple[list[str], NavWorld | None]:
    """Why the edited house cannot be measured fairly (validation against the original from the aimed episode's
    start, or a measured episode no longer solvable), and its compiled world when it can."""
    problems = [str(p) for p in validate_scene(candidate, episode_targets=sorted({e.target_type for e in episodes}),
                                               start=episodes[aimed].start[:2], original=original)]
    problems += [p.message for p in validate_house(candidate)]
    if problems:
        return problems, None
    world = compile_world(candidate, name)
    unsolvable = [f"episode {k} ({e.target_type}) is no longer solvable" for k, e in enumerate(episodes)
                  if not is_solvable(world, e)]
    return unsolvable, None if unsolvable else world
