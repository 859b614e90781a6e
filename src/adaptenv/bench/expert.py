"""Benchmark of the shortest-path expert: does it solve generated houses, how well, how fast.

Episodes come from :func:`adaptenv.sim.task.sample_episode` on procedural houses; one in five
starts at the house's own start pose with a target type drawn among all types present (reachable
or not), which is where unsolvable episodes show up: they are counted apart, never as failures.
Label throughput is measured on a batch of agents spread over all houses, stepping with
``physics.step_poses`` and resetting finished episodes, as imitation learning would.

Imports sit inside the functions: this module is loaded by its ``adaptenv bench`` command, and a
benchmark loads what it measures (torch, numba, ray) only when it runs.
"""

from __future__ import annotations

import statistics
import time
from typing import Any

import numpy as np

BATCH = 256
THROUGHPUT_STEPS = 300


def _houses(n: int, seed: int):
    from adaptenv.scene.procedural import generate_houses
    from adaptenv.sim.world import compile_world

    houses = generate_houses(n, seed)
    return [compile_world(h, name=f"procedural-{seed}-{i}") for i, h in enumerate(houses)]


def _field_timings(worlds) -> dict[str, float]:
    """Median cost (ms) of each per-(house, target) precomputation, on fresh caches."""
    from adaptenv.sim.expert import guidance_field
    from adaptenv.sim.geodesic import distance_field, success_region
    from adaptenv.sim.spec import TARGET_TYPES

    reg, dist, guide = [], [], []
    for w in worlds[:10]:
        for t in (t for t in TARGET_TYPES if w.instances_of(t)):
            w.cache.clear()
            t0 = time.perf_counter()
            success_region(w, t)
            t1 = time.perf_counter()
            distance_field(w, t)
            t2 = time.perf_counter()
            guidance_field(w, t)
            t3 = time.perf_counter()
            reg.append(t1 - t0)
            dist.append(t2 - t1)
            guide.append(t3 - t2)
        w.cache.clear()
    return {"success_region_ms": 1e3 * statistics.median(reg), "distance_field_ms": 1e3 * statistics.median(dist),
            "guidance_field_ms": 1e3 * statistics.median(guide)}


def _episodes(worlds, episodes: int, seed: int):
    from adaptenv.sim.expert import ShortestPathExpert
    from adaptenv.sim.rollout import expert_policy, run_episode
    from adaptenv.sim.task import Episode, sample_episode

    rng = np.random.default_rng(seed)
    policy = expert_policy(ShortestPathExpert())
    rows, failures = [], []
    for k in range(episodes):
        w = worlds[k % len(worlds)]
        if k % 5 == 4 and w.start is not None:
            present = [t for t in w.object_types if t in _targets()]
            ep = sample_episode(w, rng, use_house_start=True)
            ep = Episode(str(present[int(rng.integers(len(present)))]), ep.start, None) if present else ep
        else:
            ep = sample_episode(w, rng)
        m = run_episode(w, ep, policy, record=False).metrics
        rows.append(m)
        if m.solvable and not m.success:
            failures.append(f"{w.name} {ep}")
    return rows, failures


def _targets():
    from adaptenv.sim.spec import TARGET_TYPES

    return TARGET_TYPES


def _throughput(worlds, seed: int) -> float:
    """Expert labels per second at batch BATCH, stepping and resetting included (fields prebuilt)."""
    from adaptenv.sim.expert import ShortestPathExpert
    from adaptenv.sim.physics import PackedGrids, step_poses
    from adaptenv.sim.spec import END, MAX_STEPS
    from adaptenv.sim.task import available_targets, sample_episode

    rng = np.random.default_rng(seed)
    expert = ShortestPathExpert()
    grids = PackedGrids.from_worlds(worlds)
    env = rng.integers(len(worlds), size=BATCH)
    eps = [sample_episode(worlds[e], rng) for e in env]
    targets = [e.target_type for e in eps]
    x = np.array([e.start[0] for e in eps])
    z = np.array([e.start[1] for e in eps])
    yaw = np.array([e.start[2] for e in eps])
    age = np.zeros(BATCH, dtype=np.int64)

    def run(steps: int) -> None:
        for _ in range(steps):
            a = expert.act_batch(worlds, env, targets, x, z, yaw)
            step_poses(grids, env, x, z, yaw, a)
            age[:] += 1
            for i in np.flatnonzero((a == END) | (age >= MAX_STEPS)):
                ep = sample_episode(worlds[env[i]], rng)
                targets[i] = ep.target_type
                x[i], z[i], yaw[i] = ep.start
                age[i] = 0

    # Warm up: compile, and build every (house, target) field once (their cost is reported apart).
    for w in worlds:
        for t in available_targets(w):
            expert.prepare(w, t)
    run(20)
    t = time.perf_counter()
    run(THROUGHPUT_STEPS)
    return BATCH * THROUGHPUT_STEPS / (time.perf_counter() - t)


def run(episodes: int = 500, n_houses: int = 50, seed: int = 0) -> tuple[dict[str, Any], list[str]]:
    """Figures and notes (failed episodes, if any) of the expert benchmark."""
    t = time.perf_counter()
    worlds = _houses(n_houses, seed)
    build = time.perf_counter() - t
    rows, failures = _episodes(worlds, episodes, seed)
    solvable = [m for m in rows if m.solvable]
    figures: dict[str, Any] = {
        "houses": len(worlds),
        "episodes": len(rows),
        "unsolvable_episodes": len(rows) - len(solvable),
        "success_rate": float(np.mean([m.success for m in solvable])) if solvable else 0.0,
        "failures": len(failures),
        "mean_spl": float(np.mean([m.spl for m in solvable])) if solvable else 0.0,
        "mean_episode_length": float(np.mean([m.episode_length for m in solvable])) if solvable else 0.0,
        "mean_optimal_path_m": float(np.mean([m.optimal_path_length for m in solvable])) if solvable else 0.0,
        "collisions_per_episode": float(np.mean([m.collisions for m in solvable])) if solvable else 0.0,
        "house_build_ms": 1e3 * build / len(worlds),
        **_field_timings(worlds),
        f"labels_per_s_batch{BATCH}": _throughput(worlds, seed),
    }
    return figures, [f"expert failed: {f}" for f in failures[:20]]
