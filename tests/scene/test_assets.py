"""The asset catalog and footprint corners (hand-computed from the yaw convention)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adaptenv.scene.assets import is_movable, load_catalog, object_role
from adaptenv.scene.geometry import footprint_corners

#: Same examples on every run, nothing written to a .hypothesis folder.
DETERMINISTIC = settings(derandomize=True, database=None)

S = math.sqrt(0.5)


def test_catalog_counts_and_attribution():
    cat = load_catalog()
    assert len(cat.assets) == 1653
    assert len(cat.types) == 109
    assert len({a.object_type for a in cat.assets.values()}) == 109
    assert "ProcTHOR" in cat.attribution and "Apache" in cat.attribution
    assert cat.asset("Sofa_201_1").object_type == "Sofa"
    with pytest.raises(KeyError, match="NoSuchAsset"):
        cat.asset("NoSuchAsset")


def test_roles_and_movability():
    assert object_role("Painting", 1.2, is_child=False) == "wall"
    assert object_role("Television", 1.0, is_child=False) == "wall"  # wall-mounted TV
    assert object_role("Television", 0.0, is_child=False) == "floor"
    assert object_role("Bowl", 0.8, is_child=True) == "small"
    assert object_role("Doorway", 0.0, is_child=False) == "structure"
    assert is_movable("Sofa", "floor") and not is_movable("Toilet", "floor") and not is_movable("Painting", "wall")


# Corners in the order back-left, back-right, front-right, front-left (local -x-z, +x-z, +x+z, -x+z).
# Hand-derived with local x -> (cos t, -sin t) and local z -> (sin t, cos t), centre (1, 2), size 2 x 1.
@pytest.mark.parametrize(("yaw", "expected"), [
    (0.0, [(0.0, 1.5), (2.0, 1.5), (2.0, 2.5), (0.0, 2.5)]),
    # x axis -> (0, -1), z axis (front) -> (1, 0): the front is at larger x.
    (90.0, [(0.5, 3.0), (0.5, 1.0), (1.5, 1.0), (1.5, 3.0)]),
    # x axis -> (-1, 0), z axis -> (0, -1): the front is at smaller z.
    (180.0, [(2.0, 2.5), (0.0, 2.5), (0.0, 1.5), (2.0, 1.5)]),
])
def test_footprint_corners_axis_aligned(yaw, expected):
    np.testing.assert_allclose(footprint_corners(1.0, 2.0, 2.0, 1.0, yaw), expected, atol=1e-12)


def test_footprint_corners_45_degrees():
    # A 2 x 2 square at the origin: x axis -> (s, -s), z axis -> (s, s) with s = sqrt(1/2).
    expected = [(-2 * S, 0.0), (0.0, -2 * S), (2 * S, 0.0), (0.0, 2 * S)]
    np.testing.assert_allclose(footprint_corners(0.0, 0.0, 2.0, 2.0, 45.0), expected, atol=1e-12)


def _same_set(a: np.ndarray, b: np.ndarray, tol: float) -> bool:
    """Every corner of a has a corner of b within tol, and vice versa."""
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=-1)
    return bool((d.min(axis=1) < tol).all() and (d.min(axis=0) < tol).all())


coords = st.floats(-50, 50, allow_nan=False)
sizes = st.floats(0.01, 5, allow_nan=False)
yaws = st.floats(0, 360, allow_nan=False)


@DETERMINISTIC
@given(coords, coords, sizes, sizes, yaws)
def test_full_turn_is_identity(cx, cz, sx, sz, yaw):
    np.testing.assert_allclose(footprint_corners(cx, cz, sx, sz, yaw + 360.0),
                               footprint_corners(cx, cz, sx, sz, yaw), atol=1e-9)


@DETERMINISTIC
@given(coords, coords, sizes, sizes, yaws)
def test_half_turn_gives_the_same_corner_set(cx, cz, sx, sz, yaw):
    a = footprint_corners(cx, cz, sx, sz, yaw)
    b = footprint_corners(cx, cz, sx, sz, yaw + 180.0)
    assert _same_set(a, b, 1e-9)
    # ... but a different order: the front and back swap.
    np.testing.assert_allclose(b, a[[2, 3, 0, 1]], atol=1e-9)


@DETERMINISTIC
@given(coords, coords, sizes, sizes, yaws)
def test_footprint_is_a_rectangle_of_the_right_size(cx, cz, sx, sz, yaw):
    c = footprint_corners(cx, cz, sx, sz, yaw)
    assert math.dist(c[0], c[1]) == pytest.approx(sx, abs=1e-9)
    assert math.dist(c[1], c[2]) == pytest.approx(sz, abs=1e-9)
    np.testing.assert_allclose(c.mean(axis=0), (cx, cz), atol=1e-9)


def test_footprint_corners_are_the_centre_plus_the_turned_half_extents():
    """Bit for bit the corners c -/+ (sx / 2) x_axis -/+ (sz / 2) z_axis of the yaw's axes (any yaw, any size)."""
    from adaptenv.scene.geometry import yaw_axes

    rng = np.random.default_rng(0)
    for cx, cz, sx, sz, yaw in zip(*rng.uniform(-20, 20, (2, 500)), *rng.uniform(0.05, 4.0, (2, 500)),
                                   np.r_[rng.uniform(0, 360, 496), 0.0, 90.0, 180.0, 270.0], strict=True):
        ux, uz = yaw_axes(yaw)
        c, hx, hz = np.array([cx, cz]), sx / 2.0, sz / 2.0
        plain = np.stack([c - hx * ux - hz * uz, c + hx * ux - hz * uz, c + hx * ux + hz * uz, c - hx * ux + hz * uz])
        assert np.array_equal(footprint_corners(float(cx), float(cz), float(sx), float(sz), float(yaw)), plain)
