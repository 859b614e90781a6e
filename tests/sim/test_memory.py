"""Simulator memory: compact distance fields (exactly the full ones), fields shared instead of
copied, regions derived from fields, accounting, and the numba cache key that covers the batch
kernel's inlined dependencies."""

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
    held = geodesic.distance_field(real_world, "Bed")  # noqa: F841  (held: its weak memo must add nothing)
    cached = [v for v in real_world.cache.values() if isinstance(v, np.ndarray)]
    points = real_world.cache[("points", "Bed")]
    index = real_world.cache[("cells",)]
    expected = (before + sum(a.nbytes for a in cached) + points.points.nbytes + points.label.nbytes
                + points.owner.nbytes + index.rank.nbytes + index.start.nbytes)
    assert real_world.nbytes == expected
    assert real_world.cache[("distance", "Bed")].nbytes == 4 * index.cells < 4 * real_world.grid.blocked.size
    assert real_world.nbytes < 4 * 2**20


def test_every_target_type_loaded_fits_in_4_mib(real_world):
    types = available_targets(real_world)
    assert len(types) >= 7
    sim = BatchSim([real_world])
    sim.reset([Episode(t, (0.0, 0.0, 0.0)) for t in types])
    assert real_world.nbytes + sim.nbytes <= 4 * 2**20


def test_compact_field_is_exactly_the_full_shortest_path_field(real_world):
    nav = geodesic.navigable(real_world)
    for t in available_targets(real_world)[:3]:
        region = geodesic._compute_region(real_world, t)
        full = geodesic.shortest_paths(nav, region, real_world.grid.resolution)[0]
        np.testing.assert_array_equal(geodesic.distance_field(real_world, t), full)
        np.testing.assert_array_equal(geodesic.compact_field(real_world, t), full[nav])


def test_cell_index_numbers_navigable_cells_in_row_major_order():
    rng = np.random.default_rng(0)
    for shape in [(1, 1), (3, 50), (37, 41), (130, 129)]:
        for p in (0.0, 0.5, 1.0):
            mask = rng.random(shape) < p
            index = geodesic.CellIndex.from_mask(mask)
            expected = np.full(mask.size, -1)
            expected[mask.ravel()] = np.arange(mask.sum())
            np.testing.assert_array_equal(index.entry(np.arange(mask.size)), expected)
            np.testing.assert_array_equal(index.mask, mask.ravel())
            assert index.cells == mask.sum()


def test_geodesic_distance_reads_the_compact_field_as_field_at_reads_the_grid(real_world):
    g = real_world.grid
    rng = np.random.default_rng(1)
    x = rng.uniform(g.x0 - 0.5, g.x0 + g.shape[1] * g.resolution + 0.5, 5000)
    z = rng.uniform(g.z0 - 0.5, g.z0 + g.shape[0] * g.resolution + 0.5, 5000)
    for t in available_targets(real_world)[:2]:
        ref = geodesic.field_at(real_world, geodesic.distance_field(real_world, t), x, z)
        got = geodesic.geodesic_distance(real_world, t, x, z)
        np.testing.assert_array_equal(got, ref)
        assert np.isfinite(got).any() and not np.isfinite(got).all()
        assert geodesic.geodesic_distance(real_world, t, x[0], z[0]) == ref[0]


def test_distance_field_is_rebuilt_only_when_nobody_holds_it(real_world):
    first = geodesic.distance_field(real_world, "Bed")
    assert geodesic.distance_field(real_world, "Bed") is first
    copy = first.copy()
    del first
    np.testing.assert_array_equal(geodesic.distance_field(real_world, "Bed"), copy)


def test_dependency_stamp_covers_physics_scan_and_geodesic_sources():
    h = hashlib.sha256()
    for mod in (physics, scan, geodesic):
        h.update(Path(mod.__file__).read_bytes())
    assert h.hexdigest() == vector._STAMP
    for kernel in (vector._agent_step, vector._run_serial, vector._run_parallel):
        cells = [c.cell_contents for c in kernel.py_func.__closure__]
        assert cells == [vector._STAMP]  # only the stamp: numba pickles closures into its cache key
