"""Time the map memory: ``EgoMap.update``, ``EgoMap.crop`` and the Gym option's unpacking, for B agents.

    python tools/time_egomap.py [B] [STEPS] [HOUSES]

Records STEPS batched observations of B agents taking random motion actions in HOUSES (default
``preset:tiny``, the simulator on one thread), then replays them through a fresh EgoMap, whose kernels
run on numba's threads (``NUMBA_NUM_THREADS``), timing each call
(``time.perf_counter`` and ``time.process_time``); a first pass compiles the kernels and is not timed.
Prints agent-frames per second (B x calls / s) and the load average, since the machine may be
shared. docs/simulator.md quotes it.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Callable

import numpy as np

from adaptenv.agents.houses import load_house_set
from adaptenv.sim.egomap import EgoMap, unpack
from adaptenv.sim.vector import BatchSim, EpisodeSampler


def record(houses: str, batch: int, steps: int) -> list[dict[str, np.ndarray]]:
    """Observations of ``batch`` random agents over ``steps`` steps (auto-reset done agents)."""
    worlds = load_house_set(houses).worlds
    rng = np.random.default_rng(0)
    sampler = EpisodeSampler(worlds)
    sim = BatchSim(worlds, threads=1)
    obs, _ = sim.reset(*sampler.draw(rng, batch))
    out = [obs]
    for _ in range(steps - 1):
        obs, _, terminated, truncated, _ = sim.step(rng.integers(6, size=batch))
        done = np.flatnonzero(terminated | truncated)
        if done.size:
            obs = sim.reset_at(done, *sampler.draw(rng, done.size))
        out.append(obs)
    return out


def timed(calls: list[Callable[[], object]]) -> tuple[float, float]:
    """(wall, CPU) seconds of running ``calls`` in order."""
    wall, cpu = time.perf_counter(), time.process_time()
    for call in calls:
        call()
    return time.perf_counter() - wall, time.process_time() - cpu


def main(batch: int = 256, steps: int = 500, houses: str = "preset:tiny") -> None:
    trace = record(houses, batch, steps)
    first = [np.full(batch, k == 0) for k in range(steps)]
    warm = EgoMap(batch)
    for obs, f in zip(trace[:3], first[:3], strict=True):
        warm.update(obs, f)
        unpack(warm.crop(), dtype=np.uint8)
    emap = EgoMap(batch)
    packed = np.empty((batch, emap.crop_size, emap.crop_size), dtype=np.uint8)
    update = timed([lambda o=o, f=f: emap.update(o, f) for o, f in zip(trace, first, strict=True)])
    crop = timed([lambda: emap.crop(packed)] * steps)
    spread = timed([lambda: unpack(packed, dtype=np.uint8)] * steps)

    def rate(t: tuple[float, float]) -> dict[str, float]:
        return {"frames_per_s": round(batch * steps / t[0]), "frames_per_cpu_s": round(batch * steps / t[1])}

    print(json.dumps({"agents": batch, "calls": steps, "houses": houses, "update": rate(update), "crop": rate(crop),
                      "unpack_uint8": rate(spread), "loadavg": [round(x, 2) for x in os.getloadavg()]}))


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]), *sys.argv[3:4])
