"""Speedup of the executors from 1 to 2 workers on the closed loop's work (target >= 1.6x).

Two workloads (``--workload``):

- ``levels``: one item is one level: generate a 4-room house from its seed, compile it, and run the
  shortest-path expert on a few sampled episodes with full recording.
- ``heldout``: the loop's own held-out evaluation jobs (:func:`adaptenv.curriculum.jobs.run_eval`):
  the shipped policy on ``preset:pretrain-rearranged``, chunks of 50 episodes.

Items carry their seeds, so every executor must return exactly the in-process results; the
benchmark checks that before printing. Registered as ``adaptenv bench executor [--json] [--kind]
[--workload]`` by :mod:`adaptenv.cli.executor`.

Imports sit inside the functions: this module is loaded by its ``adaptenv bench`` command, and a
benchmark loads what it measures (torch, numba, ray) only when it runs.
"""

from __future__ import annotations

import os
import time
from typing import Any

#: Levels per timed map, and expert episodes per level.
N_ITEMS = 16
EPISODES_PER_ITEM = 3
#: Rooms of each generated house.
ROOMS = 4
#: Tiny items used to measure the round trip of one item on its own.
N_TINY = 400


def expert_level(item: tuple[int, int]) -> tuple[int, int, int, float]:
    """Generate house ``seed``, run ``n`` expert episodes on it; (seed, successes, steps, SPL sum).

    A top-level function with no shared state, so it runs unchanged in any worker.
    """
    from adaptenv.scene.procedural import GenerationConfig, generate_house
    from adaptenv.sim.rollout import expert_policy, run_episode
    from adaptenv.sim.task import sample_episode
    from adaptenv.sim.world import compile_world

    seed, n = item
    world = compile_world(generate_house(seed, GenerationConfig(n_rooms=ROOMS)), name=f"house-{seed}")
    successes, steps, spl = 0, 0, 0.0
    for k in range(n):
        episode = sample_episode(world, seed * 1000 + k)
        metrics = run_episode(world, episode, expert_policy(), record=True).metrics
        successes += int(metrics.success)
        steps += metrics.episode_length
        spl += float(metrics.spl)
    return seed, successes, steps, spl


#: Episodes per job of the ``heldout`` workload: 250, the loop's job size when its figures were taken, so the workload
#: keeps 4 jobs for the workers to share.
HELDOUT_CHUNK = 250
#: Held-out episodes of the ``heldout`` workload (4 chunks of ``HELDOUT_CHUNK``) and their set.
HELDOUT_EPISODES = 1000
HELDOUT_SET = "preset:pretrain-rearranged"


def heldout_items(episodes: int = HELDOUT_EPISODES) -> list[Any]:
    """The loop's evaluation jobs for the shipped policy on the rearranged held-out set."""
    from adaptenv.agents.registry import resolve_policy
    from adaptenv.curriculum.jobs import PolicyWeights, eval_jobs

    weights = PolicyWeights.of(resolve_policy("pretrained-scan"))
    return [job for _, job in eval_jobs(weights, {"heldout": HELDOUT_SET}, episodes, seed=0, chunk=HELDOUT_CHUNK)]


def heldout_chunk(job: Any) -> list[tuple[bool, float, int, int]]:
    """Run one evaluation job; (success, SPL, steps, collisions) per episode, comparable across executors."""
    from adaptenv.curriculum.jobs import run_eval

    return [(bool(r.success), float(r.spl), int(r.steps), int(r.collisions)) for r in run_eval(job)[0]]


#: workload name -> (item function, items builder taking the item count or None for its default).
WORKLOADS = {
    "levels": (expert_level, lambda n: items(n or N_ITEMS)),
    "heldout": (heldout_chunk, lambda n: heldout_items(HELDOUT_CHUNK * n if n else HELDOUT_EPISODES)),
}


def identity(x: Any) -> Any:
    """The cheapest possible item (to measure what the executor costs per item)."""
    return x


def items(n: int = N_ITEMS, seed: int = 0) -> list[tuple[int, int]]:
    """``n`` level items with seeds derived from one root seed."""
    from adaptenv.scene.procedural import child_seeds

    return [(s % (2**31), EPISODES_PER_ITEM) for s in child_seeds(seed, n)]


def _children_cpu() -> float:
    """CPU seconds used by joined child processes so far (NaN where ``resource`` is missing)."""
    try:
        import resource
    except ImportError:  # pragma: no cover - Windows
        return float("nan")
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def measure(kind: str, fn: Any, reference: list, work: list, repeats: int) -> dict[str, float]:
    """Median wall times (s) of one map with 1 and 2 workers of ``kind``, speedup and overheads."""
    from adaptenv.bench import median_time
    from adaptenv.curriculum.executor import make_executor
    from adaptenv.errors import AdaptenvError

    out: dict[str, float] = {}
    for workers in (1, 2):
        cpu0, wall0 = _children_cpu(), time.perf_counter()
        with make_executor(kind, workers=workers) as ex:
            if ex.map(fn, work) != reference:
                raise AdaptenvError(f"executor {kind} with {workers} workers returned results different from "
                                    "the in-process loop; this is a bug in the executor")
            out[f"{kind} {workers} worker(s) (s)"] = median_time(lambda ex=ex: ex.map(fn, work),
                                                                 repeats=repeats, warmup=0)
            if workers == 1:
                tiny = list(range(N_TINY))
                t = median_time(lambda ex=ex, tiny=tiny: ex.map(identity, tiny), repeats=repeats, warmup=1)
                out[f"{kind} tiny-item round trip (ms/item)"] = 1e3 * t / N_TINY
        if kind == "process":  # the pool's workers are our children: their CPU time is known once joined
            out[f"{kind} {workers} worker(s) cores used"] = (_children_cpu() - cpu0) / (time.perf_counter() - wall0)
    return out


def run(kinds: tuple[str, ...] = ("process", "ray"), n_items: int | None = None, repeats: int = 3,
        workload: str = "levels") -> dict[str, Any]:
    """All figures of one workload: in-process time, then per kind 1- and 2-worker times, speedup,
    per-item overhead. ``n_items``: levels, or evaluation chunks of 50 episodes (None: the default).

    Each executor is warmed up (and checked against the in-process results) by one untimed map.
    ``load average`` is the machine's 1-minute load before the run, and ``cores used`` the mean
    CPU the 2-worker pool got (its workers' CPU seconds over wall seconds): when other work
    competes for the cores these are well below 2 and the speedup is understated.
    """
    from adaptenv.bench import median_time
    from adaptenv.curriculum.executor import limit_threads

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    limit_threads()  # the in-process reference runs single-threaded too, like one worker
    fn, build = WORKLOADS[workload]
    work = build(n_items)
    reference = [fn(x) for x in work]  # also warms numba's cache (and loads the held-out set)
    base = median_time(lambda: [fn(x) for x in work], repeats=repeats, warmup=0)
    per_item = EPISODES_PER_ITEM if workload == "levels" else work[0].stop - work[0].start
    figures: dict[str, Any] = {"load average (1 min) before": load, "workload": workload, "items": len(work),
                               "episodes per item": per_item, "repeats": repeats,
                               "in-process (s)": base, "in-process per item (ms)": 1e3 * base / len(work)}
    for kind in kinds:
        m = measure(kind, fn, reference, work, repeats)
        one, two = m[f"{kind} 1 worker(s) (s)"], m[f"{kind} 2 worker(s) (s)"]
        figures[f"{kind} 1 worker (s)"] = one
        figures[f"{kind} 2 workers (s)"] = two
        figures[f"{kind} speedup 1->2"] = one / two
        figures[f"{kind} overhead per item (ms)"] = 1e3 * (one - base) / len(work)
        figures[f"{kind} tiny-item round trip (ms/item)"] = m[f"{kind} tiny-item round trip (ms/item)"]
        if kind == "process":
            figures["process 2 workers: cores used"] = m["process 2 worker(s) cores used"]
    return figures

