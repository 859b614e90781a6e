"""Time held-out evaluation with the shipped network's shape against smaller ones, side by side (agent steps/s).

    NUMBA_NUM_THREADS=1 python tools/time_network_size.py [EPISODES]   # default 250 val-far episodes a call

Untrained networks of each shape (seeded) play the same episodes on ``EVAL_BATCH`` refilled slots, one thread,
alternately three times; steps/s (not episodes/s) is compared, since untrained agents' episodes differ in length.
docs/BENCHMARKS.md quotes it for whether a smaller network would make issue 31's experiment fit its 3 hours.
"""

from __future__ import annotations

import dataclasses
import statistics
import sys
import time

import torch

from adaptenv.agents.evaluate import run_episodes, sample_episodes
from adaptenv.agents.network import NavNet, NeuralPolicy
from adaptenv.agents.registry import resolve_policy
from adaptenv.curriculum.jobs import EVAL_BATCH, heldout_set


def main(episodes: int = 250) -> None:
    torch.set_num_threads(1)
    worlds = heldout_set("suite:val-far").worlds
    eps = sample_episodes(worlds, episodes, 0)
    shipped = resolve_policy("pretrained-ppo").net.config
    shapes = {"shipped shape": shipped,
              "half (hidden 128, features 64, map 64, conv 16)": dataclasses.replace(
                  shipped, hidden=128, feature_dim=64, map_dim=64, conv_channels=16)}
    policies = {}
    for name, cfg in shapes.items():
        torch.manual_seed(0)
        net = NavNet(cfg)
        policies[name] = NeuralPolicy(net, seed=0, name=name)
        print(f"{name}: {sum(p.numel() for p in net.parameters()):,} weights")
        run_episodes(worlds, eps[:EVAL_BATCH], policies[name], batch=EVAL_BATCH)  # warm-up
    rates: dict[str, list[float]] = {k: [] for k in shapes}
    for _ in range(3):
        for name, policy in policies.items():
            start = time.perf_counter()
            steps = sum(r.steps for r in run_episodes(worlds, eps, policy, batch=EVAL_BATCH)[0])
            rates[name].append(steps / (time.perf_counter() - start))
    for name, r in rates.items():
        print(f"  {name}: median {statistics.median(r):,.0f} agent steps/s of {[round(x) for x in r]}")
    a, b = (statistics.median(r) for r in rates.values())
    print(f"  ratio {b / a:.2f}")


if __name__ == "__main__":
    main(*(int(x) for x in sys.argv[1:2]))
