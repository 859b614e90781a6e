"""Simulator memory: fields shared instead of copied, regions derived from fields, accounting, and
the numba cache key that covers the batch kernel's inlined dependencies."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from adaptenv.sim import geodesic, physics, scan, vector
from adaptenv.sim.task import Episode, available_targets
from adaptenv.sim.vector import BatchSim
from adaptenv.sim.world import compile_world


@pytest.fixture()
def real_world():
    from adaptenv.scene.house import load_house
    from tests.conftest import REAL_HOUSE

    return compile_world(load_house(REAL_HOUSE, validate=False), name="real")


def test_success_region_after_the_field_equals_the_computed_region(real_world):
    types = available_targets(real_world)[:3]
    computed = {t: geodesic._compute_region(real_world, t) for t in types}
    for t in types:
        geodesic.distance_field(real_world, t)
        assert ("region", t) not in real_world.cache
        np.testing.assert_array_equal(geodesic.success_region(real_world, t), computed[t])
        assert computed[t].any()


def test_batchsim_reads_the_cached_fields_without_copies(real_world):
    types = available_targets(real_world)
    sim = BatchSim([real_world])
    sim.reset([Episode(t, (0.0, 0.0, 0.0)) for t in types])
    assert len(sim._fields) == len(types)
    for t in types:
        field = real_world.cache[("distance", t)]
        assert any(np.shares_memory(f, field) for f in sim._fields)
    assert sim.nbytes == 0  # one world: rasters in place, every field a view of the world's cache


def test_world_nbytes_counts_every_cached_array_once(real_world):
    before = real_world.nbytes
    geodesic.distance_field(real_world, "Bed")
    cached = [v for v in real_world.cache.values() if isinstance(v, np.ndarray)]
    points = real_world.cache[("points", "Bed")]
    expected = before + sum(a.nbytes for a in cached) + points.points.nbytes + points.label.nbytes + points.owner.nbytes
    assert real_world.nbytes == expected
    assert real_world.nbytes < 4 * 2**20


def test_dependency_stamp_covers_physics_and_scan_sources():
    h = hashlib.sha256()
    for mod in (physics, scan):
        h.update(Path(mod.__file__).read_bytes())
    assert h.hexdigest() == vector._STAMP
    for kernel in (vector._agent_step, vector._run_serial, vector._run_parallel):
        cells = [c.cell_contents for c in kernel.py_func.__closure__]
        assert cells == [vector._STAMP]  # only the stamp: numba pickles closures into its cache key
