"""Time the loop's held-out evaluation jobs with refilled slots against one batch per chunk, side by side.

    python tools/time_eval_chunks.py [SUITE] [POLICY] [EPISODES]   # default: suite:val-far pretrained-ppo 500

The loop evaluates in jobs of ``EVAL_CHUNK`` episodes on ``EVAL_BATCH`` simulator slots, a finished slot taking the
job's next episode (:func:`adaptenv.curriculum.jobs.run_eval`). Before, a job ran 50 episodes in one batch of 50, so
every slot ran until the job's longest episode ended. This script runs the same episodes both ways, alternately
(median of three each, one thread), prints both times and their ratio, and checks that every episode ended the same.
docs/BENCHMARKS.md quotes it.
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

OLD_CHUNK = 50
"""Episodes per job, all in one batch, before refilled slots."""


def main(suite: str = "suite:val-far", policy_spec: str = "pretrained-ppo", episodes: int = 500) -> None:
    torch.set_num_threads(1)
    worlds = heldout_set(suite).worlds
    policy = resolve_policy(policy_spec)
    eps = sample_episodes(worlds, episodes, 0)

    def jobs(chunk: int, batch: int | None) -> list:
        return [r for a in range(0, episodes, chunk)
                for r in run_episodes(worlds, eps[a:a + chunk], policy, batch=batch or chunk)[0]]

    layouts = {"one batch per 50": lambda: jobs(OLD_CHUNK, None),
               f"{EVAL_CHUNK} on {EVAL_BATCH} refilled slots": lambda: jobs(EVAL_CHUNK, EVAL_BATCH)}
    times: dict[str, list[float]] = {k: [] for k in layouts}
    ends = {}
    for _ in range(3):
        for name, run in layouts.items():
            start = time.perf_counter()
            ends[name] = [(r.success, r.steps, r.spl) for r in run()]
            times[name].append(time.perf_counter() - start)
    old, new = (statistics.median(t) for t in times.values())
    print(f"{suite}, {policy_spec}, {episodes} episodes, load average {os.getloadavg()[0]:.2f}")
    for name, t in times.items():
        print(f"  {name}: median {statistics.median(t):.1f} s of {[round(x, 1) for x in t]}")
    a, b = ends.values()
    print(f"  ratio {old / new:.2f}; every episode ended the same: {a == b}")


if __name__ == "__main__":
    args = sys.argv[1:]
    main(*args[:2], *(int(x) for x in args[2:3]))
