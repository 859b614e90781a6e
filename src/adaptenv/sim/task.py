"""ObjectNav episodes: which target instances the agent sees, when ``end`` succeeds, how episodes are drawn.

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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from adaptenv.errors import AdaptenvError
from adaptenv.sim.spec import AGENT_RADIUS, FOV_DEG, ROTATE_LARGE, SUCCESS_DISTANCE, TARGET_TYPES
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


# --------------------------------------------------------------------------- episodes

def available_targets(world: NavWorld) -> list[str]:
    """Target types an episode exists for: the success region touches the largest navigable
    component and does not cover all of its enterable cells (some start lies outside the region)."""
    from adaptenv.sim.geodesic import (  # cycle: geodesic imports this module
        enterable,
        success_region,
    )

    key = ("available_targets",)
    if key not in world.cache:
        comp, n = world.grid.components(AGENT_RADIUS)
        if n == 0:
            world.cache[key], world.cache[("trivial_targets",)] = [], []
            return []
        largest = int(np.argmax(np.bincount(comp.ravel())[1:])) + 1
        floor = (comp == largest) & enterable(world)  # where starts are drawn
        present = set(world.object_types)
        avail, trivial = [], []
        for t in TARGET_TYPES:
            if t not in present:
                continue
            inside = success_region(world, t) & floor
            if not inside.any():
                continue
            (avail if int(inside.sum()) < int(floor.sum()) else trivial).append(t)
        world.cache[key], world.cache[("trivial_targets",)] = avail, trivial
    return list(world.cache[key])


def trivial_targets(world: NavWorld) -> list[str]:
    """Target types visible from every enterable cell of the largest navigable component: no episode
    can start away from them, so the house is trivial for these types."""
    available_targets(world)
    return list(world.cache[("trivial_targets",)])


def _others(world: NavWorld, target_type: str) -> str:
    """The other target types an episode exists for, as a phrase for an error message."""
    others = [t for t in available_targets(world) if t != target_type]
    return f"choose another target ({', '.join(others)})" if others else \
        "no other target type has episodes in this house either"


def _check_target(world: NavWorld, target_type: str) -> None:
    if target_type not in TARGET_TYPES:
        raise AdaptenvError(f"{world.name}: target type {target_type!r} is not an ObjectNav target; "
                            f"use one of {', '.join(TARGET_TYPES)}")
    if not world.instances_of(target_type):
        avail = available_targets(world)
        raise AdaptenvError(f"{world.name}: the house has no {target_type}; choose one of "
                            f"{', '.join(avail) if avail else '(none: no target type is solvable here)'}")


def sample_episode(world: NavWorld, rng: np.random.Generator | int, target_type: str | None = None,
                   use_house_start: bool = False, min_distance: float = 0.0) -> Episode:
    """Draw a solvable episode: a target type and a start from which its success region is reachable.

    The start is the centre of an enterable cell (:func:`adaptenv.sim.geodesic.enterable`) drawn uniformly among
    those with a finite, positive geodesic distance to the success region (so not already
    successful whatever the yaw), with yaw a multiple of 30 degrees. ``use_house_start`` takes the
    house's metadata pose instead (yaw rounded to the 6-degree lattice); that episode may be
    unsolvable, which :func:`adaptenv.sim.metrics.episode_metrics` reports as ``solvable=False``.
    ``rng`` may be an int seed, which is then recorded in ``Episode.seed``. ``min_distance`` > 0
    restricts starts to cells at least that geodesic distance (m) from the success region, and the
    target type to types that have such cells (AdaptenvError when no type has any).
    """
    seed = None
    if not isinstance(rng, np.random.Generator):
        seed = int(rng)
        rng = np.random.default_rng(seed)
    if target_type is None:
        avail = available_targets(world)
        if not avail:
            trivial = trivial_targets(world)
            if trivial:
                raise AdaptenvError(f"{world.name}: no episode exists in this house: every reachable cell already "
                                    f"sees the {', '.join(trivial)}, and no other ObjectNav target type is "
                                    "solvable; use a larger house or add another target object")
            raise AdaptenvError(f"{world.name}: no ObjectNav target type is solvable in this house (none of "
                                f"{', '.join(TARGET_TYPES)} can be seen from reachable floor); add a target "
                                "object or open a door to it")
        if min_distance > 0:
            avail = [t for t in avail if len(start_cells(world, t, min_distance))]
            if not avail:
                raise AdaptenvError(f"{world.name}: no start is {min_distance:g} m or more from any target; "
                                    "lower the start-distance floor or use larger houses")
        target_type = str(avail[int(rng.integers(len(avail)))])
    else:
        _check_target(world, target_type)
    if use_house_start:
        if world.start is None:
            raise AdaptenvError(f"{world.name}: the house has no start pose in metadata.agent; "
                                "sample a start instead or set one with House.set_agent_pose")
        x, z, yaw = world.start
        return Episode(target_type, (float(x), float(z), float(round(yaw / 6.0) * 6.0 % 360.0)), seed)
    cells = start_cells(world, target_type, min_distance)
    rows, cols = np.divmod(cells, world.grid.shape[1])
    if len(rows) == 0:
        from adaptenv.sim.geodesic import distance_field  # geodesic imports this module

        if (distance_field(world, target_type) == 0).any():  # a region exists but covers every reachable cell
            raise AdaptenvError(f"{world.name}: the {target_type} is visible from every reachable cell, so no "
                                f"episode can start away from it (the house is trivial for {target_type}); "
                                + _others(world, target_type))
        raise AdaptenvError(f"{world.name}: the {target_type} cannot be seen from any reachable floor; "
                            + _others(world, target_type))
    k = int(rng.integers(len(rows)))
    x, z = world.grid.cell_center(rows[k], cols[k])
    yaw = float(rng.integers(int(360 / ROTATE_LARGE)) * ROTATE_LARGE)
    return Episode(target_type, (float(x), float(z), yaw), seed)


def start_cells(world: NavWorld, target_type: str, min_distance: float = 0.0) -> np.ndarray:
    """Flat indices of the start cells of a type: enterable, finite geodesic distance, positive and >= ``min_distance``."""
    from adaptenv.sim.geodesic import (  # cycle: geodesic imports this module
        distance_field,
        enterable,
    )

    key = ("starts", target_type) if min_distance <= 0 else ("starts", target_type, float(min_distance))
    if key not in world.cache:
        field = distance_field(world, target_type)
        world.cache[key] = np.flatnonzero(np.isfinite(field) & (field > 0) & (field >= min_distance)
                                          & enterable(world)).astype(np.int32)
    return world.cache[key]
