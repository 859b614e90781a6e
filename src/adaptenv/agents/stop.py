"""The stop decision: choose the ``end`` threshold of a network on held-in episodes.

A :class:`~adaptenv.agents.network.NeuralPolicy` issues ``end`` at the first step where the network
gives it probability >= ``end_threshold``; its motions do not depend on the threshold (they are
drawn from the softmax over the six motions either way). So one rollout in which the agent never
stops gives every threshold's outcome at once: under threshold ``tau`` the episode would have ended
at the first step where ``p_end >= tau``, succeeding iff ``end`` succeeds at that pose.
:func:`calibrate_end_threshold` runs such rollouts on fresh episodes in the *training* houses
(held-in: never a held-out set), records the first step each grid threshold is crossed, and picks
the threshold with the highest success (ties: the higher SPL).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch

from adaptenv.agents.evaluate import sample_episodes
from adaptenv.agents.network import MapObserver, choose_actions, obs_to_tensors, observe
from adaptenv.sim import metrics, task
from adaptenv.sim.spec import END, MAX_STEPS
from adaptenv.sim.vector import BatchSim

THRESHOLDS = (0.3, 0.4, 0.5, 0.6, 0.7, 0.75, 0.8, 0.85, 0.9, 0.95)
"""The ``end`` thresholds compared by default."""


@dataclass(frozen=True)
class StopCalibration:
    """The chosen ``end`` threshold and what every candidate scored (recorded in the checkpoint card)."""

    threshold: float
    grid: list[float]
    success: list[float]
    spl: list[float]
    episodes: int
    seed: int
    rule: str = "max success over grid (ties: max SPL), never-stop rollouts on fresh held-in episodes"

    def card(self) -> dict[str, Any]:
        return asdict(self)


def stop_outcomes(net: Any, worlds: Sequence[Any], episodes: Sequence[tuple[int, Any]], *,
                  grid: Sequence[float] = THRESHOLDS, seed: int = 0, max_steps: int = MAX_STEPS,
                  batch: int = 128) -> tuple[np.ndarray, np.ndarray]:
    """Success (E, G) and SPL (E, G) of each episode under each grid threshold, from never-stop rollouts."""
    grid_arr = np.asarray(sorted(grid), dtype=np.float64)
    success = np.zeros((len(episodes), grid_arr.size), dtype=bool)
    spl = np.zeros((len(episodes), grid_arr.size))
    rng = np.random.default_rng(seed)
    net.eval()
    for lo in range(0, len(episodes), batch):
        chunk = list(episodes[lo: lo + batch])
        sim = BatchSim(worlds, max_steps=max_steps, shapes=bool(net.config.shape_features))
        obs, _ = sim.reset([ep for _, ep in chunk], [e for e, _ in chunk])
        n = len(chunk)
        h = net.initial_state(n)
        observer = MapObserver.of(net, n)
        first = torch.ones(n, dtype=torch.bool)
        crossed = np.zeros(n, dtype=np.int64)  # grid thresholds already crossed by each agent
        for _ in range(max_steps):
            with torch.no_grad():
                logits, h = net.step(obs_to_tensors(observe(observer, obs, first.numpy())), first, h)
            p_end = torch.softmax(logits.float(), -1)[:, END].numpy()
            now = np.searchsorted(grid_arr, p_end, side="right")  # thresholds <= p_end
            for i in np.flatnonzero(now > crossed).tolist():
                e = int(sim.env[i])
                ok = task.is_success(sim.worlds[e], float(sim.x[i]), float(sim.z[i]), float(sim.yaw[i]),
                                     sim.target_types[i])
                score = metrics.spl(ok, float(sim.start_geodesic[i]), float(sim.path_length[i]))
                success[lo + i, crossed[i]: now[i]] = ok
                spl[lo + i, crossed[i]: now[i]] = score
                crossed[i] = now[i]
            moves = choose_actions(logits, rng.random(n), end_threshold=2.0)  # never end
            obs, _, _, truncated, _ = sim.step(moves)
            first = torch.zeros(n, dtype=torch.bool)
            if truncated.all():
                break
    return success, spl


def calibrate_end_threshold(net: Any, worlds: Sequence[Any], *, episodes: int = 200, seed: int = 0,
                            grid: Sequence[float] = THRESHOLDS, max_steps: int = MAX_STEPS) -> StopCalibration:
    """Pick the ``end`` threshold on ``episodes`` fresh episodes in ``worlds`` (the training houses)."""
    eps = sample_episodes(list(worlds), episodes, seed=seed)
    success, spl = stop_outcomes(net, worlds, eps, grid=grid, seed=seed, max_steps=max_steps)
    g = sorted(float(x) for x in grid)
    s, p = success.mean(0), spl.mean(0)
    best = max(range(len(g)), key=lambda k: (s[k], p[k]))
    return StopCalibration(threshold=g[best], grid=g, success=[round(float(x), 4) for x in s],
                           spl=[round(float(x), 4) for x in p], episodes=episodes, seed=seed)
