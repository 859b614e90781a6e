"""Measurable objectives behind F's suggestions: how hard a scene is along one episode's route.

Each suggestion kind of :mod:`adaptenv.adapt.analysis` becomes one number measured on a compiled
world for one episode (start, target type) and the agent's recorded route:

- ``narrow_passage``: mean clearance (m, capped at :data:`CLEARANCE_CAP`) at the route points;
  lower is harder.
- ``lengthen_route``: geodesic distance (m) from the start to the target's success region;
  higher is harder.
- ``occlude_target``: fraction of route points from which some instance of the target is in line
  of sight within ``spec.MAX_RANGE`` (any heading); lower is harder.
- ``add_clutter``: fraction of route points whose clearance is below
  :data:`~adaptenv.adapt.analysis.NARROW_CLEARANCE`; higher is harder.

The route points are the agent's recorded positions (fixed, from the rollout F analysed) plus the
current shortest route from the start (steepest descent on the geodesic distance field), sampled
every :data:`ROUTE_SPACING` m, so an edit that blocks the agent's habitual path and one that
squeezes the new shortest path both count. :func:`gain` turns a before/after pair into a signed,
roughly unit-free improvement: positive means harder in the suggestion's intended direction.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np

from adaptenv.adapt.analysis import NARROW_CLEARANCE, SuggestionKind
from adaptenv.adapt.realism import realism
from adaptenv.sim.geodesic import distance_field, geodesic_distance
from adaptenv.sim.spec import MAX_RANGE
from adaptenv.sim.task import visible_points
from adaptenv.sim.world import NavWorld

#: Clearances above this (m) count as "wide open" for the narrow-passage objective.
CLEARANCE_CAP = 1.0
#: Spacing (m) of route points used for the measurements.
ROUTE_SPACING = 0.25
#: At most this many route points are checked for line of sight (evenly subsampled).
MAX_VISIBILITY_POINTS = 80
#: +1: the objective should grow to make the scene harder; -1: it should shrink.
DIRECTION: dict[str, int] = {"narrow_passage": -1, "lengthen_route": 1, "occlude_target": -1, "add_clutter": 1}
OBJECTIVE_KINDS: tuple[str, ...] = tuple(DIRECTION)
#: What each objective measures and its unit, for people reading a before/after pair.
MEANING: dict[str, tuple[str, str]] = {
    "narrow_passage": ("mean clearance along the route", "m"),
    "lengthen_route": ("shortest route from start to target", "m"),
    "occlude_target": ("share of route points that see the target", "fraction"),
    "add_clutter": ("share of route points in narrow gaps", "fraction"),
}


def harder_or_easier(kind: str, before: float | None, after: float | None) -> str:
    """'harder', 'easier' or 'unchanged' for a change of objective ``kind`` (see :data:`DIRECTION`)."""
    if before is None or after is None or not (math.isfinite(before) and math.isfinite(after)):
        return "unchanged" if before == after else "harder" if after is None else "easier"
    delta = (after - before) * DIRECTION[kind]
    return "harder" if delta > 1e-9 else "easier" if delta < -1e-9 else "unchanged"

_NEIGHBOURS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


@dataclass(frozen=True)
class RouteSpec:
    """The episode an objective is measured for: start, target type and the agent's recorded route."""

    target_type: str
    start: tuple[float, float]
    agent_points: np.ndarray
    """(N, 2) world (x, z) of the agent's recorded positions (may be empty)."""

    @classmethod
    def from_episode(cls, target_type: str, start: tuple[float, ...], trajectory=None) -> RouteSpec:
        """Build from an episode's start and target and, if given, its trajectory's poses."""
        pts = np.zeros((0, 2))
        if trajectory is not None:
            pts = np.array([(p.x, p.z) for p in trajectory.poses], dtype=float).reshape(-1, 2)
        return cls(target_type, (float(start[0]), float(start[1])), resample(pts, ROUTE_SPACING))


@dataclass(frozen=True)
class ObjectiveValues:
    """The four objective numbers of one scene for one :class:`RouteSpec`."""

    narrow_passage: float
    lengthen_route: float
    occlude_target: float
    add_clutter: float

    def value(self, kind: str) -> float:
        return float(getattr(self, kind))

    def as_dict(self) -> dict[str, float]:
        return {k: (v if math.isfinite(v) else None) for k, v in asdict(self).items()}


def resample(points: np.ndarray, spacing: float) -> np.ndarray:
    """Points along a polyline, no more than ``spacing`` apart (keeps the first and last)."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(points) < 2:
        return points
    seg = np.hypot(*np.diff(points, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        return points[:1]
    n = max(2, int(math.ceil(s[-1] / spacing)) + 1)
    t = np.linspace(0.0, s[-1], n)
    return np.stack([np.interp(t, s, points[:, 0]), np.interp(t, s, points[:, 1])], axis=1)


def shortest_route(world: NavWorld, target_type: str, start: tuple[float, float]) -> np.ndarray:
    """World points (K, 2) of a shortest route from ``start`` to the success region (empty if unreachable).

    Steepest descent over the 8 neighbours of the geodesic distance field, from the start's cell
    (or its best finite neighbour) until the field reaches 0.
    """
    g = world.grid
    field = distance_field(world, target_type)
    h, w = field.shape
    row, col = (int(v) for v in g.to_cell(start[0], start[1]))
    if not (0 <= row < h and 0 <= col < w) or not math.isfinite(field[row, col]):
        best = None
        for dr, dc in _NEIGHBOURS:
            r, c = row + dr, col + dc
            if 0 <= r < h and 0 <= c < w and math.isfinite(field[r, c]) and (best is None or field[r, c] < field[best]):
                best = (r, c)
        if best is None:
            return np.zeros((0, 2))
        row, col = best
    cells = [(row, col)]
    for _ in range(h * w):
        d = field[row, col]
        if d <= 0:
            break
        nxt, nd = None, d
        for dr, dc in _NEIGHBOURS:
            r, c = row + dr, col + dc
            if 0 <= r < h and 0 <= c < w and field[r, c] < nd:
                nxt, nd = (r, c), field[r, c]
        if nxt is None:
            break
        row, col = nxt
        cells.append(nxt)
    rows, cols = np.array(cells).T
    x, z = g.cell_center(rows, cols)
    pts = np.concatenate([[start], np.stack([x, z], axis=1)])
    return resample(pts, ROUTE_SPACING)


def route_points(world: NavWorld, route: RouteSpec) -> np.ndarray:
    """The agent's recorded route plus the current shortest route (both resampled)."""
    return np.concatenate([route.agent_points, shortest_route(world, route.target_type, route.start)])


def visibility_fraction(world: NavWorld, target_type: str, points: np.ndarray) -> float:
    """Fraction of points from which some target instance is in line of sight within MAX_RANGE (any heading)."""
    if len(points) == 0:
        return 0.0
    if len(points) > MAX_VISIBILITY_POINTS:
        points = points[np.linspace(0, len(points) - 1, MAX_VISIBILITY_POINTS).round().astype(int)]
    seen = [bool(visible_points(world, float(x), float(z), 0.0, target_type, max_distance=MAX_RANGE,
                                fov_deg=360.0).any()) for x, z in points]
    return float(np.mean(seen))


def measure(world: NavWorld, route: RouteSpec) -> ObjectiveValues:
    """All four objectives of ``world`` for the episode ``route`` (see the module docstring)."""
    pts = route_points(world, route)
    if len(pts):
        clear = world.grid.clearance_at(pts[:, 0], pts[:, 1]).astype(float)
        narrow = float(np.minimum(clear, CLEARANCE_CAP).mean())
        clutter = float((clear < NARROW_CLEARANCE).mean())
    else:
        narrow, clutter = CLEARANCE_CAP, 0.0
    geo = float(geodesic_distance(world, route.target_type, route.start[0], route.start[1]))
    return ObjectiveValues(narrow_passage=narrow, lengthen_route=geo,
                           occlude_target=visibility_fraction(world, route.target_type, pts), add_clutter=clutter)


def gain(kind: str, before: ObjectiveValues, after: ObjectiveValues) -> float:
    """Signed improvement of one objective (positive = harder as intended), scaled to be comparable.

    Clearance changes are divided by CLEARANCE_CAP, route length changes by the route length
    before (at least 1 m); the two fractions are used as they are. A route that became
    unreachable gives -inf (never an improvement: validation forbids it anyway).
    """
    a, b = before.value(kind), after.value(kind)
    if kind == "lengthen_route":
        if not math.isfinite(b):
            return -math.inf
        if not math.isfinite(a):
            return 0.0
        return (b - a) / max(a, 1.0)
    delta = (b - a) * DIRECTION[kind]
    return delta / CLEARANCE_CAP if kind == "narrow_passage" else delta


#: The weight per unit of priority of the other suggestions' objectives, beside the targeted one's 1.
OTHER_WEIGHT = 0.25


def suggestion_weights(first: str, priorities: Mapping[str, float], other: float = OTHER_WEIGHT) -> dict[str, float]:
    """Weight per objective when ``first`` is targeted: 1 for it, ``other`` times the priority for the others."""
    weights = {k: other * float(p) for k, p in priorities.items() if k in DIRECTION and k != first}
    weights[first] = 1.0
    return weights


def weighted_gain(weights: Mapping[str, float], before: ObjectiveValues, after: ObjectiveValues) -> float:
    """The sum of each objective's :func:`gain` times its weight."""
    return sum(w * gain(kind, before, after) for kind, w in weights.items())


def suggestion_kind(kind: str) -> SuggestionKind:
    """Check that ``kind`` names an objective (one of :data:`OBJECTIVE_KINDS`)."""
    if kind not in DIRECTION:
        raise ValueError(f"unknown objective {kind!r}; use one of {', '.join(OBJECTIVE_KINDS)}")
    return kind  # type: ignore[return-value]


def realism_score(house, original=None, *, geometry=None) -> float:
    """Realism of a scene in [0, 1] (:func:`adaptenv.adapt.realism.realism`'s ``total``), judged against ``original``."""
    return float(realism(house, original=original, geometry=geometry).total)
