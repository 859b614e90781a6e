"""Time the shipped network's shape against smaller ones, side by side: held-out evaluation and the loop's PPO.

    NUMBA_NUM_THREADS=1 python tools/time_network_size.py [EPISODES]   # default 250 val-far episodes a call

Untrained networks of each shape (seeded), one thread, alternately three times each:

- evaluation: the same episodes on ``EVAL_BATCH`` refilled slots, in agent steps/s (not episodes/s: untrained
  agents' episodes differ in length);
- PPO: three iterations of the loop's fine-tuning (``LOOP_PPO``, the encoder frozen, bf16 updates), each network
  anchored to itself, in frames per CPU-second (the figure that counts when two runs share two cores).

docs/BENCHMARKS.md quotes it for whether a smaller network would make issue 31's experiment fit its 3 hours.
"""

from __future__ import annotations

import dataclasses
import statistics
import sys
import tempfile
import time
from pathlib import Path

import torch

from adaptenv.agents.checkpoint import save_checkpoint
from adaptenv.agents.evaluate import run_episodes, sample_episodes
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.network import NavNet, NeuralPolicy
from adaptenv.agents.ppo import train_ppo
from adaptenv.agents.registry import resolve_policy
from adaptenv.bench.train import loop_ppo_config
from adaptenv.curriculum.jobs import EVAL_BATCH, heldout_set

SMALLER = {"a third (hidden 128, features 64, map 64, conv 16)": dict(hidden=128, feature_dim=64, map_dim=64,
                                                                      conv_channels=16),
           "a fifth (hidden 96, features 48, map 48, conv 12)": dict(hidden=96, feature_dim=48, map_dim=48,
                                                                      conv_channels=12),
           "an eighth (hidden 64, features 32, map 32, conv 8)": dict(hidden=64, feature_dim=32, map_dim=32,
                                                                       conv_channels=8)}
"""Shapes timed beside the shipped one: NavConfig fields that differ."""


def ppo_rate(init: Path, worlds: list, iterations: int = 3) -> float:
    """Frames per CPU-second of ``iterations`` PPO iterations of the loop's recipe from the checkpoint ``init``."""
    cfg = loop_ppo_config(iterations, freeze_encoder=True, precision="bf16", init=str(init))
    start = time.process_time()
    train_ppo(cfg, worlds=worlds)
    return cfg.frames / (time.process_time() - start)


def main(episodes: int = 250) -> None:
    torch.set_num_threads(1)
    worlds = heldout_set("suite:val-far").worlds
    train_worlds = load_house_set("preset:pretrain-train").worlds
    eps = sample_episodes(worlds, episodes, 0)
    shipped = resolve_policy("pretrained-ppo").net.config
    shapes = {"shipped shape": shipped} | {k: dataclasses.replace(shipped, **v) for k, v in SMALLER.items()}
    tmp = Path(tempfile.mkdtemp())
    policies, inits = {}, {}
    for i, (name, cfg) in enumerate(shapes.items()):
        torch.manual_seed(0)
        net = NavNet(cfg)
        policies[name] = NeuralPolicy(net, seed=0, name=name)
        inits[name] = save_checkpoint(tmp / f"shape{i}.pt", net, {"end_threshold": 0.5})
        print(f"{name}: {sum(p.numel() for p in net.parameters()):,} weights")
        run_episodes(worlds, eps[:EVAL_BATCH], policies[name], batch=EVAL_BATCH)  # warm-up
        ppo_rate(inits[name], train_worlds, iterations=1)
    steps: dict[str, list[float]] = {k: [] for k in shapes}
    frames: dict[str, list[float]] = {k: [] for k in shapes}
    for _ in range(3):
        for name, policy in policies.items():
            start = time.perf_counter()
            n = sum(r.steps for r in run_episodes(worlds, eps, policy, batch=EVAL_BATCH)[0])
            steps[name].append(n / (time.perf_counter() - start))
            frames[name].append(ppo_rate(inits[name], train_worlds))
    base_steps, base_frames = statistics.median(steps["shipped shape"]), statistics.median(frames["shipped shape"])
    for name in shapes:
        s, f = statistics.median(steps[name]), statistics.median(frames[name])
        print(f"  {name}: evaluation {s:,.0f} agent steps/s ({s / base_steps:.2f} times), "
              f"PPO {f:,.0f} frames per CPU-second ({f / base_frames:.2f} times)")


if __name__ == "__main__":
    main(*(int(x) for x in sys.argv[1:2]))
