"""The egocentric depth-and-semantics scan: a lidar-like fan of rays cast on the occupancy raster.

``N_RAYS`` rays spread evenly over ``FOV_DEG`` around the heading (ray 0 is the leftmost, at
yaw - FOV/2; left is the direction of decreasing yaw) each return the distance to the first
obstacle divided by ``MAX_RANGE`` (1.0 when nothing is hit within range) and the semantic class of
what they hit (``CLASS_NONE`` when nothing).

Rays are cast through *free rectangles*: every free cell belongs to two obstacle-free rectangles of
cells, its **row rectangle** (the cell's run of free cells along its row, extended up and down for
as long as the whole run stays free) and its **column rectangle** (the same with rows and columns
swapped); :func:`free_runs` numbers them once per house. A ray inside a free rectangle cannot meet
an obstacle before leaving it through one of the two sides it is heading for, so from its current
point it jumps to the farther of its exits from the cell's two rectangles, reads the rectangles of
the cell it lands in, and stops in the first obstacle cell. Depth is the exact distance at which
the ray enters that cell (to within float rounding), and a jump always crosses at least one cell
boundary, so no obstacle, however thin, is skipped.

Each rectangle reaches across the whole free stretch of its row or column, so a ray does not
slow down for obstacles beside it or behind it: in open rooms most rays need one or two jumps, and
in clutter the jumps still follow the aisles between objects (measurements in docs/simulator.md).
The scan sees every obstacle cell, floor furniture included (beds, tables, toilets): it is a
sensor at knee height, not a camera. Closed doors read as ``CLASS_DOOR``, and so do the frames of
open doorways (the 10 cm of wall on each side of the hole).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numba
import numpy as np

from adaptenv.sim.physics import PackedGrids
from adaptenv.sim.spec import CLASS_NONE, CLASS_WALL, FOV_DEG, MAX_RANGE, N_RAYS

#: Ray directions relative to the heading, degrees; ray 0 is the leftmost.
RAY_OFFSETS_DEG = FOV_DEG * (np.arange(N_RAYS) / (N_RAYS - 1) - 0.5)
RAY_COS = np.cos(np.radians(RAY_OFFSETS_DEG))
RAY_SIN = np.sin(np.radians(RAY_OFFSETS_DEG))
_NUDGE = 1e-6
"""Cells added to each jump so the ray lands strictly inside the next cell despite rounding."""
_RUNS_KEY = ("scan", "free_runs")


@dataclass(frozen=True)
class FreeRuns:
    """The free rectangles the scan jumps through, for one house or several packed together.

    ``ids`` holds two entries per cell, aligned with PackedGrids (cell ``k`` of the packed rasters
    at ``2 * k``): the row rectangle and the column rectangle of a free cell; on an obstacle cell 0
    and the cell's semantic class (so a ray that lands there reads its class from the same place).
    Rectangle ``j`` of house ``e`` is entries ``4 * (offset[e] + j)`` to ``+ 4`` of ``table``:
    ``(col0, row0, col1, row1)`` in cells, ends exclusive; rectangle 0 of each house is unused (the
    obstacle marker).
    """

    ids: np.ndarray
    """uint16 (uint32 for a house with more than 65,534 rectangles), two per cell, flat."""
    table: np.ndarray
    """uint16 (4 n,): the rectangles' bounds in cells, four values each."""
    offset: np.ndarray
    """int64 (E,): each house's first rectangle in ``table``."""


@numba.njit(cache=True)
def _row_rectangles(blocked, rid, rects):
    """Number the row rectangles of ``blocked``: fill ``rid`` (H, W) with 1 + index and ``rects`` with
    (col0, row0, col1, row1); returns their count. A run is extended a row at a time while the
    row's blocked-cell count over the run (a prefix sum) is zero."""
    h, w = blocked.shape
    before = np.zeros((h, w + 1), dtype=np.int32)  # blocked cells left of each column, per row
    for r in range(h):
        for c in range(w):
            before[r, c + 1] = before[r, c] + (1 if blocked[r, c] else 0)
    n = 0
    for r in range(h):
        c = 0
        while c < w:
            if blocked[r, c]:
                rid[r, c] = 0
                c += 1
                continue
            c1 = c
            while c1 < w and not blocked[r, c1]:
                c1 += 1
            r0 = r
            while r0 > 0 and before[r0 - 1, c1] == before[r0 - 1, c]:
                r0 -= 1
            r1 = r + 1
            while r1 < h and before[r1, c1] == before[r1, c]:
                r1 += 1
            rects[n, 0], rects[n, 1], rects[n, 2], rects[n, 3] = c, r0, c1, r1
            n += 1
            rid[r, c:c1] = n
            c = c1
    return n


def _rectangles(blocked: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row rectangles of a raster: ids int64 (H, W) (1-based, 0 on obstacles) and bounds int64 (n, 4)."""
    rid = np.empty(blocked.shape, dtype=np.int64)
    rects = np.empty((blocked.size // 2 + blocked.shape[0] + 1, 4), dtype=np.int64)
    n = _row_rectangles(blocked, rid, rects)
    return rid, rects[:n]


def free_runs(blocked: np.ndarray, semantic: np.ndarray) -> FreeRuns:
    """The row and column rectangles of a raster (cells outside it count as obstacles), with the
    ``semantic`` class of each obstacle cell."""
    blocked = np.ascontiguousarray(blocked, dtype=np.bool_)
    if max(blocked.shape) > np.iinfo(np.uint16).max:
        raise ValueError(f"a raster of {blocked.shape} cells is too large for the scan (at most 65,535 a side)")
    row_ids, row_rects = _rectangles(blocked)
    col_ids, col_rects = _rectangles(np.ascontiguousarray(blocked.T))
    col_ids, col_rects = col_ids.T, col_rects[:, [1, 0, 3, 2]]  # back to (col0, row0, col1, row1)
    n_rows = len(row_rects)
    count = 1 + n_rows + len(col_rects)
    dtype = np.uint16 if count <= np.iinfo(np.uint16).max else np.uint32
    ids = np.empty((*blocked.shape, 2), dtype=dtype)
    ids[..., 0] = row_ids
    ids[..., 1] = np.where(blocked, semantic, col_ids + n_rows)
    table = np.zeros((count, 4), dtype=np.uint16)
    table[1:1 + n_rows] = row_rects
    table[1 + n_rows:] = col_rects
    return FreeRuns(ids.reshape(-1), table.reshape(-1), np.zeros(1, dtype=np.int64))


def world_runs(world) -> FreeRuns:
    """A NavWorld's free rectangles, computed once and kept in ``world.cache`` (so ``world.nbytes`` counts them)."""
    runs = world.cache.get(_RUNS_KEY)
    if runs is None:
        runs = world.cache[_RUNS_KEY] = free_runs(world.grid.blocked, world.semantic)
    return runs


def _concat(parts: list[FreeRuns]) -> FreeRuns:
    """Several houses' FreeRuns packed in order (one house's arrays are used in place)."""
    if len(parts) == 1:
        return parts[0]
    sizes = np.array([len(p.table) // 4 for p in parts], dtype=np.int64)
    return FreeRuns(np.concatenate([p.ids for p in parts]), np.concatenate([p.table for p in parts]),
                    np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64))


def pack_runs(worlds) -> FreeRuns:
    """The free rectangles of several NavWorlds, aligned with ``PackedGrids.from_worlds(worlds)``."""
    return _concat([world_runs(w) for w in worlds])


_packed_memo: dict[int, tuple[weakref.ref, FreeRuns]] = {}


def _runs_of_grids(grids: PackedGrids, semantic: np.ndarray) -> FreeRuns:
    """Free rectangles derived from PackedGrids' clearance (obstacle cells have clearance 0), memoized
    per clearance array (by identity, dropped with it) so repeated :func:`scan` calls pay once."""
    key = id(grids.clearance)
    hit = _packed_memo.get(key)
    if hit is not None and hit[0]() is grids.clearance:
        return hit[1]
    parts = []
    for e in range(grids.offset.shape[0]):
        h, w, off = int(grids.height[e]), int(grids.width[e]), int(grids.offset[e])
        parts.append(free_runs(grids.clearance[off:off + h * w].reshape(h, w) <= 0.0,
                               semantic[off:off + h * w].reshape(h, w)))
    runs = _concat(parts)
    _packed_memo[key] = (weakref.ref(grids.clearance, lambda _, k=key: _packed_memo.pop(k, None)), runs)
    return runs


@numba.njit(cache=True, inline="always")
def _scan_one(ids, table, toff, off, h, w, x0, z0, res, x, z, yaw, ray_cos, ray_sin, max_range, depth,
              classes, i):
    """Fill row i of ``depth`` (normalized) and ``classes`` for one agent at (x, z, yaw).

    ``ids`` and ``table`` are a :class:`FreeRuns`' arrays, ``toff`` the house's first rectangle and
    ``off`` its cell offset. All rays advance in lockstep, one jump each per sweep, so the CPU
    overlaps the independent memory loads of different rays. Distances are in cells inside the loop.
    """
    n = ray_cos.shape[0]
    a = math.radians(yaw)
    sy, cy = math.sin(a), math.cos(a)
    inv = 1.0 / res
    u0, v0 = (x - x0) * inv, (z - z0) * inv  # position in cell units
    ray = np.empty((5, n))  # two allocations per scan, not seven: they are the kernel's fixed cost
    du, dv, iu, iv, t = ray[0], ray[1], ray[2], ray[3], ray[4]
    sides = np.empty(n, dtype=np.int64)  # table columns of the sides the ray heads for; -1 once done
    for r in range(n):
        # heading (sin, cos) of yaw + offset r by the angle-sum identities
        du[r] = sy * ray_cos[r] + cy * ray_sin[r]
        dv[r] = cy * ray_cos[r] - sy * ray_sin[r]
        iu[r] = 1.0 / du[r] if du[r] != 0.0 else 1e30
        iv[r] = 1.0 / dv[r] if dv[r] != 0.0 else 1e30
        sides[r] = (2 if du[r] >= 0.0 else 0) + 4 * (3 if dv[r] >= 0.0 else 1)
        t[r] = 0.0
        depth[i, r] = 1.0
        classes[i, r] = CLASS_NONE
    t_max = max_range * inv
    remaining = n
    while remaining > 0:
        for r in range(n):
            sd = sides[r]
            if sd < 0:  # this ray is done
                continue
            tr = t[r]
            u, v = u0 + tr * du[r], v0 + tr * dv[r]
            cls = -1
            jump = 0.0
            if u < 0.0 or v < 0.0:
                cls = CLASS_WALL
            else:
                col, row = int(u), int(v)  # == floor for non-negative values
                if row >= h or col >= w:
                    cls = CLASS_WALL
                else:
                    cell = off + row * w + col
                    k = np.int64(ids[2 * cell])
                    if k == 0:
                        cls = np.int64(ids[2 * cell + 1])
                    else:  # leave the farther-reaching of the cell's two rectangles
                        su, sv = sd & 3, sd >> 2
                        b1 = 4 * (toff + k)
                        b2 = 4 * (toff + np.int64(ids[2 * cell + 1]))
                        j1 = min((table[b1 + su] - u) * iu[r], (table[b1 + sv] - v) * iv[r])
                        j2 = min((table[b2 + su] - u) * iu[r], (table[b2 + sv] - v) * iv[r])
                        jump = max(j1, j2) + _NUDGE
            if cls >= 0:  # hit an obstacle cell (or left the raster, which only outside cells border)
                depth[i, r] = tr * res / max_range
                classes[i, r] = cls
                sides[r] = -1
                remaining -= 1
                continue
            tr += jump
            if tr > t_max:
                sides[r] = -1
                remaining -= 1
            t[r] = tr


@numba.njit(cache=True, parallel=True)
def _scan_batch(ids, table, toffs, offs, hs, ws, x0s, z0s, ress, env, x, z, yaw, ray_cos, ray_sin, max_range,
                depth, classes):
    for i in numba.prange(x.shape[0]):
        e = env[i]
        _scan_one(ids, table, toffs[e], offs[e], hs[e], ws[e], x0s[e], z0s[e], ress[e], x[i], z[i], yaw[i],
                  ray_cos, ray_sin, max_range, depth, classes, i)


def pack_semantic(worlds) -> np.ndarray:
    """The ``semantic`` rasters of several NavWorlds in one flat int16 array, aligned with PackedGrids
    (one world's raster is used in place, as a flat view)."""
    if len(worlds) == 1:
        return np.ascontiguousarray(worlds[0].semantic, dtype=np.int16).reshape(-1)
    return np.concatenate([np.asarray(w.semantic, dtype=np.int16).ravel() for w in worlds])


def scan(grids: PackedGrids, semantic: np.ndarray, env: np.ndarray, x: np.ndarray, z: np.ndarray,
         yaw: np.ndarray, max_range: float = MAX_RANGE, runs: FreeRuns | None = None
         ) -> tuple[np.ndarray, np.ndarray]:
    """Scan from each pose: returns depth float32 (B, N_RAYS) in [0, 1] and classes int64 (B, N_RAYS).

    ``semantic`` is :func:`pack_semantic` of the same worlds as ``grids``; ``env[i]`` is agent i's
    house index. ``runs`` is :func:`pack_runs` of those worlds; when omitted it is derived from
    ``grids`` once and remembered for as long as ``grids.clearance`` lives.
    """
    if runs is None:
        runs = _runs_of_grids(grids, semantic)
    n = np.shape(x)[0]
    depth = np.empty((n, N_RAYS), dtype=np.float32)
    classes = np.empty((n, N_RAYS), dtype=np.int64)
    _scan_batch(runs.ids, runs.table, runs.offset, grids.offset, grids.height, grids.width,
                grids.x0, grids.z0, grids.resolution, np.asarray(env, dtype=np.int64), np.asarray(x, dtype=np.float64),
                np.asarray(z, dtype=np.float64), np.asarray(yaw, dtype=np.float64), RAY_COS, RAY_SIN,
                float(max_range), depth, classes)
    return depth, classes


def scan_world(world, x: float, z: float, yaw: float, max_range: float = MAX_RANGE) -> tuple[np.ndarray, np.ndarray]:
    """Scan from one pose in one NavWorld: depth float32 (N_RAYS,), classes int64 (N_RAYS,).

    A convenience for tests and tools (it packs the world each call); simulators use :func:`scan`.
    """
    depth, classes = scan(PackedGrids.from_worlds([world]), np.asarray(world.semantic, dtype=np.int16).ravel(),
                          np.zeros(1, np.int64), np.array([x]), np.array([z]), np.array([yaw]), max_range,
                          runs=pack_runs([world]))
    return depth[0], classes[0]
