"""Time the loop's held-out evaluation jobs against their two earlier layouts, side by side.

    python tools/time_eval_chunks.py [SUITE] [POLICY] [EPISODES]   # default: suite:val-far pretrained-ppo 1000

The loop evaluates in jobs of ``EVAL_CHUNK`` episodes on ``EVAL_BATCH`` simulator slots, a finished slot taking the
job's next episode (:func:`adaptenv.curriculum.jobs.run_eval`). Until commit e49d764 a job ran 50 episodes in one batch
of 50, so every slot ran until the job's longest episode ended; then jobs of 250 on 50 refilled slots. This script runs
the same episodes all three ways, alternately (median of three each, one thread), prints the times and their ratios to
the first layout, and checks that every episode ended the same. docs/BENCHMARKS.md quotes it.
"""

from __future__ import annotations

import os
import statistics
import sys
import time

import torch

from adaptenv.agents.evaluate import run_episodes, sample_episodes
from adaptenv.agents.registry import resolve_policy
from adaptenv.curriculum.jobs import EVAL_BATCH, EVAL_CHUNK, heldout_set

LAYOUTS = {"one batch per 50": (50, None), "250 on 50 refilled slots": (250, 50),
           f"{EVAL_CHUNK} on {EVAL_BATCH} refilled slots (now)": (EVAL_CHUNK, EVAL_BATCH)}
"""Layout name -> (episodes per job, simulator slots; None: the whole job in one batch)."""


def main(suite: str = "suite:val-far", policy_spec: str = "pretrained-ppo", episodes: int = 1000) -> None:
    torch.set_num_threads(1)
    worlds = heldout_set(suite).worlds
    policy = resolve_policy(policy_spec)
    eps = sample_episodes(worlds, episodes, 0)

    def jobs(chunk: int, batch: int | None) -> list:
        return [r for a in range(0, episodes, chunk)
                for r in run_episodes(worlds, eps[a:a + chunk], policy, batch=batch or chunk)[0]]

    times: dict[str, list[float]] = {k: [] for k in LAYOUTS}
    ends = {}
    for _ in range(3):
        for name, (chunk, batch) in LAYOUTS.items():
            start = time.perf_counter()
            ends[name] = [(r.success, r.steps, r.spl) for r in jobs(chunk, batch)]
            times[name].append(time.perf_counter() - start)
    first = statistics.median(times["one batch per 50"])
    print(f"{suite}, {policy_spec}, {episodes} episodes, load average {os.getloadavg()[0]:.2f}")
    for name, t in times.items():
        print(f"  {name}: median {statistics.median(t):.1f} s of {[round(x, 1) for x in t]}, "
              f"{first / statistics.median(t):.2f} times the first")
    print(f"  every episode ended the same: {all(e == ends['one batch per 50'] for e in ends.values())}")


if __name__ == "__main__":
    args = sys.argv[1:]
    main(*args[:2], *(int(x) for x in args[2:3]))
