"""ObjectNav episodes: which target instances the agent sees, when ``end`` succeeds, how episodes are drawn.

Visibility and sample points are defined in :mod:`adaptenv.sim.targets` (re-exported here): an
instance is visible when one of its sample points lies within ``max_distance``, inside the field of
view and in line of sight of the agent centre.
"""

from __future__ import annotations

import numpy as np

from adaptenv.errors import AdaptenvError
from adaptenv.sim.geodesic import distance_field, enterable, success_region
from adaptenv.sim.spec import AGENT_RADIUS, ROTATE_LARGE, TARGET_TYPES
from adaptenv.sim.targets import (
    EDGE_SPACING,
    Episode,
    TargetPoints,
    bearing_deg,
    is_success,
    los_clear,
    point_visible,
    sample_points,
    target_points,
    visible_instances,
    visible_points,
    wrap_deg,
)
from adaptenv.sim.world import NavWorld

# --------------------------------------------------------------------------- episodes

def available_targets(world: NavWorld) -> list[str]:
    """Target types an episode exists for: the success region touches the largest navigable
    component and does not cover all of its enterable cells (some start lies outside the region)."""
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
    key = ("starts", target_type) if min_distance <= 0 else ("starts", target_type, float(min_distance))
    if key not in world.cache:
        field = distance_field(world, target_type)
        world.cache[key] = np.flatnonzero(np.isfinite(field) & (field > 0) & (field >= min_distance)
                                          & enterable(world)).astype(np.int32)
    return world.cache[key]


__all__ = [
    "EDGE_SPACING", "Episode", "TargetPoints", "available_targets", "bearing_deg", "is_success", "los_clear",
    "point_visible", "sample_episode", "sample_points", "start_cells", "target_points", "trivial_targets",
    "visible_instances", "visible_points", "wrap_deg",
]
