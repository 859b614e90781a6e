"""The paper's normalized 0..100 grid: round trips, corners and orientation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adaptenv.scene.grid import NormalizedGrid

#: Same examples on every run, nothing written to a .hypothesis folder.
DETERMINISTIC = settings(derandomize=True, database=None)

finite = st.floats(-100, 100, allow_nan=False)
extent = st.floats(0.5, 50, allow_nan=False)


@DETERMINISTIC
@given(finite, finite, extent, extent, st.floats(-10, 120), st.floats(-10, 120))
def test_grid_world_round_trip(x0, z0, w, h, gx, gy):
    grid = NormalizedGrid.from_bounds(x0, z0, x0 + w, z0 + h)
    x, z = grid.to_world(gx, gy)
    bx, by = grid.to_grid(x, z)
    assert float(bx) == pytest.approx(gx, abs=1e-7)
    assert float(by) == pytest.approx(gy, abs=1e-7)
    assert float(grid.units_to_meters(grid.meters_to_units(w))) == pytest.approx(w)


def test_corners_wide_house():
    grid = NormalizedGrid.from_bounds(2.0, 1.0, 12.0, 5.0)  # 10 m wide, 4 m deep
    assert grid.point(2.0, 1.0) == pytest.approx((0.0, 0.0))
    assert grid.point(12.0, 5.0) == pytest.approx((100.0, 40.0))


def test_corners_real_house(real_house):
    grid = NormalizedGrid.for_house(real_house)
    xs = [p.x for r in real_house.rooms for p in r.floorPolygon]
    zs = [p.z for r in real_house.rooms for p in r.floorPolygon]
    short, long = max(xs) - min(xs), max(zs) - min(zs)
    assert short < long
    assert grid.point(min(xs), min(zs)) == pytest.approx((0.0, 0.0))
    assert grid.point(max(xs), max(zs)) == pytest.approx((100.0 * short / long, 100.0))


def test_plus_z_is_up_and_plus_x_is_right():
    grid = NormalizedGrid.from_bounds(0.0, 0.0, 4.0, 4.0)
    gx, gy = grid.point(1.0, 1.0)
    assert grid.point(1.0, 2.0)[1] > gy and grid.point(1.0, 2.0)[0] == pytest.approx(gx)
    assert grid.point(2.0, 1.0)[0] > gx and grid.point(2.0, 1.0)[1] == pytest.approx(gy)
    x, z = grid.to_world(np.array([0.0, 50.0]), np.array([0.0, 100.0]))
    np.testing.assert_allclose(x, [0.0, 2.0])
    np.testing.assert_allclose(z, [0.0, 4.0])


def test_empty_bounds_raise():
    with pytest.raises(ValueError, match="empty"):
        NormalizedGrid.from_bounds(1.0, 1.0, 1.0, 1.0)
