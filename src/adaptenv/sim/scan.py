"""The egocentric depth-and-semantics scan: a lidar-like fan of rays cast on the occupancy raster.

``N_RAYS`` rays spread evenly over ``FOV_DEG`` around the heading (ray 0 is the leftmost, at
yaw - FOV/2; left is the direction of decreasing yaw) each return the distance to the first
obstacle divided by ``MAX_RANGE`` (1.0 when nothing is hit within range) and the semantic class of
what they hit (``CLASS_NONE`` when nothing).

Rays are cast through *free squares*: for every free cell and each of the four quadrants of
direction, :func:`free_squares` stores the side ``s`` of the largest obstacle-free square of cells
that has this cell as its corner and extends into that quadrant (``s = 0`` on obstacle cells;
cells outside the raster count as obstacles). A ray whose direction lies in a quadrant cannot
leave that square before crossing its far sides, so it jumps straight to the nearer of those
two sides, then reads the square of the cell it lands in, and stops in the first obstacle cell.
Depth is the exact distance at which the ray enters that cell (to within float rounding), and
a step always crosses at least one cell boundary, so no obstacle, however thin, is skipped.

Unlike sphere tracing on the clearance field (which the scan used before), the step does not
shrink for obstacles beside or behind the ray, only for those in its quadrant ahead: clutter costs
fewer extra steps, and open rooms take fewer steps too (see docs/simulator.md for measurements).
The scan sees every obstacle cell, floor furniture included (beds, tables, toilets): it is a
sensor at knee height, not a camera. Closed doors read as ``CLASS_DOOR``, and so do the frames of
open doorways (the 10 cm of wall on each side of the hole).
"""

from __future__ import annotations

import math
import weakref

import numba
import numpy as np

from adaptenv.sim.physics import PackedGrids
from adaptenv.sim.spec import CLASS_NONE, CLASS_WALL, FOV_DEG, MAX_RANGE, N_RAYS

#: Ray directions relative to the heading, degrees; ray 0 is the leftmost.
RAY_OFFSETS_DEG = FOV_DEG * (np.arange(N_RAYS) / (N_RAYS - 1) - 0.5)
RAY_COS = np.cos(np.radians(RAY_OFFSETS_DEG))
RAY_SIN = np.sin(np.radians(RAY_OFFSETS_DEG))
N_QUADRANTS = 4
"""Quadrant q of a direction (du, dv): bit 0 set when du < 0, bit 1 set when dv < 0."""
_NUDGE = 1e-6
"""Cells added to each jump so the ray lands strictly inside the next cell despite rounding."""
_SQUARES_KEY = ("scan", "free_squares")


@numba.njit(cache=True)
def _free_squares(blocked, out):
    """Fill ``out`` (4, H, W) uint8 with the free-square sides of each quadrant (capped at 255).

    The classic largest-square recurrence, swept from the far corner of each quadrant:
    ``s = 1 + min(s of the three neighbours ahead)`` on free cells, 0 on obstacles and off the raster.
    """
    h, w = blocked.shape
    for q in range(N_QUADRANTS):
        su = -1 if q & 1 else 1
        sv = -1 if q & 2 else 1
        r_first, r_stop = (h - 1, -1) if sv > 0 else (0, h)
        c_first, c_stop = (w - 1, -1) if su > 0 else (0, w)
        for r in range(r_first, r_stop, -sv):
            for c in range(c_first, c_stop, -su):
                if blocked[r, c]:
                    out[q, r, c] = 0
                    continue
                rn, cn = r + sv, c + su
                m = 0
                if 0 <= rn < h and 0 <= cn < w:
                    m = min(out[q, rn, c], out[q, r, cn], out[q, rn, cn])
                out[q, r, c] = min(m + 1, 255)


def free_squares(blocked: np.ndarray) -> np.ndarray:
    """uint8 (4, H, W): per quadrant, the side in cells of the largest free square cornered at each cell."""
    blocked = np.ascontiguousarray(blocked, dtype=np.bool_)
    out = np.empty((N_QUADRANTS, *blocked.shape), dtype=np.uint8)
    _free_squares(blocked, out)
    return out


def world_squares(world) -> np.ndarray:
    """A NavWorld's free squares, computed once and kept in ``world.cache`` (so ``world.nbytes`` counts them)."""
    sq = world.cache.get(_SQUARES_KEY)
    if sq is None:
        sq = world.cache[_SQUARES_KEY] = free_squares(world.grid.blocked)
    return sq


def pack_squares(worlds) -> np.ndarray:
    """The free squares of several NavWorlds in one flat uint8 array, aligned with PackedGrids: house
    e's quadrant q starts at ``4 * offset[e] + q * H_e * W_e`` (one world's array is used in place)."""
    if len(worlds) == 1:
        return world_squares(worlds[0]).reshape(-1)
    return np.concatenate([world_squares(w).ravel() for w in worlds])


_packed_memo: dict[int, tuple[weakref.ref, np.ndarray]] = {}


def _squares_of_grids(grids: PackedGrids) -> np.ndarray:
    """Free squares derived from PackedGrids' clearance (obstacle cells have clearance 0), memoized
    per clearance array (by identity, dropped with it) so repeated :func:`scan` calls pay once."""
    key = id(grids.clearance)
    hit = _packed_memo.get(key)
    if hit is not None and hit[0]() is grids.clearance:
        return hit[1]
    parts = []
    for e in range(grids.offset.shape[0]):
        h, w, off = int(grids.height[e]), int(grids.width[e]), int(grids.offset[e])
        parts.append(free_squares(grids.clearance[off:off + h * w].reshape(h, w) <= 0.0).ravel())
    sq = parts[0] if len(parts) == 1 else np.concatenate(parts)
    _packed_memo[key] = (weakref.ref(grids.clearance, lambda _, k=key: _packed_memo.pop(k, None)), sq)
    return sq


@numba.njit(cache=True, inline="always")
def _scan_one(sq, sem, off, h, w, x0, z0, res, x, z, yaw, ray_cos, ray_sin, max_range, depth, classes, i):
    """Fill row i of ``depth`` (normalized) and ``classes`` for one agent at (x, z, yaw).

    ``sq`` is :func:`pack_squares` output and ``off`` the house's cell offset. All rays advance in
    lockstep, one jump each per sweep, so the CPU overlaps the independent memory loads of different
    rays. Distances are in cells inside the loop.
    """
    n = ray_cos.shape[0]
    a = math.radians(yaw)
    sy, cy = math.sin(a), math.cos(a)
    inv = 1.0 / res
    hw = h * w
    u0, v0 = (x - x0) * inv, (z - z0) * inv  # position in cell units
    ray = np.empty((5, n))  # two allocations per scan, not seven: they are the kernel's fixed cost
    du, dv, iu, iv, t = ray[0], ray[1], ray[2], ray[3], ray[4]
    base = np.empty(n, dtype=np.int64)  # start of the ray's quadrant in ``sq``; -1 once the ray is done
    for r in range(n):
        # heading (sin, cos) of yaw + offset r by the angle-sum identities
        du[r] = sy * ray_cos[r] + cy * ray_sin[r]
        dv[r] = cy * ray_cos[r] - sy * ray_sin[r]
        iu[r] = 1.0 / du[r] if du[r] != 0.0 else 1e30
        iv[r] = 1.0 / dv[r] if dv[r] != 0.0 else 1e30
        base[r] = 4 * off + ((1 if du[r] < 0.0 else 0) + (2 if dv[r] < 0.0 else 0)) * hw
        t[r] = 0.0
        depth[i, r] = 1.0
        classes[i, r] = CLASS_NONE
    t_max = max_range * inv
    remaining = n
    while remaining > 0:
        for r in range(n):
            b = base[r]
            if b < 0:  # this ray is done
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
                    s = np.int64(sq[b + row * w + col])
                    if s == 0:
                        cls = sem[off + row * w + col]
                    else:  # leave the free square through the nearer of its two far sides
                        bu = col + s if du[r] >= 0.0 else col + 1 - s
                        bv = row + s if dv[r] >= 0.0 else row + 1 - s
                        jump = min((bu - u) * iu[r], (bv - v) * iv[r]) + _NUDGE
            if cls >= 0:  # hit an obstacle cell (or left the raster, which only outside cells border)
                depth[i, r] = tr * res / max_range
                classes[i, r] = cls
                base[r] = -1
                remaining -= 1
                continue
            tr += jump
            if tr > t_max:
                base[r] = -1
                remaining -= 1
            t[r] = tr


@numba.njit(cache=True, parallel=True)
def _scan_batch(sq, sem, offs, hs, ws, x0s, z0s, ress, env, x, z, yaw, ray_cos, ray_sin, max_range, depth,
                classes):
    for i in numba.prange(x.shape[0]):
        e = env[i]
        _scan_one(sq, sem, offs[e], hs[e], ws[e], x0s[e], z0s[e], ress[e], x[i], z[i], yaw[i],
                  ray_cos, ray_sin, max_range, depth, classes, i)


def pack_semantic(worlds) -> np.ndarray:
    """The ``semantic`` rasters of several NavWorlds in one flat int16 array, aligned with PackedGrids
    (one world's raster is used in place, as a flat view)."""
    if len(worlds) == 1:
        return np.ascontiguousarray(worlds[0].semantic, dtype=np.int16).reshape(-1)
    return np.concatenate([np.asarray(w.semantic, dtype=np.int16).ravel() for w in worlds])


def scan(grids: PackedGrids, semantic: np.ndarray, env: np.ndarray, x: np.ndarray, z: np.ndarray,
         yaw: np.ndarray, max_range: float = MAX_RANGE, squares: np.ndarray | None = None
         ) -> tuple[np.ndarray, np.ndarray]:
    """Scan from each pose: returns depth float32 (B, N_RAYS) in [0, 1] and classes int64 (B, N_RAYS).

    ``semantic`` is :func:`pack_semantic` of the same worlds as ``grids``; ``env[i]`` is agent i's
    house index. ``squares`` is :func:`pack_squares` of those worlds; when omitted it is derived from
    ``grids`` once and remembered for as long as ``grids.clearance`` lives.
    """
    if squares is None:
        squares = _squares_of_grids(grids)
    n = np.shape(x)[0]
    depth = np.empty((n, N_RAYS), dtype=np.float32)
    classes = np.empty((n, N_RAYS), dtype=np.int64)
    _scan_batch(squares, semantic, grids.offset, grids.height, grids.width, grids.x0, grids.z0,
                grids.resolution, np.asarray(env, dtype=np.int64), np.asarray(x, dtype=np.float64),
                np.asarray(z, dtype=np.float64), np.asarray(yaw, dtype=np.float64), RAY_COS, RAY_SIN,
                float(max_range), depth, classes)
    return depth, classes


def scan_world(world, x: float, z: float, yaw: float, max_range: float = MAX_RANGE) -> tuple[np.ndarray, np.ndarray]:
    """Scan from one pose in one NavWorld: depth float32 (N_RAYS,), classes int64 (N_RAYS,).

    A convenience for tests and tools (it packs the world each call); simulators use :func:`scan`.
    """
    depth, classes = scan(PackedGrids.from_worlds([world]), np.asarray(world.semantic, dtype=np.int16).ravel(),
                          np.zeros(1, np.int64), np.array([x]), np.array([z]), np.array([yaw]), max_range,
                          squares=pack_squares([world]))
    return depth[0], classes[0]
