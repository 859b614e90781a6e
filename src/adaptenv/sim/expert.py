"""A shortest-path expert in the agent's own action space (the teacher for imitation learning).

Per (house, target type) the expert precomputes, once, a *guidance field*: a Dijkstra distance to
the inner success region (the success region shrunk by one cell, so arriving means success from
anywhere in the cell) whose step cost grows near obstacles (cells with clearance below
``PREFERRED_CLEARANCE`` cost up to ``1 + CLEARANCE_PENALTY`` times their length) with each cell's successor along its
guidance path. At each step the agent aims at a *look-ahead* cell: the farthest cell along the
guidance path from its own cell, up to ``LOOKAHEAD_CELLS`` steps, that it can reach in a straight
line with a margin of one cell.

Each step is then a pure function of the pose (no memory, so no oscillation between steps):

1. inside the success region: ``end`` if a target instance is in view (exactly
   :func:`adaptenv.sim.task.is_success`); otherwise, if one is within range and in line of sight,
   turn toward it;
2. otherwise aim at the look-ahead cell; if a 0.2 m move along the nearest lattice heading is
   blocked (narrow gaps, door frames), plan the next two (turn, move) pairs over all lattice
   headings with the exact physics and take the first action of the plan that ends on the lowest
   guidance value (each action costing ``PLAN_STEP_COST``);
3. move ahead when aligned within ``ALIGN_TOLERANCE`` and the move is free, else take the turn
   (30 or 6 degrees) leaving the smallest heading error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from adaptenv.sim.geodesic import distance_field, navigable, shortest_paths, success_region
from adaptenv.sim.spec import (
    AGENT_RADIUS,
    END,
    FOV_DEG,
    MOVE_AHEAD,
    MOVE_STEP,
    ROTATE_LARGE,
    ROTATE_LEFT,
    ROTATE_LEFT_SMALL,
    ROTATE_RIGHT,
    ROTATE_RIGHT_SMALL,
    ROTATE_SMALL,
    SUCCESS_DISTANCE,
)
from adaptenv.sim.task import bearing_deg, point_visible, target_points, wrap_deg
from adaptenv.sim.world import NavWorld

#: Below this clearance (m) a cell costs extra in the guidance field, keeping the expert off walls.
PREFERRED_CLEARANCE = 0.4
#: Extra cost factor of a cell at exactly the agent radius (linear down to 0 at PREFERRED_CLEARANCE).
CLEARANCE_PENALTY = 2.0
#: Deepest ancestor (cells along the guidance path) the expert aims at.
LOOKAHEAD_CELLS = 24
#: A success-region component without a (2 * SMALL_GOAL_CELLS + 1)-cell square inside is "small".
SMALL_GOAL_CELLS = 2
#: Within this guidance distance (m) of a small goal the expert searches its last two moves exactly.
FINAL_SEARCH_RANGE = 0.5
#: Cost (m of guidance) of one action when planning around a blocked move.
PLAN_STEP_COST = 0.02
#: Move ahead when the heading error is at most this (degrees); otherwise turn first.
ALIGN_TOLERANCE = 9.0


@dataclass(frozen=True)
class GuidanceField:
    """Per (world, target) arrays the expert reads."""

    distance: np.ndarray
    """float32 (H, W): the true geodesic distance field (0 in the success region)."""
    guidance: np.ndarray
    """float32 (H, W): clearance-weighted distance to the inner success region."""
    parent: np.ndarray
    """int32 (H, W): flat index of each cell's successor along its guidance path (-1 at goals and unreachable cells)."""
    small_goal: np.ndarray
    """bool (H, W): goal cells of a success-region component too small to walk into reliably."""


@numba.njit(cache=True)
def _segment_clear(clear, x0, z0, res, ax, az, bx, bz, min_clear):
    h, w = clear.shape
    dx, dz = bx - ax, bz - az
    n = int(math.ceil(math.sqrt(dx * dx + dz * dz) / (0.5 * res)))
    for k in range(1, n + 1):
        f = k / n
        col = int(math.floor((ax + f * dx - x0) / res))
        row = int(math.floor((az + f * dz - z0) / res))
        if row < 0 or row >= h or col < 0 or col >= w or clear[row, col] < min_clear:
            return False
    return True


@numba.njit(cache=True)
def _lookahead(clear, parent, x0, z0, res, x, z, start, min_clear, max_depth):
    """Farthest ancestor of cell ``start`` (<= max_depth steps) reachable straight from (x, z) with margin."""
    w = clear.shape[1]
    best, a, depth, check = start, start, 0, 2
    while depth < max_depth:
        p = parent[a // w, a % w]
        if p < 0:
            break
        a = p
        depth += 1
        if depth <= 2:
            best = a
        elif depth == check:
            ax, az = x0 + (a % w + 0.5) * res, z0 + (a // w + 0.5) * res
            if not _segment_clear(clear, x0, z0, res, x, z, ax, az, min_clear):
                break
            best = a
            check = depth + max(1, depth // 3)
    return best


def guidance_field(world: NavWorld, target_type: str) -> GuidanceField:
    """The expert's precomputed arrays for one target type (cached in ``world.cache``)."""
    key = ("guidance", target_type)
    if key in world.cache:
        return world.cache[key]
    from scipy import ndimage

    g = world.grid
    nav = navigable(world)
    region = success_region(world, target_type)
    inner = ndimage.binary_erosion(region, border_value=0)
    core = ndimage.binary_erosion(region, iterations=SMALL_GOAL_CELLS, border_value=0)
    # A region component too thin to survive erosion keeps all its cells as goals; one without a
    # core is "small": 0.2 m moves may step over it, so the expert plans its last moves exactly.
    comp, n = ndimage.label(region)
    small = np.zeros(g.shape, dtype=bool)
    if n:
        has_inner = np.zeros(n + 1, dtype=bool)
        has_inner[np.unique(comp[inner])] = True
        inner |= region & ~has_inner[comp]
        has_core = np.zeros(n + 1, dtype=bool)
        has_core[np.unique(comp[core])] = True
        small = region & ~has_core[comp]
    span = PREFERRED_CLEARANCE - AGENT_RADIUS
    mult = (1.0 + CLEARANCE_PENALTY * np.clip((PREFERRED_CLEARANCE - g.clearance) / span, 0.0, 1.0)).astype(np.float32)
    guide, parent = shortest_paths(nav, inner, g.resolution, mult)
    out = GuidanceField(distance_field(world, target_type), guide, parent.astype(np.int32), small & inner)
    world.cache[key] = out
    return out


@numba.njit(cache=True)
def _move_ok(clear, x0, z0, res, x, z, yaw, radius, step):
    h, w = clear.shape
    t = math.radians(yaw)
    dx, dz = step * math.sin(t), step * math.cos(t)
    n_sub = max(1, int(math.ceil(abs(step) / (0.5 * min(res, radius)))))
    for k in range(1, n_sub + 1):
        f = k / n_sub
        col = int(math.floor((x + f * dx - x0) / res))
        row = int(math.floor((z + f * dz - z0) / res))
        if row < 0 or row >= h or col < 0 or col >= w or clear[row, col] < radius:
            return False
    return True


@numba.njit(cache=True)
def _best_turn(err, large, small):
    """The turn action leaving the smallest |heading error|, or -1 when no turn reduces it."""
    best, best_err = -1, abs(err)
    # A left turn decreases yaw, so the error (desired - yaw) grows by the turn angle.
    for action, delta in ((ROTATE_LEFT, large), (ROTATE_RIGHT, -large),
                          (ROTATE_LEFT_SMALL, small), (ROTATE_RIGHT_SMALL, -small)):
        e = abs(wrap_deg(err + delta))
        if e < best_err - 1e-9:
            best, best_err = action, e
    return best


@numba.njit(cache=True)
def _n_turns(delta, large, small):
    """Fewest 30/6-degree turns that rotate by ``delta`` degrees (a multiple of ``small``)."""
    k = int(round(abs(wrap_deg(delta)) / small))
    per = int(round(large / small))
    best = k
    for a in range(k // per + 2):
        best = min(best, a + abs(k - per * a))
    return best


@numba.njit(cache=True)
def _face_cost(occ, lab, x0, z0, res, x, z, heading, pts, plab, max_d2, half_fov, large, small):
    """Fewest turns after which a target point is in view from (x, z), -1 if none is in range and sight."""
    best = -1
    for p in range(pts.shape[0]):
        if point_visible(occ, lab, x0, z0, res, x, z, heading, pts[p, 0], pts[p, 1], plab[p], max_d2, 360.0):
            e = abs(wrap_deg(bearing_deg(x, z, pts[p, 0], pts[p, 1]) - heading))
            need = 0 if e <= half_fov else _n_turns(math.ceil((e - half_fov) / small - 1e-9) * small, large, small)
            if best < 0 or need < best:
                best = need
    return best


@numba.njit(cache=True)
def _final_search(clear, occ, lab, x0, z0, res, x, z, yaw, pts, plab, radius, step, max_d2, half_fov,
                  large, small):
    """First action of the shortest plan (turn, move, turn, move, turn, end) ending in success, or -1."""
    n_head = int(round(360.0 / small))
    best_cost, best_h1 = 1 << 30, -1.0
    for k1 in range(n_head):
        h1 = k1 * small
        t1 = _n_turns(h1 - yaw, large, small)
        if t1 + 2 >= best_cost or not _move_ok(clear, x0, z0, res, x, z, h1, radius, step):
            continue
        r1 = math.radians(h1)
        x1, z1 = x + step * math.sin(r1), z + step * math.cos(r1)
        f = _face_cost(occ, lab, x0, z0, res, x1, z1, h1, pts, plab, max_d2, half_fov, large, small)
        if f >= 0 and t1 + 1 + f + 1 < best_cost:
            best_cost, best_h1 = t1 + 1 + f + 1, h1
        for k2 in range(n_head):
            h2 = k2 * small
            t2 = _n_turns(h2 - h1, large, small)
            if t1 + t2 + 3 >= best_cost or not _move_ok(clear, x0, z0, res, x1, z1, h2, radius, step):
                continue
            r2 = math.radians(h2)
            x2, z2 = x1 + step * math.sin(r2), z1 + step * math.cos(r2)
            f = _face_cost(occ, lab, x0, z0, res, x2, z2, h2, pts, plab, max_d2, half_fov, large, small)
            if f >= 0 and t1 + t2 + 2 + f + 1 < best_cost:
                best_cost, best_h1 = t1 + t2 + 2 + f + 1, h1
    if best_h1 < 0:
        return -1
    t = _best_turn(wrap_deg(best_h1 - yaw), large, small)
    return MOVE_AHEAD if t < 0 else t


@numba.njit(cache=True)
def _guide_after(clear, guide, x0, z0, res, x, z, heading, radius, step):
    """(ok, x', z', guidance at x') of a move along ``heading``; ok False when it is blocked."""
    if not _move_ok(clear, x0, z0, res, x, z, heading, radius, step):
        return False, x, z, np.inf
    t = math.radians(heading)
    x1, z1 = x + step * math.sin(t), z + step * math.cos(t)
    return True, x1, z1, guide[int(math.floor((z1 - z0) / res)), int(math.floor((x1 - x0) / res))]


@numba.njit(cache=True)
def _progress_search(clear, guide, x0, z0, res, x, z, yaw, radius, step, large, small):
    """First action of the plan of at most two (turn, move) pairs ending on the lowest guidance value.

    Used when the straight move toward the look-ahead point is blocked (narrow gaps, door frames):
    it finds the exact lattice headings that thread the agent's disc through. -1 if every move is blocked.
    """
    n_head = int(round(360.0 / small))
    best, best_h1 = np.inf, -1.0
    for k1 in range(n_head):
        h1 = k1 * small
        ok, x1, z1, g1 = _guide_after(clear, guide, x0, z0, res, x, z, h1, radius, step)
        if not ok:
            continue
        t1 = _n_turns(h1 - yaw, large, small)
        score = g1 + PLAN_STEP_COST * (t1 + 1)
        if score < best:
            best, best_h1 = score, h1
        for k2 in range(n_head):
            h2 = k2 * small
            t2 = _n_turns(h2 - h1, large, small)
            # A 0.2 m move lowers the guidance by at most its cost (length x (1 + penalty)) plus a cell or two.
            if g1 - step * (1.0 + CLEARANCE_PENALTY) - 4 * res + PLAN_STEP_COST * (t1 + t2 + 2) >= best:
                continue
            ok2, x2, z2, g2 = _guide_after(clear, guide, x0, z0, res, x1, z1, h2, radius, step)
            if ok2 and g2 + PLAN_STEP_COST * (t1 + t2 + 2) < best:
                best, best_h1 = g2 + PLAN_STEP_COST * (t1 + t2 + 2), h1
    if best_h1 < 0:
        return -1
    t = _best_turn(wrap_deg(best_h1 - yaw), large, small)
    return MOVE_AHEAD if t < 0 else t


@numba.njit(cache=True)
def _act(clear, occ, lab, x0, z0, res, dist, guide, parent, small_goal, pts, plab, xs, zs, yaws, radius, step,
         tol, half_fov, max_d2, large, small, min_clear, max_depth, search_range, out):
    h, w = clear.shape
    for i in range(xs.shape[0]):
        x, z, yaw = xs[i], zs[i], yaws[i]
        c = int(math.floor((x - x0) / res))
        r = int(math.floor((z - z0) / res))
        if r < 0 or r >= h or c < 0 or c >= w:
            out[i] = END  # outside the house: unsolvable, give up at once
            continue
        if not np.isfinite(dist[r, c]):
            # Off the navigable cells (e.g. a start pose too close to a wall): steer by the best
            # neighbour, as geodesic_distance does; no finite neighbour means unsolvable.
            best_v, br, bc = np.inf, -1, -1
            for rr in range(max(0, r - 1), min(h, r + 2)):
                for cc in range(max(0, c - 1), min(w, c + 2)):
                    v = guide[rr, cc] + math.hypot(x0 + (cc + 0.5) * res - x, z0 + (rr + 0.5) * res - z)
                    if v < best_v:
                        best_v, br, bc = v, rr, cc
            if not np.isfinite(best_v):
                out[i] = END
                continue
            r, c = br, bc
        if dist[r, c] == 0.0:
            best_err, found = 1e9, False
            for p in range(pts.shape[0]):
                if point_visible(occ, lab, x0, z0, res, x, z, yaw, pts[p, 0], pts[p, 1], plab[p], max_d2, 360.0):
                    e = wrap_deg(bearing_deg(x, z, pts[p, 0], pts[p, 1]) - yaw)
                    if abs(e) < abs(best_err):
                        best_err, found = e, True
            if found and abs(best_err) <= half_fov:
                out[i] = END
                continue
            if found:
                t = _best_turn(best_err, large, small)
                out[i] = t if t >= 0 else MOVE_AHEAD
                continue
        if guide[r, c] <= search_range:
            root = r * w + c
            while parent[root // w, root % w] >= 0:
                root = parent[root // w, root % w]
            if small_goal[root // w, root % w]:
                a = _final_search(clear, occ, lab, x0, z0, res, x, z, yaw, pts, plab, radius, step, max_d2,
                                  half_fov, large, small)
                if a >= 0:
                    out[i] = a
                    continue
        li = _lookahead(clear, parent, x0, z0, res, x, z, r * w + c, min_clear, max_depth)
        if li == r * w + c:
            # In the inner region without a visible target from this exact point: approach the nearest one.
            best_d, desired = 1e18, yaw
            for p in range(pts.shape[0]):
                d2 = (pts[p, 0] - x) ** 2 + (pts[p, 1] - z) ** 2
                if d2 < best_d:
                    best_d, desired = d2, bearing_deg(x, z, pts[p, 0], pts[p, 1])
        else:
            desired = bearing_deg(x, z, x0 + (li % w + 0.5) * res, z0 + (li // w + 0.5) * res)
        lattice = round(desired / small) * small
        if not _move_ok(clear, x0, z0, res, x, z, lattice, radius, step):
            a = _progress_search(clear, guide, x0, z0, res, x, z, yaw, radius, step, large, small)
            out[i] = a if a >= 0 else ROTATE_RIGHT
            continue
        err = wrap_deg(desired - yaw)
        if abs(err) <= tol and _move_ok(clear, x0, z0, res, x, z, yaw, radius, step):
            out[i] = MOVE_AHEAD
            continue
        t = _best_turn(err, large, small)
        out[i] = t if t >= 0 else MOVE_AHEAD


class ShortestPathExpert:
    """Acts like an agent that knows the map: follows the guidance field, ends when the target is in view.

    Example:
        >>> expert = ShortestPathExpert()
        >>> action = expert.act(world, "Bed", x, z, yaw)  # doctest: +SKIP
    """

    name = "expert"

    def __init__(self, align_tolerance: float = ALIGN_TOLERANCE):
        self.align_tolerance = float(align_tolerance)

    def prepare(self, world: NavWorld, target_type: str) -> GuidanceField:
        """Precompute (or fetch from ``world.cache``) the arrays for one target type."""
        return guidance_field(world, target_type)

    def _run(self, world: NavWorld, target_type: str, x: np.ndarray, z: np.ndarray, yaw: np.ndarray,
             out: np.ndarray) -> None:
        gf = self.prepare(world, target_type)
        tp = target_points(world, target_type)
        g = world.grid
        _act(g.clearance, world.occluder, g.label, g.x0, g.z0, g.resolution, gf.distance, gf.guidance,
             gf.parent, gf.small_goal, tp.points, tp.label, x, z, yaw, AGENT_RADIUS, MOVE_STEP,
             self.align_tolerance, FOV_DEG / 2.0, SUCCESS_DISTANCE ** 2, ROTATE_LARGE, ROTATE_SMALL,
             AGENT_RADIUS + g.resolution, LOOKAHEAD_CELLS, FINAL_SEARCH_RANGE, out)

    def act(self, world: NavWorld, target_type: str, x: float, z: float, yaw: float, *,
            collided: bool = False) -> int:
        """The expert's action (an index into ``spec.ACTIONS``) at one pose.

        ``collided`` is accepted for interface compatibility; the expert is memoryless and its
        moves are checked before they are taken, so it never needs it.
        """
        out = np.empty(1, dtype=np.int64)
        self._run(world, target_type, np.array([x], dtype=np.float64), np.array([z], dtype=np.float64),
                  np.array([yaw], dtype=np.float64), out)
        return int(out[0])

    def act_batch(self, worlds: list[NavWorld], env_idx: np.ndarray, target_types, x: np.ndarray,
                  z: np.ndarray, yaw: np.ndarray) -> np.ndarray:
        """Actions (int64 (B,)) for B agents; agent i is in ``worlds[env_idx[i]]`` looking for ``target_types[i]``.

        Agents are grouped by (house, target) and each group runs in one compiled call.
        """
        env_idx = np.asarray(env_idx, dtype=np.int64)
        x = np.ascontiguousarray(x, dtype=np.float64)
        z = np.ascontiguousarray(z, dtype=np.float64)
        yaw = np.ascontiguousarray(yaw, dtype=np.float64)
        n = len(env_idx)
        out = np.empty(n, dtype=np.int64)
        if isinstance(target_types, str):
            target_types = [target_types] * n
        groups: dict[tuple[int, str], list[int]] = {}
        for i, (e, t) in enumerate(zip(env_idx.tolist(), target_types, strict=True)):
            groups.setdefault((e, t), []).append(i)
        for (e, t), members in groups.items():
            if len(members) == n:
                self._run(worlds[e], t, x, z, yaw, out)
                break
            idx = np.array(members, dtype=np.int64)
            sub = np.empty(len(idx), dtype=np.int64)
            self._run(worlds[e], t, x[idx], z[idx], yaw[idx], sub)
            out[idx] = sub
        return out
