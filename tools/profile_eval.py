"""Profile the loop's held-out evaluation: one job of episodes on ``EVAL_BATCH`` refilled slots, one thread.

    python tools/profile_eval.py [SUITE] [POLICY] [EPISODES]   # default: suite:val-far pretrained-ppo 250

Prints the wall time, the agent steps and cProfile's 18 most expensive functions by their own time.
docs/BENCHMARKS.md quotes it for where a final evaluation's time goes.
"""

from __future__ import annotations

import cProfile
import pstats
import sys
import time

import torch

from adaptenv.agents.evaluate import run_episodes, sample_episodes
from adaptenv.agents.registry import resolve_policy
from adaptenv.curriculum.jobs import EVAL_BATCH, heldout_set


def main(suite: str = "suite:val-far", policy_spec: str = "pretrained-ppo", episodes: int = 250) -> None:
    torch.set_num_threads(1)
    worlds = heldout_set(suite).worlds
    policy = resolve_policy(policy_spec)
    eps = sample_episodes(worlds, episodes, 0)
    run_episodes(worlds, eps[:EVAL_BATCH], policy, batch=EVAL_BATCH)  # warm-up: compiled kernels, first allocations
    profile = cProfile.Profile()
    start = time.perf_counter()
    profile.enable()
    results = run_episodes(worlds, eps, policy, batch=EVAL_BATCH)[0]
    profile.disable()
    print(f"{suite}, {policy_spec}, {episodes} episodes: {time.perf_counter() - start:.2f} s, "
          f"{sum(r.steps for r in results)} agent steps")
    pstats.Stats(profile).sort_stats("tottime").print_stats(18)


if __name__ == "__main__":
    args = sys.argv[1:]
    main(*args[:2], *(int(x) for x in args[2:3]))
