"""Candidate edits without rollouts, and the feature vector a learned G scores each one by.

:func:`enumerate_candidates` draws the moves the built-in G draws (toward, across or along the
route, toward the target, turns, wall slides) and as many random displacements of random movable
objects (the random G's moves, targets excluded), all from the request alone: nothing is placed,
validated or rolled out. :func:`candidate_features` turns each into a fixed vector of
:data:`FEATURE_NAMES` (the moved object, the displacement on the 100x100 grid, the rotation, where the
object stands relative to the route, the start and the target, and F's analysis), the same vector
``adaptenv gdata collect`` stores and the ``learned`` G scores.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from adaptenv.adapt.analysis import Analysis
from adaptenv.adapt.generators.builtin import BuiltinGenerator, Candidate
from adaptenv.adapt.generators.random_perturbation import random_move
from adaptenv.adapt.objectives import RouteSpec, route_points
from adaptenv.adapt.validation import EditValidator
from adaptenv.errors import ConfigError
from adaptenv.sim.world import NavWorld

KINDS = ("toward", "across", "sideways", "toward_target", "turn", "to_wall", "random")
"""How a candidate was drawn: the built-in G's move kinds, plus ``random`` (a random G move)."""
FAILURE_MODES = ("timeout", "ended_too_far", "ended_without_sight", "stuck", "looping", "never_saw_target")
CONCERN_KINDS = ("collision", "close_proximity", "narrow_clearance", "detour", "revisit", "oscillation",
                 "late_sight", "premature_end")
SUGGESTION_KINDS = ("narrow_passage", "occlude_target", "lengthen_route", "add_clutter")
#: Distances (m) are divided by this and capped at 1.
DIST_SCALE = 10.0
#: Largest displacement (grid units) of the random candidates (the random G's).
RANDOM_UNITS = 15.0
#: The share of candidates drawn as random moves by default (the rest are the built-in G's route moves).
RANDOM_SHARE = 0.5

FEATURE_NAMES: tuple[str, ...] = (
    "dx", "dy", "move_m", "rotates", "turn_sin", "turn_cos", "relocate",
    *(f"kind_{k}" for k in KINDS),
    "width_m", "depth_m", "log_area", "height_m", "tall", "against_wall",
    "d_route", "d_target", "d_start", "d_route_new", "d_target_new", "d_start_new", "toward_route",
    "in_target_room", "in_start_room", "n_rooms", "n_movable", "route_m",
    "success", "spl", *(f"mode_{m}" for m in FAILURE_MODES),
    *(f"concern_{c}" for c in CONCERN_KINDS), *(f"suggest_{s}" for s in SUGGESTION_KINDS),
)
"""The names of :func:`candidate_features`' columns, in order."""


@dataclass(frozen=True)
class Scene:
    """What features are measured against: the route's points, the start and the target instances' centres (m)."""

    route: np.ndarray
    start: np.ndarray
    targets: np.ndarray
    target_ids: frozenset[str]

    @classmethod
    def of(cls, v: EditValidator, world: NavWorld, route: RouteSpec) -> Scene:
        """The scene of ``v``'s house for the episode of ``route``."""
        pts = route_points(world, route)
        start = np.asarray(route.start, dtype=float)
        ids = frozenset(t.object_id for t in world.instances_of(route.target_type))
        ctx = v.ctx
        tpos = np.array([ctx.centers[ctx.index[t]] for t in sorted(ids) if t in ctx.index], dtype=float).reshape(-1, 2)
        return cls(pts if len(pts) else start[None, :], start, tpos, ids)


def enumerate_candidates(v: EditValidator, world: NavWorld, route: RouteSpec, rng: np.random.Generator, n: int,
                         *, scene: Scene | None = None, random_share: float = RANDOM_SHARE,
                         fit: bool = True) -> list[Candidate]:
    """Up to ``n`` distinct candidate edits (no rollouts): the built-in G's route moves, then random moves for
    ``random_share`` of ``n`` (or to fill what the route moves leave). ``fit=False`` leaves the route moves unfitted
    to the plausibility rules (:func:`~adaptenv.adapt.generators.builtin.fit_rules`), for a caller that fits them
    later."""
    scene = scene or Scene.of(v, world, route)
    if not 0.0 <= random_share <= 1.0:
        raise ConfigError(f"random_share {random_share}: must be from 0 to 1")
    routed = max(1, int(n * (1.0 - random_share))) if random_share < 1.0 else 0
    builtin = BuiltinGenerator(max_candidates=routed, fit_to_rules=fit)
    out = builtin._candidates(v, world, route, set(scene.target_ids), rng, limit=routed) if routed else []
    ids = [oid for oid, m in zip(v.ctx.ids, v.ctx.movable, strict=True) if m and oid not in scene.target_ids]
    seen = {(c.object_id, c.dx_units, c.dy_units, c.rotation) for c in out}
    for _ in range(3 * n):
        if len(out) >= n or not ids:
            break
        dx, dy, yaw = random_move(rng, RANDOM_UNITS, rotate_p=0.3)
        c = Candidate(ids[int(rng.integers(len(ids)))], round(dx, 1), round(dy, 1),
                      None if yaw is None else round(yaw, 1), "random")
        if (key := (c.object_id, c.dx_units, c.dy_units, c.rotation)) not in seen:
            seen.add(key)
            out.append(c)
    return out


def analysis_features(analysis: Analysis | None) -> list[float]:
    """F's analysis as numbers: success, SPL, failure mode, the worst severity per concern kind, suggestion priorities."""
    if analysis is None:
        return [0.0] * (2 + len(FAILURE_MODES) + len(CONCERN_KINDS) + len(SUGGESTION_KINDS))
    o = analysis.outcome
    severity = {k: 0.0 for k in CONCERN_KINDS}
    for c in analysis.concerns:
        severity[c.kind] = max(severity[c.kind], float(c.severity))
    priority = {k: 0.0 for k in SUGGESTION_KINDS}
    for s in analysis.suggestions:
        priority[s.kind] = max(priority[s.kind], float(s.priority))
    return [float(o.success), float(o.spl or 0.0), *(float(o.failure_mode == m) for m in FAILURE_MODES),
            *severity.values(), *priority.values()]


def _dists(points: np.ndarray, ps: np.ndarray) -> np.ndarray:
    """Distance (over DIST_SCALE, at most 1) from each of ``ps`` (N, 2) to the nearest of ``points`` (1 when none)."""
    if len(points) == 0:
        return np.ones(len(ps))
    d = np.hypot(points[None, :, 0] - ps[:, None, 0], points[None, :, 1] - ps[:, None, 1])
    return np.minimum(1.0, d.min(axis=1) / DIST_SCALE)


def candidate_features(v: EditValidator, scene: Scene, cands: list[Candidate], analysis: Analysis | None
                       ) -> np.ndarray:
    """(len(cands), len(FEATURE_NAMES)) float32: one row per candidate, computed from the request alone."""
    ctx, upm = v.ctx, v.ctx.grid.units_per_meter
    fps = {f.object_id: f for f in v.geometry.footprints}
    anchored = v.plausible.anchored if v.plausible is not None else frozenset()
    target_rooms = {int(ctx.room_of[ctx.index[t]]) for t in scene.target_ids if t in ctx.index}
    start_room = v.geometry.room_of_point(float(scene.start[0]), float(scene.start[1]))
    route_m = float(np.sum(np.hypot(*np.diff(scene.route, axis=0).T))) if len(scene.route) > 1 else 0.0
    house = [len(v.geometry.rooms) / 10.0, float(np.sum(ctx.movable)) / 50.0, min(1.0, route_m / 40.0)]
    fa = analysis_features(analysis)
    index = np.array([ctx.index[c.object_id] for c in cands], dtype=int)
    centers = ctx.centers[index].reshape(-1, 2)
    d = np.array([(c.dx_units, c.dy_units) for c in cands], dtype=float).reshape(-1, 2) / upm
    new = centers + d
    route = scene.route
    to_route = route[np.hypot(route[None, :, 0] - centers[:, None, 0],
                              route[None, :, 1] - centers[:, None, 1]).argmin(axis=1)] - centers
    moved = np.hypot(d[:, 0], d[:, 1])
    norm = moved * np.hypot(to_route[:, 0], to_route[:, 1])
    dot = d[:, 0] * to_route[:, 0] + d[:, 1] * to_route[:, 1]
    start = scene.start[None, :]
    near = np.stack([_dists(route, centers), _dists(scene.targets, centers), _dists(start, centers),
                     _dists(route, new), _dists(scene.targets, new), _dists(start, new)], axis=1)
    rows = []
    for n, (c, i) in enumerate(zip(cands, index.tolist(), strict=True)):
        yaw = float(ctx.yaws[i])
        turn = math.radians(((c.rotation - yaw) if c.rotation is not None else 0.0) % 360.0)
        fp = fps.get(c.object_id)
        w, dep = (float(fp.size[0]), float(fp.size[1])) if fp is not None else (float(ctx.sizes[i, 0]), float(ctx.sizes[i, 1]))
        rows.append([
            c.dx_units / 100.0, c.dy_units / 100.0, min(1.0, float(moved[n]) / 5.0), float(c.rotation is not None),
            math.sin(turn), math.cos(turn), float(c.relocate), *(float(c.kind == k) for k in KINDS),
            w, dep, math.log(max(w * dep, 1e-3)), float(fp.height) if fp is not None else 0.0,
            float(fp.occludes) if fp is not None else 0.0, float(c.object_id in anchored), *near[n].tolist(),
            float(dot[n]) / float(norm[n]) if norm[n] > 1e-9 else 0.0,
            float(int(ctx.room_of[i]) in target_rooms), float(ctx.room_ids[int(ctx.room_of[i])] == start_room)
            if 0 <= int(ctx.room_of[i]) < len(ctx.room_ids) else 0.0,
            *house, *fa,
        ])
    return np.asarray(rows, dtype=np.float32).reshape(len(cands), len(FEATURE_NAMES))


__all__ = ["FEATURE_NAMES", "KINDS", "Scene", "analysis_features", "candidate_features", "enumerate_candidates"]
