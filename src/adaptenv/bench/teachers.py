"""Benchmark: labelling speed of the searching teachers, the explorer and the map explorer, side by side.

One BatchSim of ``agents`` slots runs ``steps`` steps (finished episodes are redrawn at once, as in
DAgger's collection). Both teachers label every state (each keeps its own map, so each must see
every step), in alternating order from step to step; the executed action is the map explorer's
label, replaced by a uniformly random motion with probability ``random_share`` (DAgger's mixture
of teacher and student). Each teacher's frames/s is taken per block of ``block`` steps; the report
gives the medians over blocks and their ratio. The first ``warmup`` steps (compilation, the first
plans) are not timed.

Example::

    python -c "from adaptenv.bench.teachers import bench_labelling; print(bench_labelling())"
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np


def bench_labelling(houses: str = "preset:pretrain-train", agents: int = 256, steps: int = 256, seed: int = 0, *,
                    block: int = 16, warmup: int = 8, random_share: float = 0.2) -> dict[str, Any]:
    """Frames/s of the explorer and map-explorer teachers labelling the same states (see the module docstring)."""
    from adaptenv.agents.houses import load_house_set
    from adaptenv.agents.teachers import ExplorerTeacher, MapExplorerTeacher
    from adaptenv.sim.spec import END
    from adaptenv.sim.vector import BatchSim, EpisodeSampler

    worlds = load_house_set(houses).worlds
    rng = np.random.default_rng(seed)
    sampler = EpisodeSampler(worlds)
    sim = BatchSim(worlds)
    teachers = {"explorer": ExplorerTeacher(sim), "map-explorer": MapExplorerTeacher(sim)}
    obs, _ = sim.reset(*sampler.draw(rng, agents))
    first = np.ones(agents, dtype=bool)
    seconds = {name: np.zeros(steps) for name in teachers}
    for t in range(warmup + steps):
        labels = {}
        for name in (list(teachers) if t % 2 == 0 else list(teachers)[::-1]):
            start = time.perf_counter()
            labels[name] = teachers[name].label(obs, first)
            if t >= warmup:
                seconds[name][t - warmup] = time.perf_counter() - start
        actions = np.where(rng.random(agents) < random_share, rng.integers(0, END, size=agents), labels["map-explorer"])
        obs, _, terminated, truncated, _ = sim.step(actions)
        done = np.flatnonzero(terminated | truncated)
        first = np.zeros(agents, dtype=bool)
        if done.size:
            obs = sim.reset_at(done, *sampler.draw(rng, done.size))
            first[done] = True
    n_blocks = steps // block
    fps = {name: agents * block / s[: n_blocks * block].reshape(n_blocks, block).sum(axis=1)
           for name, s in seconds.items()}
    med = {name: float(np.median(v)) for name, v in fps.items()}
    return {"houses": houses, "agents": agents, "steps": steps, "blocks": n_blocks,
            "explorer_fps": med["explorer"], "map_explorer_fps": med["map-explorer"],
            "ratio": med["map-explorer"] / med["explorer"]}


__all__ = ["bench_labelling"]
