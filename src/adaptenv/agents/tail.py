"""Tail success: how an agent does on its own hardest 10% of houses, chosen with one seed, scored with another.

The protocol of SFL (Rutherford et al., "No Regrets", NeurIPS 2024), on houses instead of levels:
every house of an unseen set gets ``per_house`` episodes drawn with the **selection seed**; the
``fraction`` of houses where the agent succeeds least (ties broken by lower mean SPL, then by house
index) are its hardest; those houses get ``per_house`` new episodes drawn with the **scoring seed**,
and tail success is the agent's success on them. Choosing and scoring on separate draws keeps the
selection's luck out of the score (a house picked for bad luck regresses to its mean). With the
suite ``tail`` (200 houses) and ``per_house=10``, the selection pass is 2,000 episodes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from adaptenv.agents.evaluate import summarize
from adaptenv.agents.policy import Policy
from adaptenv.agents.runner import run_episodes
from adaptenv.sim import task
from adaptenv.sim.world import NavWorld


@dataclass(frozen=True)
class TailResult:
    """An agent's mean success on the selection pass and its success on its hardest houses, re-drawn."""

    mean_success: float
    """Success over every selection-pass episode."""
    tail_success: float
    """Success on the hardest houses' scoring-pass episodes."""
    tail_houses: tuple[int, ...]
    """Indices of the hardest houses, hardest first."""
    selection_episodes: int
    scoring_episodes: int

    def card(self) -> dict:
        return {"mean_success": self.mean_success, "tail_success": self.tail_success,
                "tail_houses": list(self.tail_houses), "selection_episodes": self.selection_episodes,
                "scoring_episodes": self.scoring_episodes}


def house_episodes(worlds: Sequence[NavWorld], houses: Sequence[int], per_house: int, seed: int
                   ) -> list[tuple[int, task.Episode]]:
    """``per_house`` episodes in each house of ``houses``: episode j of house e from the seed ``(seed, e, j)``."""
    return [(e, task.sample_episode(worlds[e], int(np.random.SeedSequence([seed, e, j]).generate_state(1)[0])))
            for e in houses for j in range(per_house)]


def hardest(success: np.ndarray, spl: np.ndarray, fraction: float) -> list[int]:
    """Indices of the ``fraction`` of rows (houses) with the lowest success, then lowest SPL, then lowest index."""
    k = max(1, int(round(fraction * len(success))))
    order = np.lexsort((np.arange(len(success)), spl, success))
    return order[:k].tolist()


def tail_success(policy: Policy, worlds: Sequence[NavWorld], *, per_house: int = 10, fraction: float = 0.1,
                 select_seed: int = 0, score_seed: int = 1, batch: int = 64) -> TailResult:
    """Run the protocol of the module docstring with ``policy`` on ``worlds``."""
    if select_seed == score_seed:
        raise ValueError("the selection and scoring seeds must differ (the scoring pass needs new draws)")
    everyone = list(range(len(worlds)))
    eps = house_episodes(worlds, everyone, per_house, select_seed)
    results, _ = run_episodes(worlds, eps, policy, batch=batch)
    success = np.array([r.success for r in results], dtype=float).reshape(len(worlds), per_house).mean(1)
    spl = np.array([r.spl for r in results], dtype=float).reshape(len(worlds), per_house).mean(1)
    worst = hardest(success, spl, fraction)
    scored, _ = run_episodes(worlds, house_episodes(worlds, worst, per_house, score_seed), policy, batch=batch)
    return TailResult(summarize(results)["success"], summarize(scored)["success"], tuple(worst), len(results),
                      len(scored))
