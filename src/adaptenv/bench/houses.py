"""Benchmark: how long one procedural house takes (all stages, checks and retries included).

Target: a 5-room house well under 100 ms on one core.

Imports sit inside the functions: this module is loaded by its ``adaptenv bench`` command, and a
benchmark loads what it measures (torch, numba, ray) only when it runs.
"""

from __future__ import annotations

import os
import statistics
import time

from adaptenv.bench import emit


def time_houses(n_rooms: int, houses: int, seed: int = 0) -> tuple[list[float], list[float]]:
    """Wall and CPU times (s) of ``generate_house`` for ``houses`` consecutive seeds at this room count.

    CPU time (this process only) stays meaningful when other jobs share the machine.
    """
    from adaptenv.scene.assets import load_catalog
    from adaptenv.scene.procedural import GenerationConfig, generate_house

    catalog = load_catalog()
    cfg = GenerationConfig(n_rooms=n_rooms)
    generate_house(seed + 10_000, cfg, catalog)  # warm-up: imports, caches
    wall, cpu = [], []
    for s in range(seed, seed + houses):
        t, c = time.perf_counter(), time.process_time()
        generate_house(s, cfg, catalog)
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return wall, cpu


def run(as_json: bool, houses: int = 20) -> None:
    """Time ``houses`` 5-room and 10-room houses and print the medians (ms) and the load average."""
    figures: dict[str, float | int] = {"houses per room count": houses}
    for n_rooms in (5, 10):
        wall, cpu = time_houses(n_rooms, houses)
        figures[f"{n_rooms}-room median (ms)"] = 1000 * statistics.median(wall)
        figures[f"{n_rooms}-room median CPU (ms)"] = 1000 * statistics.median(cpu)
        figures[f"{n_rooms}-room max (ms)"] = 1000 * max(wall)
    if hasattr(os, "getloadavg"):
        figures["load average (1 min)"] = round(os.getloadavg()[0], 2)
    emit("procedural houses", figures, as_json, notes=["target: 5-room median well under 100 ms"])
