"""The stop decision: never-stop rollouts give every threshold's outcome, as a plain run with that threshold does."""

from __future__ import annotations

import numpy as np
import torch

from adaptenv.agents.evaluate import sample_episodes
from adaptenv.agents.network import choose_actions, obs_to_tensors
from adaptenv.agents.registry import load_pretrained
from adaptenv.agents.stop import calibrate_end_threshold, stop_outcomes
from adaptenv.sim.vector import BatchSim

GRID = (0.3, 0.6, 0.9)
MAX_STEPS = 120


def reference_success(net, worlds, episodes, threshold: float, seed: int) -> np.ndarray:
    """Plain loop: run the threshold rule itself (same uniform stream) and read each episode's success."""
    rng = np.random.default_rng(seed)
    sim = BatchSim(worlds, max_steps=MAX_STEPS)
    obs, _ = sim.reset([ep for _, ep in episodes], [e for e, _ in episodes])
    n = len(episodes)
    h, first = net.initial_state(n), torch.ones(n, dtype=torch.bool)
    for _ in range(MAX_STEPS):
        with torch.no_grad():
            logits, h = net.step(obs_to_tensors(obs), first, h)
        obs, _, _, _, _ = sim.step(choose_actions(logits, rng.random(n), threshold))
        first = torch.zeros(n, dtype=torch.bool)
        if sim.done.all():
            break
    return sim.success.copy()


def test_never_stop_rollouts_match_running_each_threshold(tiny_set):
    net = load_pretrained("pretrained-scan").net
    worlds = tiny_set.worlds
    episodes = sample_episodes(worlds, 12, seed=3)
    success, spl = stop_outcomes(net, worlds, episodes, grid=GRID, seed=5, max_steps=MAX_STEPS)
    assert success.shape == (12, 3) and spl.shape == (12, 3)
    assert success.any(), "the pretrained policy should solve some tiny-house episodes"
    for k, tau in enumerate(GRID):
        assert (reference_success(net, worlds, episodes, tau, seed=5) == success[:, k]).all(), tau
    assert ((spl > 0) == success).all()


def test_calibration_picks_the_best_threshold_and_records_the_table(tiny_set):
    cal = calibrate_end_threshold(load_pretrained("pretrained-scan").net, tiny_set.worlds, episodes=8, seed=1, grid=GRID,
                                  max_steps=MAX_STEPS)
    assert cal.grid == list(GRID) and len(cal.success) == 3 and cal.episodes == 8
    best = max(range(3), key=lambda k: (cal.success[k], cal.spl[k]))
    assert cal.threshold == GRID[best]
    assert cal.card()["rule"].startswith("max success")
