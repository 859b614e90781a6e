"""Regret of an agent against the shortest-path expert, per episode (the optimum navigation has).

The level buffer scores levels with these (:mod:`adaptenv.curriculum.buffer`) and F's diagnosis
reports them (:mod:`adaptenv.adapt.diagnosis`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def _episodes(values: float | Sequence[float] | np.ndarray, name: str) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(values, dtype=np.float64))
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"{name}: expected one value per episode (a non-empty 1-D sequence), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: values must be finite")
    return arr


def success_regret(agent_success: float | Sequence[float], expert_success: float | Sequence[float]) -> float:
    """Mean over episodes of max(0, expert success - agent success): true regret with the expert as optimum."""
    a, e = _episodes(agent_success, "agent_success"), _episodes(expert_success, "expert_success")
    if a.shape != e.shape:
        raise ValueError(f"success_regret: {a.size} agent episodes but {e.size} expert episodes")
    return float(np.mean(np.clip(e - a, 0.0, 1.0)))


def spl_regret(agent_spl: float | Sequence[float], expert_success: float | Sequence[float]) -> float:
    """Mean over episodes of (1 - SPL) where the expert succeeds, 0 where it fails (unsolvable: no signal)."""
    s, e = _episodes(agent_spl, "agent_spl"), _episodes(expert_success, "expert_success")
    if s.shape != e.shape:
        raise ValueError(f"spl_regret: {s.size} agent episodes but {e.size} expert episodes")
    return float(np.mean(np.where(e > 0.5, 1.0 - np.clip(s, 0.0, 1.0), 0.0)))
