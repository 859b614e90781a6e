"""ObjectNav targets: the episode record, sample points of the target instances, and visibility.

Visibility (the one definition used by success, the success region and "first sight"):
an instance is visible from pose (x, z, yaw) when at least one of its *sample points*

- lies within ``max_distance`` of the agent centre (Euclidean),
- lies inside the horizontal field of view (bearing within ``fov_deg / 2`` of the yaw), and
- has an unobstructed line of sight from the agent centre: the segment is walked at half-cell
  steps (every step including the end point) over ``world.occluder``; cells labelled as the
  instance itself never block, every other occluder cell does (walls, closed doors, windows,
  outside, furniture at least ``OCCLUDER_MIN_HEIGHT`` tall). Low furniture never blocks.

Sample points of a footprint (:func:`sample_points`): its centre, its four corners and points
along each edge no more than ``EDGE_SPACING`` apart (at least the edge midpoint), all pulled one
grid cell inside the footprint so they fall on the instance's own cells. The 2 m success
distance is therefore measured to the nearest sample point, which can exceed the distance to the
footprint's closest point by up to ``EDGE_SPACING / 2`` along long edges.

:mod:`adaptenv.sim.task` (episodes) and :mod:`adaptenv.sim.geodesic` (the success region) both
build on this module; ``task`` re-exports its names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from adaptenv.sim.spec import FOV_DEG, SUCCESS_DISTANCE
from adaptenv.sim.world import NavWorld

#: Largest gap (m) between sample points along a footprint edge.
EDGE_SPACING = 0.5


@dataclass(frozen=True)
class Episode:
    """One ObjectNav task: find any instance of ``target_type`` starting from ``start``."""

    target_type: str
    start: tuple[float, float, float]
    """(x, z, yaw degrees)."""
    seed: int | None = None


@dataclass(frozen=True)
class TargetPoints:
    """Sample points of every instance of one type, flattened (see the module docstring)."""

    points: np.ndarray
    """float64 (P, 2) world (x, z)."""
    label: np.ndarray
    """int64 (P,) occupancy label of the point's instance (its own cells never occlude)."""
    owner: np.ndarray
    """int64 (P,) index of the point's instance in ``world.instances_of(type)``."""
    ids: tuple[str, ...]


# --------------------------------------------------------------------------- numba kernels

@numba.njit(cache=True)
def los_clear(occ, lab, x0, z0, res, ax, az, bx, bz, ignore):
    """Whether the segment a -> b crosses no occluder cell except those labelled ``ignore``."""
    h, w = occ.shape
    dx, dz = bx - ax, bz - az
    n = int(math.ceil(math.sqrt(dx * dx + dz * dz) / (0.5 * res)))
    for k in range(1, n + 1):
        f = k / n
        col = int(math.floor((ax + f * dx - x0) / res))
        row = int(math.floor((az + f * dz - z0) / res))
        if row < 0 or row >= h or col < 0 or col >= w:
            return False
        if occ[row, col] and lab[row, col] != ignore:
            return False
    return True


@numba.njit(cache=True)
def wrap_deg(a):
    """Angle in degrees wrapped to [-180, 180)."""
    return (a + 180.0) % 360.0 - 180.0


@numba.njit(cache=True)
def bearing_deg(ax, az, bx, bz):
    """Yaw (degrees, 0 faces +z, 90 faces +x) pointing from a to b."""
    return math.degrees(math.atan2(bx - ax, bz - az))


@numba.njit(cache=True)
def point_visible(occ, lab, x0, z0, res, x, z, yaw, px, pz, plab, max_d2, half_fov):
    """Visibility of one sample point (squared distance, then field of view, then line of sight)."""
    dx, dz = px - x, pz - z
    if dx * dx + dz * dz > max_d2:
        return False
    if half_fov < 180.0 and abs(wrap_deg(bearing_deg(x, z, px, pz) - yaw)) > half_fov:
        return False
    return los_clear(occ, lab, x0, z0, res, x, z, px, pz, plab)


@numba.njit(cache=True)
def _visible_points(occ, lab, x0, z0, res, x, z, yaw, pts, plab, max_d2, half_fov, out):
    for p in range(pts.shape[0]):
        out[p] = point_visible(occ, lab, x0, z0, res, x, z, yaw, pts[p, 0], pts[p, 1], plab[p], max_d2, half_fov)


# --------------------------------------------------------------------------- sample points

def sample_points(corners: np.ndarray, inset: float) -> np.ndarray:
    """Centre, corners and edge points (<= EDGE_SPACING apart) of a footprint, pulled ``inset`` inside."""
    c = corners.mean(axis=0)
    ex, ez = corners[1] - corners[0], corners[3] - corners[0]
    lx, lz = float(np.linalg.norm(ex)), float(np.linalg.norm(ez))
    ux, uz = ex / max(lx, 1e-12), ez / max(lz, 1e-12)
    hx, hz = max(lx / 2 - inset, 0.0), max(lz / 2 - inset, 0.0)
    pts = [c]
    # Walk the inset rectangle's boundary: (-hx,-hz) -> (+hx,-hz) -> (+hx,+hz) -> (-hx,+hz) -> back.
    loop = [(-hx, -hz), (hx, -hz), (hx, hz), (-hx, hz)]
    for k in range(4):
        (a0, b0), (a1, b1) = loop[k], loop[(k + 1) % 4]
        n = max(2, math.ceil(math.hypot(a1 - a0, b1 - b0) / EDGE_SPACING))
        for i in range(n):
            t = i / n
            a, b = a0 + t * (a1 - a0), b0 + t * (b1 - b0)
            pts.append(c + a * ux + b * uz)
    return np.unique(np.round(np.array(pts), 9), axis=0)


def target_points(world: NavWorld, target_type: str) -> TargetPoints:
    """Sample points of every instance of a type (cached in ``world.cache``)."""
    key = ("points", target_type)
    if key not in world.cache:
        inst = world.instances_of(target_type)
        parts = [sample_points(t.corners, world.grid.resolution) for t in inst]
        pts = np.concatenate(parts) if parts else np.zeros((0, 2))
        label = np.concatenate([np.full(len(p), t.label) for p, t in zip(parts, inst, strict=True)]) if parts else np.zeros(0)
        owner = np.concatenate([np.full(len(p), k) for k, p in enumerate(parts)]) if parts else np.zeros(0)
        world.cache[key] = TargetPoints(np.ascontiguousarray(pts, dtype=np.float64), label.astype(np.int64),
                                        owner.astype(np.int64), tuple(t.object_id for t in inst))
    return world.cache[key]


# --------------------------------------------------------------------------- visibility and success

def visible_points(world: NavWorld, x: float, z: float, yaw: float, target_type: str, *,
                   max_distance: float = SUCCESS_DISTANCE, fov_deg: float = FOV_DEG) -> np.ndarray:
    """bool (P,): which sample points of ``target_points(world, type)`` are visible from the pose."""
    tp = target_points(world, target_type)
    out = np.zeros(len(tp.points), dtype=np.bool_)
    if len(out):
        g = world.grid
        _visible_points(world.occluder, g.label, g.x0, g.z0, g.resolution, float(x), float(z), float(yaw),
                        tp.points, tp.label, float(max_distance) ** 2, float(fov_deg) / 2.0, out)
    return out


def visible_instances(world: NavWorld, x: float, z: float, yaw: float, target_type: str, *,
                      max_distance: float = SUCCESS_DISTANCE, fov_deg: float = FOV_DEG) -> list[str]:
    """Ids of the instances of ``target_type`` visible from the pose (see the module docstring)."""
    tp = target_points(world, target_type)
    vis = visible_points(world, x, z, yaw, target_type, max_distance=max_distance, fov_deg=fov_deg)
    return [tp.ids[k] for k in np.unique(tp.owner[vis])]


def is_success(world: NavWorld, x: float, z: float, yaw: float, target_type: str) -> bool:
    """Whether ``end`` at this pose succeeds: some instance visible within SUCCESS_DISTANCE."""
    return bool(visible_points(world, x, z, yaw, target_type).any())
