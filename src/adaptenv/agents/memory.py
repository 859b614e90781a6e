"""Does the agent use long memory? Wipe its memory every K steps and see how success changes.

:class:`WipeMemory` wraps any batched policy and, before the agent acts at steps K, 2K, 3K, ...
of each episode, wipes that agent's memory: ``policy.forget(state, indices)`` when the policy has
it (:class:`~adaptenv.agents.network.NeuralPolicy` zeroes the GRU memory and empties the map of a
map-reading network), else the agents' rows of a tensor or array state are zeroed.
:func:`memory_check` runs the same episodes once per K through the evaluation harness and
reports success, SPL and length per K with the paired difference in success against K = 0
(never wiped). If success barely moves at K = 32, the policy uses no memory older than 32 steps.

Example::

    adaptenv memory-check --policy pretrained --houses suite:val-far -n 200 --every 128 --every 32 --every 8
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from adaptenv.agents.evaluate import evaluate, paired_difference
from adaptenv.agents.houses import HouseSet, load_house_set
from adaptenv.agents.policy import (
    Observation,
    Policy,
    PolicyContext,
    State,
    bind_policy,
    policy_name,
)
from adaptenv.agents.registry import resolve_policy
from adaptenv.errors import ConfigError
from adaptenv.sim.spec import MAX_STEPS

DEFAULT_EVERY = (0, 128, 32, 8)
"""Wipe intervals :func:`memory_check` runs by default (0: never, the baseline)."""


def _zero_rows(state: State, indices: np.ndarray) -> State | None:
    """A copy of an array or tensor state with rows ``indices`` zeroed (None for any other state)."""
    torch = sys.modules.get("torch")
    if isinstance(state, np.ndarray) or (torch is not None and isinstance(state, torch.Tensor)):
        out = state.copy() if isinstance(state, np.ndarray) else state.clone()
        out[indices] = 0
        return out
    return None


def _has_rows(state: State, batch: int) -> bool:
    """Whether ``state`` is a numpy array or torch tensor with one row per agent."""
    return _zero_rows(state, np.zeros(0, np.int64)) is not None and len(state.shape) > 0 and state.shape[0] == batch


def _cannot_wipe(policy: Policy, state: State, flag: str = "") -> ConfigError:
    """The error for a policy whose memory :class:`WipeMemory` cannot wipe (naming ``flag`` when given)."""
    where = f"{flag}: " if flag else ""
    return ConfigError(f"{where}the {policy_name(policy)} policy's memory cannot be wiped: it needs "
                       f"forget(state, indices), or a state that is a tensor or array with one row per agent "
                       f"(its state is {type(state).__name__})")


def check_wipeable(policy: Policy, state: State, batch: int, flag: str = "") -> None:
    """Raise ConfigError unless ``policy`` has ``forget`` or ``state`` has one array row per agent."""
    if not callable(getattr(policy, "forget", None)) and not _has_rows(state, batch):
        raise _cannot_wipe(policy, state, flag)


def require_wipeable(policy: Policy, flag: str = "") -> None:
    """Fail early (ConfigError naming ``flag``) when :class:`WipeMemory` could not wipe ``policy``."""
    check_wipeable(policy, policy.initial_state(1), 1, flag)


def wipe(policy: Policy, state: State, indices: np.ndarray) -> State:
    """``state`` with the memory of agents ``indices`` wiped (``policy.forget`` or zeroed rows)."""
    forget = getattr(policy, "forget", None)
    if callable(forget):
        return forget(state, indices)
    out = _zero_rows(state, indices)
    if out is None:
        raise _cannot_wipe(policy, state)
    return out


class WipeMemory:
    """A :class:`~adaptenv.agents.policy.Policy` wrapper wiping each agent's memory at steps K, 2K, ... of its episode.

    Steps count from 0 at each episode start (where ``done``); ``every=0`` never wipes (pass-through).
    """

    def __init__(self, policy: Policy, every: int):
        if every < 0:
            raise ConfigError(f"wipe every {every} steps: the interval must be >= 0 (0: never)")
        self.policy = policy
        self.every = int(every)
        self.name = policy_name(policy)
        self._steps = np.zeros(0, dtype=np.int64)

    def bind(self, context: PolicyContext) -> None:
        """Pass the runner's context on to the wrapped policy when it takes one."""
        bind_policy(self.policy, context)

    def initial_state(self, batch: int) -> State:
        state = self.policy.initial_state(batch)
        if self.every:
            check_wipeable(self.policy, state, batch)
        self._steps = np.zeros(batch, dtype=np.int64)
        return state

    def due(self, done: np.ndarray) -> np.ndarray:
        """Agents about to act at a step K, 2K, ... of their episode (after restarting the counts where ``done``)."""
        if len(self._steps) != len(done):
            self._steps = np.zeros(len(done), dtype=np.int64)
        self._steps[done] = 0
        if not self.every:
            return np.zeros(0, dtype=np.int64)
        return np.flatnonzero((self._steps > 0) & (self._steps % self.every == 0))

    def act(self, obs: Observation, state: State, done: np.ndarray) -> tuple[np.ndarray, State]:
        done = np.asarray(done, dtype=bool)
        due = self.due(done)
        if due.size:
            state = wipe(self.policy, state, due)
        actions, state = self.policy.act(obs, state, done)
        self._steps += 1
        return actions, state


def wipe_intervals(every: Sequence[int], flag: str = "every") -> list[int]:
    """0 (the baseline) then the distinct positive intervals of ``every`` in the given order; negatives, or no
    positive interval to compare with the baseline, raise."""
    bad = [k for k in every if k < 0]
    if bad:
        raise ConfigError(f"{flag} {bad[0]}: wipe intervals must be >= 0 steps (0: never)")
    if not any(k > 0 for k in every):
        raise ConfigError(f"{flag} {', '.join(map(str, every)) or '(none)'}: no interval of 1 step or more to compare "
                          f"with never wiping (0, which always runs); pass {flag} K with K >= 1")
    return [0, *dict.fromkeys(int(k) for k in every if k > 0)]


def _row(every: int, summary: dict[str, Any]) -> dict[str, Any]:
    """The figures of one K: success, SPL and length with their standard errors."""
    return {"every": every, **{k: summary[k] for k in ("episodes", "successes", "success", "success_se",
                                                        "success_ci95", "spl", "spl_se", "steps", "steps_se")}}


def memory_check(policy: Policy | str, houses: HouseSet | str, episodes: int = 200, every: Sequence[int] = DEFAULT_EVERY,
                 seed: int = 0, workers: int = 1, batch: int = 64, max_steps: int = MAX_STEPS,
                 progress: Callable[[int], None] | None = None) -> dict[str, Any]:
    """Run the same episodes with memory wiped every K steps, once per K in ``every`` (0 always runs first).

    Returns the policy, houses, seed and floor, and one row per K: success, SPL, length (mean and
    s.e.) and the paired difference of success and SPL from K = 0 with a 95% normal interval.
    ``policy`` is an object or a ``--policy`` spec (a spec is needed for ``workers > 1``);
    ``progress`` gets the episodes finished over all runs.
    """
    house_set = load_house_set(houses) if isinstance(houses, str) else houses
    resolved = resolve_policy(policy, seed=seed) if isinstance(policy, str) else policy
    require_wipeable(resolved, f"--policy {policy}" if isinstance(policy, str) else "")
    target = policy if workers > 1 else resolved
    rows, base = [], None
    for i, k in enumerate(wipe_intervals(every)):
        report = evaluate(target, house_set, episodes=episodes, seed=seed, batch=batch, workers=workers,
                          max_steps=max_steps, with_expert=False, wrap=functools.partial(WipeMemory, every=k),
                          progress=None if progress is None else functools.partial(_offset, progress, i * episodes))
        base = report.results if base is None else base
        rows.append({**_row(k, report.summary), "success_diff": paired_difference(report.results, base, "success"),
                     "spl_diff": paired_difference(report.results, base, "spl")})
    return {"policy": policy if isinstance(policy, str) else policy_name(policy), "houses": house_set.spec,
            "episodes": episodes, "seed": seed, "floor": report.summary.get("floor", "no floor"), "runs": rows}


def _offset(progress: Callable[[int], None], offset: int, done: int) -> None:
    """Report ``done`` episodes of the current run as ``offset + done`` over all runs."""
    progress(offset + done)
