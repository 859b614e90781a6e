"""A frontier explorer that reads nothing but its own observations: it plans on the EgoMap it builds.

:class:`MapExplorerPolicy` is the searching teacher without privileges: its decisions are a
function of the same :class:`~adaptenv.sim.egomap.EgoMap` a map-reading student sees (scans
marked at the pose dead-reckoned from ``prev_action`` and ``collided``). Every step, for the whole
batch in one compiled kernel:

1. **Stop.** ``end`` when a ray of the current scan hits the target type within ``STOP_DISTANCE``.
2. **Cells** (0.2 m map cells): BLOCKED (not FREE), TIGHT (FREE and OBSTACLE), NEAR (FREE with an
   OBSTACLE 8-neighbour: the agent's radius is one cell) or CLEAR; the agent's own cell is never
   BLOCKED. Steps from NEAR and TIGHT cells cost ``1 + NEAR_COST`` and ``1 + TIGHT_COST`` times more.
3. **Goal.** Before the target was sighted: the frontier, CLEAR cells (else NEAR cells) with a
   4-neighbour that is unknown (neither FREE nor OBSTACLE), not the agent's own cell. After a
   sighting (any TARGET cell): NEAR or CLEAR cells within ``APPROACH_CELLS`` of a TARGET cell, or
   the frontier while none of those can be reached.
4. **Plan.** Dijkstra from the goal (8-connected, diagonals cost sqrt 2 and may not cut corners)
   within the box the agent's scans can have reached, replanned every ``REPLAN_EVERY`` steps, on
   the first sighting, after a bump or on reaching a frontier cell.
5. **Steer.** Aim at the farthest cell of the descent path (up to ``LOOKAHEAD`` cells) reachable
   in a straight line over CLEAR cells; move ahead when aligned within ``ALIGN_TOLERANCE`` and the
   cells up to half a cell past the move are not BLOCKED, else take the turn (30 or 6 degrees)
   leaving the smallest heading error. When that way is blocked, turn to the lattice heading whose
   clear move ends on the lowest cost-to-go and take that move. At an approach goal, face the
   nearest TARGET cell and step toward it. Without any goal in reach: rotate right.

A blocked move marks the cell ahead as OBSTACLE (the EgoMap does it) and triggers a replan; the
policy also remembers its last ``BUMPS`` blocked moves (pose and heading) and never repeats one.
It needs no :class:`~adaptenv.agents.policy.PolicyContext` (no ``bind``), is deterministic and
batch independent.

Example::

    adaptenv evaluate --policy map-explorer --houses suite:val-far -n 200
"""

from __future__ import annotations

import math

import numba
import numpy as np

from adaptenv.agents.policy import Observation, State
from adaptenv.sim.egomap import CELL, FREE, OBSTACLE, SIZE, TARGET, EgoMap
from adaptenv.sim.expert import ALIGN_TOLERANCE, _best_turn, _n_turns
from adaptenv.sim.spec import (
    END,
    MAX_RANGE,
    MOVE_AHEAD,
    MOVE_STEP,
    NO_ACTION,
    ROTATE_LARGE,
    ROTATE_RIGHT,
    ROTATE_SMALL,
    SUCCESS_DISTANCE,
)
from adaptenv.sim.task import wrap_deg

#: Steps between replans (a first sighting, a bump or a reached frontier also replan).
REPLAN_EVERY = 6
#: Cells along the descent path the agent may aim at.
LOOKAHEAD = 6
#: After a sighting, head for traversable cells within this many cells (1.2 m) of a TARGET cell.
APPROACH_CELLS = 6
#: Extra cost factor of a step from a NEAR cell (next to an OBSTACLE cell): paths keep a cell off walls where they can.
NEAR_COST = 3.0
#: Extra cost factor of a step from a TIGHT cell (FREE and OBSTACLE): only narrow passages use them.
TIGHT_COST = 20.0
#: Cost (cells of path) of one turn when searching the headings around a blocked move.
TURN_COST = 0.1
#: ``end`` when a ray of the current scan hits the target type this close (m).
STOP_DISTANCE = SUCCESS_DISTANCE - 0.4
#: Cells around the agent its scan can mark (MAX_RANGE plus the hit cell): the planning box grows by it.
REACH = int(math.ceil(MAX_RANGE / CELL)) + 2

_EXPLORE, _APPROACH = 0, 1
_BLOCKED, _TIGHT, _NEAR, _CLEAR = 0, 1, 2, 3
BUMPS = 64
"""Blocked moves (pose and heading) each agent remembers, so that it does not repeat one."""
_INF = np.float32(np.inf)
_SQRT2 = math.sqrt(2.0)
_PROBE = MOVE_STEP + 0.5 * CELL
"""Length (m) of the segment ahead a move must find traversable (a move's end plus half a cell)."""
_DR = np.array([-1, 1, 0, 0, -1, -1, 1, 1], dtype=np.int64)
_DC = np.array([0, 0, -1, 1, -1, 1, -1, 1], dtype=np.int64)


@numba.njit(cache=True, inline="always")
def _push(hk, hv, size, key, val):
    """Push (key, val) on the binary min-heap (hk, hv) of ``size`` entries; returns the new size."""
    j = size
    while j > 0:
        p = (j - 1) >> 1
        if hk[p] <= key:
            break
        hk[j] = hk[p]
        hv[j] = hv[p]
        j = p
    hk[j] = key
    hv[j] = val
    return size + 1


@numba.njit(cache=True, inline="always")
def _pop(hk, hv, size):
    """Pop the smallest entry of the heap: (key, val, new size)."""
    key, val = hk[0], hv[0]
    size -= 1
    lk, lv = hk[size], hv[size]
    j = 0
    while True:
        c = 2 * j + 1
        if c >= size:
            break
        if c + 1 < size and hk[c + 1] < hk[c]:
            c += 1
        if hk[c] >= lk:
            break
        hk[j] = hk[c]
        hv[j] = hv[c]
        j = c
    hk[j] = lk
    hv[j] = lv
    return key, val, size


@numba.njit(cache=True)
def _classify(g, cls, box, ar, ac):
    """Planning class of each cell of ``box``: BLOCKED (not FREE), TIGHT (FREE and OBSTACLE: a ray passed, another
    stopped in it), NEAR (FREE with an OBSTACLE 8-neighbour) or CLEAR (FREE, none); the agent's own cell at least TIGHT."""
    n = g.shape[0]
    for r in range(box[0], box[1]):
        for c in range(box[2], box[3]):
            v = g[r, c]
            k = _BLOCKED
            if v & OBSTACLE and v & FREE:
                k = _TIGHT
            elif v & FREE:
                k = _CLEAR
                for rr in range(max(r - 1, 0), min(r + 2, n)):
                    for cc in range(max(c - 1, 0), min(c + 2, n)):
                        if g[rr, cc] & OBSTACLE:
                            k = _NEAR
            cls[r, c] = k
    cls[ar, ac] = max(cls[ar, ac], _TIGHT)


@numba.njit(cache=True)
def _frontier(g, cls, box, ar, ac, least, goal):
    """Mark the frontier in ``goal``: cells of class >= ``least`` with an unknown 4-neighbour, not the agent's; count."""
    n = g.shape[0]
    count = 0
    for r in range(box[0], box[1]):
        for c in range(box[2], box[3]):
            goal[r, c] = False
            if cls[r, c] < least or (r == ar and c == ac):
                continue
            for k in range(4):
                rr, cc = r + _DR[k], c + _DC[k]
                if 0 <= rr < n and 0 <= cc < n and (g[rr, cc] & (FREE | OBSTACLE)) == 0:
                    goal[r, c] = True
                    count += 1
                    break
    return count


@numba.njit(cache=True)
def _approach(g, cls, box, radius, goal):
    """Mark NEAR or CLEAR cells within ``radius`` cells of a TARGET cell in ``goal``; count them."""
    r0, r1, c0, c1 = box[0], box[1], box[2], box[3]
    for r in range(r0, r1):
        for c in range(c0, c1):
            goal[r, c] = False
    count = 0
    r2 = radius * radius
    for r in range(r0, r1):
        for c in range(c0, c1):
            if not g[r, c] & TARGET:
                continue
            for rr in range(max(r - radius, r0), min(r + radius + 1, r1)):
                for cc in range(max(c - radius, c0), min(c + radius + 1, c1)):
                    if (rr - r) ** 2 + (cc - c) ** 2 <= r2 and cls[rr, cc] >= _NEAR and not goal[rr, cc]:
                        goal[rr, cc] = True
                        count += 1
    return count


@numba.njit(cache=True, inline="always")
def _cost(cls, r, c, k):
    """Cost of the step from cell (r, c) along neighbour direction k (length times the penalty of (r, c)'s class)."""
    base = _SQRT2 if k >= 4 else 1.0
    if cls[r, c] == _NEAR:
        return base * (1.0 + NEAR_COST)
    if cls[r, c] == _TIGHT:
        return base * (1.0 + TIGHT_COST)
    return base


@numba.njit(cache=True, inline="always")
def _step_ok(cls, box, r, c, k):
    """Whether the step from (r, c) along direction k stays on traversable cells of ``box`` without cutting a corner."""
    rr, cc = r + _DR[k], c + _DC[k]
    if rr < box[0] or rr >= box[1] or cc < box[2] or cc >= box[3] or cls[rr, cc] == _BLOCKED:
        return False
    return k < 4 or (cls[rr, c] != _BLOCKED and cls[r, cc] != _BLOCKED)


@numba.njit(cache=True)
def _dijkstra(cls, goal, box, dist, hk, hv):
    """Cost-to-go (cells, NEAR cells dearer) to the goal over traversable cells of ``box``, 8-connected."""
    n = cls.shape[0]
    size = 0
    for r in range(box[0], box[1]):
        for c in range(box[2], box[3]):
            if goal[r, c]:
                dist[r, c] = 0.0
                size = _push(hk, hv, size, 0.0, r * n + c)
            else:
                dist[r, c] = np.inf
    while size > 0:
        d, v, size = _pop(hk, hv, size)
        r, c = v // n, v % n
        if d > dist[r, c]:
            continue
        for k in range(8):
            if not _step_ok(cls, box, r, c, k):
                continue
            rr, cc = r + _DR[k], c + _DC[k]
            nd = d + _cost(cls, rr, cc, k)
            if nd < dist[rr, cc]:
                dist[rr, cc] = nd
                size = _push(hk, hv, size, nd, rr * n + cc)


@numba.njit(cache=True)
def _plan(g, cls, dist, box, ar, ac, approach, goal, hk, hv):
    """Dijkstra toward the approach goal (if ``approach`` and reachable), else the CLEAR frontier, else any
    frontier; returns the planned mode (-1 when no goal is reachable)."""
    _classify(g, cls, box, ar, ac)
    if approach and _approach(g, cls, box, APPROACH_CELLS, goal) > 0:
        _dijkstra(cls, goal, box, dist, hk, hv)
        if dist[ar, ac] < np.inf:
            return _APPROACH
    for least in (_CLEAR, _NEAR):
        if _frontier(g, cls, box, ar, ac, least, goal) > 0:
            _dijkstra(cls, goal, box, dist, hk, hv)
            if dist[ar, ac] < np.inf:
                return _EXPLORE
    return -1


@numba.njit(cache=True)
def _cell(x, z, half):
    """(row, col) of the map cell holding map-frame point (x, z)."""
    return int(math.floor(z / CELL)) + half, int(math.floor(x / CELL)) + half


@numba.njit(cache=True)
def _line_clear(cls, box, x, z, tx, tz, least, ar, ac, half):
    """Whether the segment (x, z) -> (tx, tz) (map frame, m) crosses only cells of class >= ``least`` or the agent's."""
    dx, dz = tx - x, tz - z
    steps = int(math.ceil(math.sqrt(dx * dx + dz * dz) / (0.5 * CELL)))
    for k in range(1, steps + 1):
        f = k / steps
        r, c = _cell(x + f * dx, z + f * dz, half)
        if r == ar and c == ac:
            continue
        if r < box[0] or r >= box[1] or c < box[2] or c >= box[3] or cls[r, c] < least:
            return False
    return True


@numba.njit(cache=True)
def _aim(cls, dist, box, x, z, ar, ac, half):
    """Farthest cell (row, col) of the descent path, up to LOOKAHEAD, reachable straight over CLEAR cells."""
    br, bc = ar, ac
    r, c = ar, ac
    for depth in range(LOOKAHEAD):
        best, nr, nc = np.inf, -1, -1
        for k in range(8):
            if not _step_ok(cls, box, r, c, k):
                continue
            rr, cc = r + _DR[k], c + _DC[k]
            v = dist[rr, cc] + _cost(cls, r, c, k)
            if dist[rr, cc] < dist[r, c] and v < best:
                best, nr, nc = v, rr, cc
        if nr < 0:
            break
        r, c = nr, nc
        tx, tz = (c - half + 0.5) * CELL, (r - half + 0.5) * CELL
        if depth > 0 and not _line_clear(cls, box, x, z, tx, tz, _CLEAR, ar, ac, half):
            break
        br, bc = r, c
    return br, bc


@numba.njit(cache=True)
def _clear_ahead(cls, box, bumps, x, z, heading, ar, ac, half):
    """Whether a move at ``heading`` (degrees) finds traversable cells up to _PROBE ahead and was not blocked before
    from this very pose."""
    for k in range(bumps.shape[0]):
        if abs(bumps[k, 0] - x) < 1e-6 and abs(bumps[k, 1] - z) < 1e-6 and abs(wrap_deg(bumps[k, 2] - heading)) < 0.5:
            return False
    t = math.radians(heading)
    return _line_clear(cls, box, x, z, x + _PROBE * math.sin(t), z + _PROBE * math.cos(t), _TIGHT, ar, ac, half)


@numba.njit(cache=True)
def _progress(cls, dist, box, bumps, x, z, yaw, ar, ac, half):
    """When the way to the aim is blocked: the lattice heading whose clear move ends on the lowest cost-to-go (each
    turn costing TURN_COST) and the first action toward it; (NaN, right turn) when no move makes progress."""
    best, best_h = dist[ar, ac], 1e9
    per = int(round(360.0 / ROTATE_SMALL))
    for k in range(per):
        h = yaw + k * ROTATE_SMALL
        if not _clear_ahead(cls, box, bumps, x, z, h, ar, ac, half):
            continue
        t = math.radians(h)
        r, c = _cell(x + MOVE_STEP * math.sin(t), z + MOVE_STEP * math.cos(t), half)
        if not (box[0] <= r < box[1] and box[2] <= c < box[3]):
            continue
        v = dist[r, c] + TURN_COST * _n_turns(k * ROTATE_SMALL, ROTATE_LARGE, ROTATE_SMALL)
        if v < best:
            best, best_h = v, h
    if best_h > 1e8:
        return np.nan, ROTATE_RIGHT
    turn = _best_turn(wrap_deg(best_h - yaw), ROTATE_LARGE, ROTATE_SMALL)
    return best_h, MOVE_AHEAD if turn < 0 else turn


@numba.njit(cache=True)
def _steer(cls, dist, box, bumps, x, z, yaw, ar, ac, half):
    """Turn or move toward the aim cell of the plan; search the lattice headings when the way there is blocked.
    Returns (heading to keep turning to, or NaN; action)."""
    tr, tc = _aim(cls, dist, box, x, z, ar, ac, half)
    tx, tz = (tc - half + 0.5) * CELL, (tr - half + 0.5) * CELL
    err = wrap_deg(math.degrees(math.atan2(tx - x, tz - z)) - yaw)
    if abs(err) <= ALIGN_TOLERANCE and _clear_ahead(cls, box, bumps, x, z, yaw, ar, ac, half):
        return np.nan, MOVE_AHEAD
    turn = _best_turn(err, ROTATE_LARGE, ROTATE_SMALL)
    lattice = yaw + round(err / ROTATE_SMALL) * ROTATE_SMALL
    if turn >= 0 and _clear_ahead(cls, box, bumps, x, z, lattice, ar, ac, half):
        return np.nan, turn
    return _progress(cls, dist, box, bumps, x, z, yaw, ar, ac, half)


@numba.njit(cache=True)
def _face_target(g, cls, box, bumps, x, z, yaw, ar, ac, half):
    """At an approach goal: turn toward the nearest TARGET cell; when facing it, step ahead unless blocked."""
    best, tx, tz = np.inf, 0.0, 0.0
    for r in range(box[0], box[1]):
        for c in range(box[2], box[3]):
            if g[r, c] & TARGET:
                px, pz = (c - half + 0.5) * CELL, (r - half + 0.5) * CELL
                d2 = (px - x) ** 2 + (pz - z) ** 2
                if d2 < best:
                    best, tx, tz = d2, px, pz
    err = wrap_deg(math.degrees(math.atan2(tx - x, tz - z)) - yaw)
    turn = _best_turn(err, ROTATE_LARGE, ROTATE_SMALL)
    if turn >= 0 and abs(err) > ROTATE_SMALL / 2:
        return turn
    if _clear_ahead(cls, box, bumps, x, z, yaw, ar, ac, half):
        return MOVE_AHEAD
    return ROTATE_RIGHT


@numba.njit(cache=True)
def _act_one(i, grid, pose, first, prev, collided, depth, sem, target, cls, dist, box, plan_box, mode, age, sighted,
             bumps, n_bumps, heading, goal, hk, hv, out):
    """Agent i's action into ``out[i]``; ``goal``, ``hk`` and ``hv`` are its chunk's scratch."""
    n = grid.shape[1]
    half = n // 2
    x, z, yaw = pose[i, 0], pose[i, 1], pose[i, 2]
    ar, ac = _cell(x, z, half)
    ar, ac = min(max(ar, 0), n - 1), min(max(ac, 0), n - 1)
    if first[i]:
        sighted[i] = False
        mode[i] = -1
        bumps[i, :, :] = np.nan
        n_bumps[i] = 0
        heading[i] = np.nan
        box[i, 0], box[i, 1], box[i, 2], box[i, 3] = ar, ar + 1, ac, ac + 1
    elif collided[i] != 0:
        k = n_bumps[i] % BUMPS
        bumps[i, k, 0], bumps[i, k, 1] = x, z
        bumps[i, k, 2] = yaw if prev[i] == MOVE_AHEAD else yaw + 180.0
        n_bumps[i] += 1
    box[i, 0] = max(min(box[i, 0], ar - REACH), 0)
    box[i, 1] = min(max(box[i, 1], ar + REACH + 1), n)
    box[i, 2] = max(min(box[i, 2], ac - REACH), 0)
    box[i, 3] = min(max(box[i, 3], ac + REACH + 1), n)
    stop, seen = False, False
    for k in range(depth.shape[1]):
        if sem[i, k] == target[i] and depth[i, k] < MAX_RANGE - 1e-6:
            seen = True
            if depth[i, k] <= STOP_DISTANCE:
                stop = True
    if stop:
        out[i] = END
        return
    new_sighting = seen and not sighted[i]
    sighted[i] = sighted[i] or seen
    age[i] += 1
    g, d, ci, pb = grid[i], dist[i], cls[i], plan_box[i]
    # replan on schedule, without a plan, after a bump, on the first sighting, or at a reached frontier cell
    if (mode[i] < 0 or age[i] >= REPLAN_EVERY or collided[i] != 0 or new_sighting
            or (mode[i] == _EXPLORE and d[ar, ac] == 0.0)):
        pb[:] = box[i]
        mode[i] = _plan(g, ci, d, pb, ar, ac, sighted[i], goal, hk, hv)
        age[i] = 0
    if heading[i] == heading[i]:
        # finish the turn a heading search chose, then take its move (no dithering around a blocked move)
        turn = _best_turn(wrap_deg(heading[i] - yaw), ROTATE_LARGE, ROTATE_SMALL)
        if turn >= 0:
            out[i] = turn
            return
        heading[i] = np.nan
        if _clear_ahead(ci, pb, bumps[i], x, z, yaw, ar, ac, half):
            out[i] = MOVE_AHEAD
            return
    if mode[i] < 0 or not (pb[0] <= ar < pb[1] and pb[2] <= ac < pb[3]) or not d[ar, ac] < np.inf:
        out[i] = ROTATE_RIGHT
    elif mode[i] == _APPROACH and d[ar, ac] == 0.0:
        out[i] = _face_target(g, ci, pb, bumps[i], x, z, yaw, ar, ac, half)
    else:
        heading[i], out[i] = _steer(ci, d, pb, bumps[i], x, z, yaw, ar, ac, half)


@numba.njit(cache=True, parallel=True)
def _act(grid, pose, first, prev, collided, depth, sem, target, cls, dist, box, plan_box, mode, age, sighted, bumps,
         n_bumps, heading, goal, hk, hv, out):
    """One action per agent from its EgoMap (see the module docstring); updates the plan arrays in place. Agents are
    dealt round-robin to ``goal.shape[0]`` chunks, each with its own scratch (``goal[c]``, ``hk[c]``, ``hv[c]``)."""
    b, chunks = grid.shape[0], goal.shape[0]
    for c in numba.prange(chunks):
        for i in range(c, b, chunks):
            _act_one(i, grid, pose, first, prev, collided, depth, sem, target, cls, dist, box, plan_box, mode, age,
                     sighted, bumps, n_bumps, heading, goal[c], hk[c], hv[c], out)


def _first(obs: Observation, done: np.ndarray) -> np.ndarray:
    """Where an agent's map starts fresh: a new episode, or no previous action."""
    b = len(done)
    prev = np.asarray(obs["prev_action"], dtype=np.int64).reshape(b)
    return np.asarray(done, dtype=np.bool_).reshape(b) | (prev == NO_ACTION)


class MapExplorerPolicy:
    """Frontier exploration and target approach planned on the agent's own EgoMap (see the module docstring).

    Batched, deterministic, no ``bind``: it reads only its observations. ``emap`` is the map it acted
    on at the last call (a trainer may read it); the plan arrays are kept alongside, per agent.
    """

    name = "map-explorer"

    def __init__(self) -> None:
        self.emap = EgoMap(0)
        self._alloc(0)

    def _alloc(self, batch: int, emap: EgoMap | None = None) -> None:
        """Fresh plan arrays for ``batch`` agents, and a fresh map unless ``emap`` (someone else's) is given."""
        self.emap = EgoMap(batch) if emap is None else emap
        n = self.emap.size
        self._cls = np.zeros((batch, n, n), dtype=np.uint8)
        self._dist = np.full((batch, n, n), np.inf, dtype=np.float32)
        self._box = np.zeros((batch, 4), dtype=np.int64)
        self._plan_box = np.zeros((batch, 4), dtype=np.int64)
        self._mode = np.full(batch, -1, dtype=np.int64)
        self._age = np.zeros(batch, dtype=np.int64)
        self._sighted = np.zeros(batch, dtype=np.bool_)
        self._bumps = np.full((batch, BUMPS, 3), np.nan)
        self._n_bumps = np.zeros(batch, dtype=np.int64)
        self._heading = np.full(batch, np.nan)
        chunks = max(1, min(batch, numba.get_num_threads()))  # planning scratch per chunk of agents (see _act)
        self._goal = np.zeros((chunks, n, n), dtype=np.bool_)
        self._heap_k = np.empty((chunks, 9 * n * n), dtype=np.float32)
        self._heap_v = np.empty((chunks, 9 * n * n), dtype=np.int64)

    def initial_state(self, batch: int) -> State:
        return None

    def act(self, obs: Observation, state: State, done: np.ndarray) -> tuple[np.ndarray, State]:
        b = len(done)
        if self.emap.batch != b:
            self._alloc(b)
        first = _first(obs, done)
        self.emap.update(obs, first)
        return self._decide(self.emap, obs, first), state

    def act_on(self, emap: EgoMap, obs: Observation, done: np.ndarray) -> np.ndarray:
        """Actions planned on ``emap``, a map someone else keeps and has already updated with ``obs`` and ``done``
        (a trainer's MapObserver): the same actions as :meth:`act`, without marking the scan twice. Call one of
        the two for a batch, not both."""
        b = len(done)
        if emap.size != SIZE or emap.batch != b:
            raise ValueError(f"act_on needs an EgoMap of {b} agents and size {SIZE}, got {emap.batch} and {emap.size}")
        if len(self._mode) != b:
            self._alloc(b, emap)
        self.emap = emap
        return self._decide(emap, obs, _first(obs, done))

    def _decide(self, emap: EgoMap, obs: Observation, first: np.ndarray) -> np.ndarray:
        """Run the planner on ``emap`` (already updated with ``obs``)."""
        b = len(first)
        out = np.empty(b, dtype=np.int64)
        _act(emap.grid, emap.pose, first, np.asarray(obs["prev_action"], dtype=np.int64).reshape(b),
             np.asarray(obs["collided"], dtype=np.int64).reshape(b),
             np.ascontiguousarray(obs["depth"], dtype=np.float64).reshape(b, -1) * MAX_RANGE,
             np.ascontiguousarray(obs["semantic"], dtype=np.int64).reshape(b, -1),
             np.asarray(obs["target"], dtype=np.int64).reshape(b), self._cls, self._dist, self._box, self._plan_box,
             self._mode, self._age, self._sighted, self._bumps, self._n_bumps, self._heading, self._goal, self._heap_k, self._heap_v, out)
        return out


__all__ = ["MapExplorerPolicy"]
