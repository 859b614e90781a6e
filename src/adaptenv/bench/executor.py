"""Speedup of the executors from 1 to 2 workers on expert episodes in procedural houses (target >= 1.6x).

One item is one level of the closed loop: generate a 4-room house from its seed, compile it, and
run the shortest-path expert on a few sampled episodes with full recording (as evaluation does).
Items carry their seeds, so every executor must return exactly the in-process results; the
benchmark checks that before printing. Registered as ``adaptenv bench executor [--json] [--kind]``
by :mod:`adaptenv.cli.executor`.
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


def measure(kind: str, reference: list, work: list, repeats: int) -> dict[str, float]:
    """Median wall times (s) of one map with 1 and 2 workers of ``kind``, speedup and overheads."""
    from adaptenv.bench import median_time
    from adaptenv.curriculum.executor import make_executor
    from adaptenv.errors import AdaptenvError

    out: dict[str, float] = {}
    for workers in (1, 2):
        cpu0, wall0 = _children_cpu(), time.perf_counter()
        with make_executor(kind, workers=workers) as ex:
            if ex.map(expert_level, work) != reference:
                raise AdaptenvError(f"executor {kind} with {workers} workers returned results different from "
                                    "the in-process loop; this is a bug in the executor")
            out[f"{kind} {workers} worker(s) (s)"] = median_time(lambda ex=ex: ex.map(expert_level, work),
                                                                 repeats=repeats, warmup=0)
            if workers == 1:
                tiny = list(range(N_TINY))
                t = median_time(lambda ex=ex, tiny=tiny: ex.map(identity, tiny), repeats=repeats, warmup=1)
                out[f"{kind} tiny-item round trip (ms/item)"] = 1e3 * t / N_TINY
        if kind == "process":  # the pool's workers are our children: their CPU time is known once joined
            out[f"{kind} {workers} worker(s) cores used"] = (_children_cpu() - cpu0) / (time.perf_counter() - wall0)
    return out


def run(kinds: tuple[str, ...] = ("process", "ray"), n_items: int = N_ITEMS, repeats: int = 3) -> dict[str, Any]:
    """All figures: in-process time, then per kind 1- and 2-worker times, speedup, per-item overhead.

    Each executor is warmed up (and checked against the in-process results) by one untimed map.
    ``load average`` is the machine's 1-minute load before the run, and ``cores used`` the mean
    CPU the 2-worker pool got (its workers' CPU seconds over wall seconds): when other work
    competes for the cores these are well below 2 and the speedup is understated.
    """
    from adaptenv.bench import median_time
    from adaptenv.curriculum.executor import limit_threads

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    limit_threads()  # the in-process reference runs single-threaded too, like one worker
    work = items(n_items)
    reference = [expert_level(x) for x in work]  # also warms numba's cache
    base = median_time(lambda: [expert_level(x) for x in work], repeats=repeats, warmup=0)
    figures: dict[str, Any] = {"load average (1 min) before": load, "items": n_items,
                               "episodes per item": EPISODES_PER_ITEM, "repeats": repeats,
                               "in-process (s)": base, "in-process per item (ms)": 1e3 * base / n_items}
    for kind in kinds:
        m = measure(kind, reference, work, repeats)
        one, two = m[f"{kind} 1 worker(s) (s)"], m[f"{kind} 2 worker(s) (s)"]
        figures[f"{kind} 1 worker (s)"] = one
        figures[f"{kind} 2 workers (s)"] = two
        figures[f"{kind} speedup 1->2"] = one / two
        figures[f"{kind} overhead per item (ms)"] = 1e3 * (one - base) / n_items
        figures[f"{kind} tiny-item round trip (ms/item)"] = m[f"{kind} tiny-item round trip (ms/item)"]
        if kind == "process":
            figures["process 2 workers: cores used"] = m["process 2 worker(s) cores used"]
    return figures

