"""Held-out evaluation suites: fixed, versioned, paired episode sets that leave out the easy starts.

A suite is a house set (a procedural preset no method trains on, or one of the pretraining sets)
plus an :class:`EpisodeFloor`: a minimum geodesic start distance (m) to the target's success
region and, optionally, a minimum number of steps the shortest-path expert needs. Episode ``k`` of
a suite depends only on ``(suite, seed, k)``: it is drawn in house ``k % n_houses`` from the seed
``SeedSequence([seed, k])`` (the same seed as an unfloored episode), and when the expert-step floor
rejects it, from ``SeedSequence([seed, k, j])`` for ``j = 1, 2, ...``. So every method sees the
same episodes (paired comparisons), any slice equals the same slice of the whole list, and the
``version`` string plus the episode hash checked in ``tests/agents/test_suites.py`` pin them.

Use a suite wherever a house set is accepted (``--houses suite:long-unseen``, a loop's held-out
spec): :func:`adaptenv.agents.houses.load_house_set` returns its houses with the floor attached, and
:func:`adaptenv.agents.evaluate.sample_episodes` applies it. ``adaptenv evaluate --min-geodesic 6``
applies a floor to any house set.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from adaptenv.agents.policy import ExpertPolicy
from adaptenv.agents.runner import run_episodes
from adaptenv.errors import ConfigError
from adaptenv.sim.spec import MAX_STEPS
from adaptenv.sim.task import available_targets, sample_episode, start_cells

#: Attempts per episode before the expert-step floor gives up (ConfigError).
MAX_FLOOR_ATTEMPTS = 64


@dataclass(frozen=True)
class EpisodeFloor:
    """Which starts an episode may have: far enough from the target by geodesic distance and expert steps."""

    min_geodesic: float = 0.0
    """Minimum geodesic distance (m) from the start to the target's success region (0: no floor)."""
    min_expert_steps: int = 0
    """Minimum steps the shortest-path expert takes to succeed (0: no floor; costs one expert rollout per draw)."""

    @property
    def active(self) -> bool:
        return self.min_geodesic > 0 or self.min_expert_steps > 0

    def label(self) -> str:
        """A short text for reports, e.g. ``geodesic >= 6 m, expert >= 60 steps``."""
        parts = []
        if self.min_geodesic > 0:
            parts.append(f"geodesic >= {self.min_geodesic:g} m")
        if self.min_expert_steps > 0:
            parts.append(f"expert >= {self.min_expert_steps} steps")
        return ", ".join(parts) or "no floor"


@dataclass(frozen=True)
class SuiteSpec:
    """One named held-out suite (see the module docstring)."""

    houses: str
    """House-set spec of its houses (``preset:NAME``)."""
    floor: EpisodeFloor
    """Start-distance floor of its episodes."""
    version: str
    """Bumped whenever the houses or the episode rule change (the test's hash must then be updated)."""
    description: str = ""
    """One line for the docs and ``--help``."""


#: The 6 m floor: the issue-12 measurement found pi_0's rearrangement drop three times larger there.
LONG = EpisodeFloor(min_geodesic=6.0)

SUITES: dict[str, SuiteSpec] = {
    "long-train": SuiteSpec("preset:pretrain-train", LONG, "2",
                            "pretraining houses, starts >= 6 m from the target (Figure 1: train)"),
    "long-rearranged": SuiteSpec("preset:pretrain-rearranged", LONG, "2",
                                 "rearranged pretraining houses, starts >= 6 m (Figure 1: rearranged)"),
    "long-unseen": SuiteSpec("preset:pretrain-unseen", LONG, "2",
                             "unseen houses of the pretraining distribution, starts >= 6 m (Figure 1: unseen)"),
    "rearranged": SuiteSpec("preset:suite-rearranged", LONG, "1",
                            "the 24 pretraining homes, each rearranged 10 times with new seeds, starts >= 6 m"),
    "large": SuiteSpec("preset:suite-large", EpisodeFloor(min_geodesic=4.0), "2",
                       "7-10 room houses, starts >= 4 m from the target"),
    "far": SuiteSpec("preset:suite-large", EpisodeFloor(min_geodesic=10.0), "2",
                     "7-10 room houses, starts >= 10 m from the target (it lies rooms away)"),
    "clutter": SuiteSpec("preset:suite-clutter", EpisodeFloor(min_geodesic=4.0), "2",
                         "cluttered 3-6 room houses, starts >= 4 m from the target"),
    "doors": SuiteSpec("preset:suite-doors", EpisodeFloor(min_geodesic=6.0), "2",
                       "5-8 room houses joined only by doors (a tree of rooms), starts >= 6 m"),
    "closed": SuiteSpec("preset:suite-closed", EpisodeFloor(min_geodesic=8.0), "1",
                        "6-9 room houses with 40% of interior doors shut, starts >= 8 m from the target"),
    "unseen-assets": SuiteSpec("preset:suite-unseen-assets", LONG, "1",
                               "2-6 room houses furnished with test-split assets (shapes never trained on), starts >= 6 m"),
    "tail": SuiteSpec("preset:suite-tail", EpisodeFloor(), "1",
                      "200 unseen houses of the training distribution, any start (for the hardest-10% tail)"),
    # Validation twins of long-unseen, rearranged, far, clutter and closed: settings are chosen here, never on the suites above.
    "val-long": SuiteSpec("preset:validation", LONG, "1", "validation twin of long-unseen: new houses, starts >= 6 m"),
    "val-rearranged": SuiteSpec("preset:validation-rearranged", LONG, "1",
                                "validation twin of rearranged: 10 other rearrangements of each home, starts >= 6 m"),
    "val-far": SuiteSpec("preset:validation-large", EpisodeFloor(min_geodesic=10.0), "1",
                         "validation twin of far: 7-10 room houses, starts >= 10 m"),
    "val-clutter": SuiteSpec("preset:validation-clutter", EpisodeFloor(min_geodesic=4.0), "1",
                             "validation twin of clutter: cluttered 3-6 room houses, starts >= 4 m"),
    "val-unseen-assets": SuiteSpec("preset:validation-unseen-assets", LONG, "1",
                                   "validation twin of unseen-assets: val-split assets, starts >= 6 m"),
    "val-closed": SuiteSpec("preset:validation-closed", EpisodeFloor(min_geodesic=8.0), "1",
                            "validation twin of closed: 6-9 room houses with shut doors, starts >= 8 m"),
}


def suite_spec(name: str) -> SuiteSpec:
    """The suite of this name; ConfigError lists the known names."""
    try:
        return SUITES[name]
    except KeyError:
        raise ConfigError(f"--houses suite:{name}: unknown suite; choose one of "
                          + ", ".join(f"suite:{s}" for s in SUITES)) from None


class SuiteWorlds(list):
    """A list of compiled worlds that carries the episode floor of its suite (read by ``sample_episodes``)."""

    floor: EpisodeFloor = EpisodeFloor()

    def __init__(self, worlds: Sequence[Any], floor: EpisodeFloor):
        super().__init__(worlds)
        self.floor = floor


def episode_seed(seed: int, k: int, attempt: int = 0) -> int:
    """The seed of draw ``attempt`` of episode ``k`` (attempt 0 is the unfloored episode's seed)."""
    key = [seed, k] if attempt == 0 else [seed, k, attempt]
    return int(np.random.SeedSequence(key).generate_state(1)[0])


def sample_floored(worlds: Sequence[Any], n: int, seed: int, floor: EpisodeFloor, *, start: int = 0,
                   max_steps: int = MAX_STEPS) -> list[tuple[int, Any]]:
    """Episodes ``start..n-1`` meeting ``floor`` as (house index, Episode) pairs (see the module docstring).

    A house without any start that far from any target is skipped for the next house
    (``(k + j) % n_houses``); ConfigError when no house has one.
    """
    houses = {k: _house_for(worlds, k, floor) for k in range(start, n)}
    chosen: dict[int, tuple[int, Any]] = {}
    pending = list(range(start, n))
    for attempt in range(MAX_FLOOR_ATTEMPTS):
        if not pending:
            break
        cands = [(houses[k], sample_episode(worlds[houses[k]], episode_seed(seed, k, attempt),
                                                 min_distance=floor.min_geodesic)) for k in pending]
        steps = expert_steps(worlds, cands, max_steps) if floor.min_expert_steps > 0 else [None] * len(cands)
        still = []
        for k, cand, s in zip(pending, cands, steps, strict=True):
            if floor.min_expert_steps <= 0 or (s is not None and s >= floor.min_expert_steps):
                chosen[k] = cand
            else:
                still.append(k)
        pending = still
    if pending:
        raise ConfigError(f"{len(pending)} episodes found no start the expert needs {floor.min_expert_steps} "
                          f"steps or more for in {MAX_FLOOR_ATTEMPTS} draws; lower --min-expert-steps")
    return [chosen[k] for k in range(start, n)]


def expert_steps(worlds: Sequence[Any], episodes: Sequence[tuple[int, Any]], max_steps: int = MAX_STEPS
                 ) -> list[int | None]:
    """Steps the shortest-path expert takes on each episode (None where it fails), run in one batch."""
    results, _ = run_episodes(worlds, episodes, ExpertPolicy(), max_steps=max_steps)
    return [r.steps if r.success else None for r in results]


def _house_for(worlds: Sequence[Any], k: int, floor: EpisodeFloor) -> int:
    """House index of episode k: ``k % n`` unless that house has no start meeting the geodesic floor."""
    n = len(worlds)
    for j in range(n):
        e = (k + j) % n
        w = worlds[e]
        if floor.min_geodesic <= 0 or any(len(start_cells(w, t, floor.min_geodesic)) for t in available_targets(w)):
            return e
    raise ConfigError(f"no house of the set has a start {floor.min_geodesic:g} m or more from a target; "
                      "lower --min-geodesic or use larger houses")


def episodes_hash(episodes: Sequence[tuple[int, Any]]) -> str:
    """sha256 (first 16 hex digits) of (house, target, start, seed) of every episode: pins a suite."""
    h = hashlib.sha256()
    for e, ep in episodes:
        x, z, yaw = ep.start
        h.update(f"{e}|{ep.target_type}|{x:.4f}|{z:.4f}|{yaw:.1f}|{ep.seed}\n".encode())
    return h.hexdigest()[:16]
