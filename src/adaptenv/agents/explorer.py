"""A teacher that searches: frontier exploration over the map it has seen, then the shortest path to the target.

Unlike the shortest-path expert, :class:`ExplorerPolicy` does not know where the target is. Each
agent keeps a memory of what its scans have shown it and acts on that alone:

1. **Mapping.** Every step, each depth ray (and two rays interpolated between each neighbouring
   pair, at the smaller of the two depths) marks the cells it crossed (sampled every two cells) as *seen*, up to the hit
   point; the hit cell is marked too. Rays whose semantic class is the target type mark their hit
   cell as a *target sighting*.
2. **Goal.** Before any sighting, the goal is the set of *frontier* cells: seen cells where the
   agent's disc fits with an unseen neighbour (the edge of the known map). After a sighting, the
   goal is the seen navigable cells within ``APPROACH_DISTANCE`` of a sighted cell.
3. **Path.** A Dijkstra field toward the goal over the seen navigable cells, on a grid ``COARSE``
   times coarser than the world's (0.2 m cells), replanned every ``REPLAN_EVERY`` steps or when the
   goal changes. The agent aims at the farthest cell of its path (up to ``LOOKAHEAD`` coarse cells)
   it can reach in a straight line, turning or moving like the expert (same turn choice, same
   exact move check, same two-move search around blocked moves).
4. **Stop.** ``end`` when the current scan shows the target type within ``STOP_DISTANCE``.

What it reads besides its observations (``depth``, ``semantic``, ``target``): through the
:class:`~adaptenv.agents.policy.PolicyContext`, its own pose (``x``, ``z``, ``yaw``) and house
index, and from the compiled world only the grid frame (origin, resolution, shape) and the
*clearance of cells it has seen* (the distance to the nearest obstacle, which near the edge of its
map can reflect an obstacle not yet seen) plus the exact clearance along the 0.2 m move it is
about to take (what a bumper would tell it). It never reads target instances, the success region,
distance fields or unseen cells' contents.

Example::

    adaptenv evaluate --policy explorer --houses suite:large -n 200
"""

from __future__ import annotations

import math

import numba
import numpy as np

from adaptenv.agents.policy import Observation, PolicyContext, State
from adaptenv.errors import ConfigError
from adaptenv.sim.expert import (
    ALIGN_TOLERANCE,
    _best_turn,
    _move_ok,
    _progress_search,
    _segment_clear,
)
from adaptenv.sim.geodesic import shortest_paths
from adaptenv.sim.scan import RAY_OFFSETS_DEG
from adaptenv.sim.spec import (
    AGENT_RADIUS,
    END,
    MAX_RANGE,
    MOVE_AHEAD,
    MOVE_STEP,
    ROTATE_LARGE,
    ROTATE_RIGHT,
    ROTATE_SMALL,
    SUCCESS_DISTANCE,
    class_id,
)
from adaptenv.sim.task import bearing_deg, wrap_deg

#: Planning cells are this many world cells on a side (0.2 m at the default 0.05 m resolution).
COARSE = 4
#: Steps between replans (a changed goal, a sighting or reaching the goal also replan).
REPLAN_EVERY = 6
#: Coarse cells along the path the agent may aim at.
LOOKAHEAD = 6
#: After a sighting, head for seen navigable cells this close (m) to a sighted cell.
APPROACH_DISTANCE = 1.2
#: ``end`` when a ray of the current scan hits the target type this close (m).
STOP_DISTANCE = SUCCESS_DISTANCE - 0.4
#: Interpolated rays between neighbouring scan rays (closes the gaps of the fan at long range).
INTERPOLATE = 2


@numba.njit(cache=True)
def _mark_cell(seen, nav, cnav, ccount, row, col, f):
    """Mark one world cell seen; keep the coarse counts of seen cells and seen navigable blocks."""
    if not seen[row, col]:
        seen[row, col] = True
        ccount[row // f, col // f] += 1
        if nav[row, col]:
            cnav[row // f, col // f] = True


@numba.njit(cache=True)
def _mark_scan(seen, nav, cnav, ccount, csighted, x0, z0, res, f, x, z, yaw, offsets, depth, sem, target,
               n_interp, body):
    """Mark the cells crossed by each ray (and interpolated rays) as seen, and the agent's own disc;
    target hits mark their coarse block as sighted. Returns whether this scan sighted the target."""
    h, w = seen.shape
    n = offsets.shape[0]
    found = False
    for k in range(n):
        for s in range(n_interp + 1 if k < n - 1 else 1):
            fr = s / (n_interp + 1)
            if s == 0:
                d, off, hit_cls = depth[k], offsets[k], sem[k]
            else:
                d = min(depth[k], depth[k + 1])
                off = offsets[k] + fr * (offsets[k + 1] - offsets[k])
                hit_cls = sem[k] if sem[k] == sem[k + 1] else -1
            t = math.radians(yaw + off)
            ux, uz = math.sin(t), math.cos(t)
            steps = int(d / (2 * res)) + 1
            for i in range(steps + 1):
                r = min(i * 2 * res, d)
                col = int(math.floor((x + r * ux - x0) / res))
                row = int(math.floor((z + r * uz - z0) / res))
                if 0 <= row < h and 0 <= col < w:
                    _mark_cell(seen, nav, cnav, ccount, row, col, f)
            if d < MAX_RANGE - 1e-6:
                rr = d + 0.5 * res
                col = int(math.floor((x + rr * ux - x0) / res))
                row = int(math.floor((z + rr * uz - z0) / res))
                if 0 <= row < h and 0 <= col < w:
                    _mark_cell(seen, nav, cnav, ccount, row, col, f)
                    if hit_cls == target:
                        csighted[row // f, col // f] = True
                        found = True
    c0, r0 = int(math.floor((x - x0) / res)), int(math.floor((z - z0) / res))
    for row in range(max(0, r0 - body), min(h, r0 + body + 1)):
        for col in range(max(0, c0 - body), min(w, c0 + body + 1)):
            _mark_cell(seen, nav, cnav, ccount, row, col, f)
    return found


@numba.njit(cache=True)
def _aim(clear, parent, x0, z0, res, cres, x, z, start, min_clear, max_depth):
    """Farthest coarse cell along the path from ``start`` (<= max_depth) reachable in a straight line."""
    cw = parent.shape[1]
    best, a = start, start
    for depth in range(max_depth):
        p = parent[a // cw, a % cw]
        if p < 0:
            break
        a = p
        ax, az = x0 + (a % cw + 0.5) * cres, z0 + (a // cw + 0.5) * cres
        if depth > 0 and not _segment_clear(clear, x0, z0, res, x, z, ax, az, min_clear):
            break
        best = a
    return best


class _Memory:
    """What one agent knows: seen cells (and their coarse summaries), sighted target blocks, its plan."""

    def __init__(self, shape: tuple[int, int]):
        ch, cw = -(-shape[0] // COARSE), -(-shape[1] // COARSE)
        self.seen = np.zeros(shape, dtype=np.bool_)
        self.cnav = np.zeros((ch, cw), dtype=np.bool_)
        """Coarse blocks holding a seen cell where the agent's disc fits."""
        self.ccount = np.zeros((ch, cw), dtype=np.int32)
        """Seen cells per coarse block."""
        self.csighted = np.zeros((ch, cw), dtype=np.bool_)
        """Coarse blocks where a ray hit the target type."""
        self.sighted = False
        self.parent: np.ndarray | None = None
        self.guide: np.ndarray | None = None
        self.mode = ""
        self.age = 0


class ExplorerPolicy:
    """Frontier exploration, then the shortest path on its own map to the sighted target (see module docstring).

    Batched and deterministic (no randomness). Needs :meth:`bind` like the expert, but reads only its
    pose and the grid geometry it has seen (documented in the module docstring).
    """

    name = "explorer"

    def __init__(self) -> None:
        self._class_id = class_id
        self._context: PolicyContext | None = None
        self._mem: list[_Memory | None] = []
        self._offsets = np.ascontiguousarray(RAY_OFFSETS_DEG, dtype=np.float64)

    def bind(self, context: PolicyContext) -> None:
        self._context = context
        self._mem = []

    def initial_state(self, batch: int) -> State:
        return None

    def act(self, obs: Observation, state: State, done: np.ndarray) -> tuple[np.ndarray, State]:
        ctx = self._context
        if ctx is None:
            raise ConfigError("the explorer policy needs its pose from the runner; run it through adaptenv's "
                              "runners (evaluate, rollout, train) which bind a PolicyContext")
        b = len(done)
        if len(self._mem) != b:
            self._mem = [None] * b
        out = np.empty(b, dtype=np.int64)
        depth = np.asarray(obs["depth"], dtype=np.float64) * MAX_RANGE
        sem = np.asarray(obs["semantic"], dtype=np.int64)
        target = np.asarray(obs["target"], dtype=np.int64).reshape(b)
        for i in range(b):
            world = ctx.worlds[int(ctx.env_idx[i])]
            mem = self._mem[i]
            if done[i] or mem is None or mem.seen.shape != world.grid.shape:
                mem = self._mem[i] = _Memory(world.grid.shape)
            out[i] = self._act_one(world, mem, float(ctx.x[i]), float(ctx.z[i]), float(ctx.yaw[i]),
                                   depth[i], sem[i], int(target[i]))
        return out, state

    # -- one agent -----------------------------------------------------------------------------------

    def _act_one(self, world, mem: _Memory, x: float, z: float, yaw: float, depth: np.ndarray,
                 sem: np.ndarray, target: int) -> int:
        g = world.grid
        res = g.resolution
        new_sighting = _mark_scan(mem.seen, self._navigable(world), mem.cnav, mem.ccount, mem.csighted, g.x0, g.z0,
                                  res, COARSE, x, z, yaw, self._offsets, np.ascontiguousarray(depth),
                                  np.ascontiguousarray(sem), target, INTERPOLATE,
                                  int(math.ceil(AGENT_RADIUS / res)))
        hits = (sem == target) & (depth <= STOP_DISTANCE)
        if hits.any():
            return END
        mem.sighted |= bool(new_sighting)
        mode = "approach" if mem.sighted else "explore"
        mem.age += 1
        if mem.parent is None or mode != mem.mode or mem.age >= REPLAN_EVERY or (mode == "approach" and new_sighting):
            self._plan(world, mem, mode, x, z)
        return self._steer(world, mem, x, z, yaw)

    @staticmethod
    def _navigable(world) -> np.ndarray:
        """bool (H, W): cells where the agent's disc fits (read only where the agent has seen)."""
        key = ("explorer.navigable",)
        if key not in world.cache:
            world.cache[key] = np.ascontiguousarray(world.grid.clearance >= AGENT_RADIUS)
        return world.cache[key]

    def _plan(self, world, mem: _Memory, mode: str, x: float, z: float) -> None:
        """Recompute the coarse Dijkstra field toward the current goal (frontier or sighted target)."""
        from scipy import ndimage

        g = world.grid
        cres = g.resolution * COARSE
        cnav = mem.cnav.copy()
        if mode == "approach":
            dist = ndimage.distance_transform_edt(~mem.csighted) * cres
            goal = cnav & (dist <= APPROACH_DISTANCE)
        else:
            # a block is unknown while under a quarter of its cells are seen; frontier = known
            # navigable blocks next to an unknown one
            unknown = mem.ccount < (COARSE * COARSE) // 4
            near = np.zeros_like(unknown)
            near[1:, :] |= unknown[:-1, :]
            near[:-1, :] |= unknown[1:, :]
            near[:, 1:] |= unknown[:, :-1]
            near[:, :-1] |= unknown[:, 1:]
            goal = cnav & near & ~unknown
        r, c = int((z - g.z0) / cres), int((x - g.x0) / cres)
        if 0 <= r < cnav.shape[0] and 0 <= c < cnav.shape[1]:
            cnav[r, c] = True
            # the agent's own block never counts as a goal while exploring (it would stop the search)
            if mode == "explore":
                goal[r, c] = False
        guide, parent = shortest_paths(cnav, goal, cres)
        mem.guide, mem.parent = guide, parent
        mem.mode, mem.age = mode, 0

    def _steer(self, world, mem: _Memory, x: float, z: float, yaw: float) -> int:
        """Turn or move toward the farthest straight-line-reachable cell of the plan (as the expert steers)."""
        g = world.grid
        res = g.resolution
        cres = res * COARSE
        parent, guide = mem.parent, mem.guide
        ch, cw = parent.shape
        r, c = int((z - g.z0) / cres), int((x - g.x0) / cres)
        if not (0 <= r < ch and 0 <= c < cw) or not np.isfinite(guide[r, c]):
            return ROTATE_RIGHT  # no known way to any goal from here: look around
        if guide[r, c] == 0.0:
            if mem.mode == "approach":
                return self._face_sighting(mem, g, x, z, yaw)
            mem.age = REPLAN_EVERY  # reached a frontier: replan next step
            return ROTATE_RIGHT
        a = _aim(g.clearance, parent, g.x0, g.z0, res, cres, x, z, r * cw + c, AGENT_RADIUS + res, LOOKAHEAD)
        desired = bearing_deg(x, z, g.x0 + (a % cw + 0.5) * cres, g.z0 + (a // cw + 0.5) * cres)
        lattice = round(desired / ROTATE_SMALL) * ROTATE_SMALL
        if not _move_ok(g.clearance, g.x0, g.z0, res, x, z, lattice, AGENT_RADIUS, MOVE_STEP):
            fine = np.repeat(np.repeat(guide, COARSE, axis=0), COARSE, axis=1)[: g.shape[0], : g.shape[1]]
            act = _progress_search(g.clearance, np.ascontiguousarray(fine), g.x0, g.z0, res, x, z, yaw,
                                   AGENT_RADIUS, MOVE_STEP, ROTATE_LARGE, ROTATE_SMALL)
            return int(act) if act >= 0 else ROTATE_RIGHT
        err = wrap_deg(desired - yaw)
        if abs(err) <= ALIGN_TOLERANCE and _move_ok(g.clearance, g.x0, g.z0, res, x, z, yaw, AGENT_RADIUS, MOVE_STEP):
            return MOVE_AHEAD
        t = _best_turn(err, ROTATE_LARGE, ROTATE_SMALL)
        return int(t) if t >= 0 else MOVE_AHEAD

    @staticmethod
    def _face_sighting(mem: _Memory, g, x: float, z: float, yaw: float) -> int:
        """At the approach goal: turn toward the nearest sighted block, or step toward it when facing it."""
        cres = g.resolution * COARSE
        rows, cols = np.nonzero(mem.csighted)
        px, pz = g.x0 + (cols + 0.5) * cres, g.z0 + (rows + 0.5) * cres
        k = int(np.argmin((px - x) ** 2 + (pz - z) ** 2))
        err = wrap_deg(bearing_deg(x, z, float(px[k]), float(pz[k])) - yaw)
        t = _best_turn(err, ROTATE_LARGE, ROTATE_SMALL)
        if t >= 0 and abs(err) > ROTATE_SMALL / 2:
            return int(t)
        if _move_ok(g.clearance, g.x0, g.z0, g.resolution, x, z, yaw, AGENT_RADIUS, MOVE_STEP):
            return MOVE_AHEAD
        return ROTATE_RIGHT
