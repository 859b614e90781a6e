"""Benchmark: validated edits per second (collision-aware placement + incremental validation).

Random proposals (a random movable object, a displacement uniform in -30..30 grid units on each
axis, a random absolute yaw half of the time) go through :class:`EditValidator` on a procedural
5-room house, one core, no policy rollouts. Target: at least 1,000 validated edits per second.

Imports sit inside the functions: this module is loaded by its ``adaptenv bench`` command, and a
benchmark loads what it measures (torch, numba, ray) only when it runs.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

TARGET_PER_SECOND = 1000.0


def bench_house(seed: int = 0):
    """A procedural 5-room house (the benchmark's scene)."""
    from adaptenv.scene.procedural import GenerationConfig, generate_house

    return generate_house(seed, GenerationConfig(n_rooms=5))


def proposals(ids: list[str], n: int, rng: np.random.Generator) -> list[tuple[str, float, float, float | None]]:
    """n random edit proposals: (object id, dx units, dy units, absolute yaw or None)."""
    out = []
    for _ in range(n):
        oid = ids[int(rng.integers(len(ids)))]
        dx, dy = rng.uniform(-30.0, 30.0, 2)
        yaw = float(rng.uniform(0.0, 360.0)) if rng.random() < 0.5 else None
        out.append((oid, float(dx), float(dy), yaw))
    return out


def run(n: int = 2000, seed: int = 0, house=None) -> dict[str, Any]:
    """Time ``n`` random proposals; returns the figures (rates, split, acceptance).

    The CPU-second rate (process time) is the one-core figure when other jobs share the machine.
    """
    from adaptenv.adapt import placement as placement_mod
    from adaptenv.adapt.validation import EditValidator
    from adaptenv.scene.geometry import SceneGeometry

    house = house if house is not None else bench_house(seed)
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    validator = EditValidator(house)
    setup = time.perf_counter() - t0
    ids = [oid for oid, m in zip(validator.ctx.ids, validator.ctx.movable, strict=True) if m]
    reqs = proposals(ids, n, rng)

    # Time placement separately by wrapping the function the validator calls.
    spent = {"placement": 0.0}
    real = placement_mod.place_units

    def timed(*args, **kwargs):
        t = time.perf_counter()
        out = real(*args, **kwargs)
        spent["placement"] += time.perf_counter() - t
        return out

    import adaptenv.adapt.validation as validation_mod

    validation_mod.place_units = timed
    try:
        t, cpu = time.perf_counter(), time.process_time()
        for oid, dx, dy, yaw in reqs:
            validator.try_edit(oid, dx, dy, yaw, source="random")
        total = time.perf_counter() - t
        cpu = time.process_time() - cpu
    finally:
        validation_mod.place_units = real
    accepted = sum(e.accepted for e in validator.log)
    moved = sum(e.changed for e in validator.log)
    geometry = SceneGeometry.from_house(house)
    return {
        "rooms": len(geometry.rooms),
        "floor objects": len(geometry.floor_objects),
        "raster cells": int(np.prod(validator.raster.shape)),
        "edits": n,
        "validated edits per s": n / total,
        "validated edits per CPU s": n / max(cpu, 1e-9),
        "placement ms per edit": spent["placement"] / n * 1e3,
        "validation ms per edit": (total - spent["placement"]) / n * 1e3,
        "accepted fraction": accepted / n,
        "changed fraction": moved / n,
        "setup ms": setup * 1e3,
        "target per s": TARGET_PER_SECOND,
    }
