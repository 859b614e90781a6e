"""Success regions and geodesic distance fields: where ``end`` can succeed and how far that is.

The geodesic distance is a shortest path over navigable cells (clearance >= AGENT_RADIUS) with
16 neighbours: the 8 king moves (cost res, res*sqrt(2)) plus the 8 knight moves (cost
res*sqrt(5)), never cutting a corner (a move needs every cell its segment crosses to be
navigable). Knight moves cut the metric's worst error against the true Euclidean shortest path
from 8.2% (8 neighbours) to 2.7%. Navigable connectivity is unchanged (4-connected components).
Fields are cached per target type in ``world.cache``, compactly: only the values on navigable cells
(the only cells a field can be finite on), numbered by one :class:`CellIndex` per world that every
type shares, so a field costs 4 bytes per navigable cell instead of 4 per cell; the values are
exactly the full field's. Once a type's field exists its success region is not kept either (it is
exactly the field's zeros).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numba
import numpy as np
from scipy import ndimage

from adaptenv.sim.spec import AGENT_RADIUS, SUCCESS_DISTANCE
from adaptenv.sim.targets import Episode, los_clear, target_points
from adaptenv.sim.world import NavWorld

# Moves (dr, dc) and the two cells each crosses besides its ends (equal to an end for king moves).
_MOVES = [(0, 1), (1, 0), (0, -1), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1),
          (1, 2), (2, 1), (-1, 2), (-2, 1), (1, -2), (2, -1), (-1, -2), (-2, -1)]


def _crossed(dr: int, dc: int) -> tuple[tuple[int, int], tuple[int, int]]:
    if abs(dr) == abs(dc):  # diagonal: both orthogonal neighbours
        return (dr, 0), (0, dc)
    if abs(dr) == 2:  # (2, 1): the middle row, both columns
        return (dr // 2, 0), (dr // 2, dc)
    if abs(dc) == 2:
        return (0, dc // 2), (dr, dc // 2)
    return (0, 0), (0, 0)


_DR = np.array([m[0] for m in _MOVES], dtype=np.int64)
_DC = np.array([m[1] for m in _MOVES], dtype=np.int64)
_LEN = np.array([math.hypot(*m) for m in _MOVES], dtype=np.float64)
_C1 = np.array([_crossed(*m)[0] for m in _MOVES], dtype=np.int64)
_C2 = np.array([_crossed(*m)[1] for m in _MOVES], dtype=np.int64)


@numba.njit(cache=True, inline="always")
def _sift_up(hk, hv, pos, k):
    key, v = hk[k], hv[k]
    while k > 0:
        p = (k - 1) >> 1
        if hk[p] <= key:
            break
        hk[k], hv[k] = hk[p], hv[p]
        pos[hv[k]] = k
        k = p
    hk[k], hv[k] = key, v
    pos[v] = k


@numba.njit(cache=True, inline="always")
def _sift_down(hk, hv, pos, k, n):
    key, v = hk[k], hv[k]
    while True:
        c = 2 * k + 1
        if c >= n:
            break
        if c + 1 < n and hk[c + 1] < hk[c]:
            c += 1
        if hk[c] >= key:
            break
        hk[k], hv[k] = hk[c], hv[c]
        pos[hv[k]] = k
        k = c
    hk[k], hv[k] = key, v
    pos[v] = k


@numba.njit(cache=True)
def _dijkstra(nav, mult, src, res, drs, dcs, lens, c1, c2, dist, parent):
    """Multi-source Dijkstra (indexed binary heap with decrease-key); step cost = length * mult[destination]."""
    h, w = nav.shape
    hk = np.empty(h * w, dtype=np.float64)
    hv = np.empty(h * w, dtype=np.int64)
    pos = np.full(h * w, -1, dtype=np.int64)  # heap slot, -1 never pushed, -2 settled
    n = 0
    for r in range(h):
        for c in range(w):
            if src[r, c] and nav[r, c]:
                i = r * w + c
                dist[i] = 0.0
                hk[n], hv[n], pos[i] = 0.0, i, n
                n += 1
    n_moves = drs.shape[0]
    while n > 0:
        d, i = hk[0], hv[0]
        pos[i] = -2
        n -= 1
        if n > 0:
            hk[0], hv[0] = hk[n], hv[n]
            pos[hv[0]] = 0
            _sift_down(hk, hv, pos, 0, n)
        r, c = i // w, i % w
        for m in range(n_moves):
            rr, cc = r + drs[m], c + dcs[m]
            if rr < 0 or rr >= h or cc < 0 or cc >= w or not nav[rr, cc]:
                continue
            j = rr * w + cc
            if pos[j] == -2:
                continue
            if not nav[r + c1[m, 0], c + c1[m, 1]] or not nav[r + c2[m, 0], c + c2[m, 1]]:
                continue
            nd = d + lens[m] * res * mult[rr, cc]
            if nd < dist[j]:
                dist[j] = nd
                parent[j] = i
                if pos[j] == -1:
                    hk[n], hv[n] = nd, j
                    n += 1
                    _sift_up(hk, hv, pos, n - 1)
                else:
                    hk[pos[j]] = nd
                    _sift_up(hk, hv, pos, pos[j])


def shortest_paths(nav: np.ndarray, sources: np.ndarray, res: float,
                   mult: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Distances (float32 (H, W), inf where unreachable) and parent cell indices (int64, -1 at sources).

    ``mult`` (float32 (H, W)) scales the cost of entering each cell; None means plain length.
    """
    h, w = nav.shape
    dist = np.full(h * w, np.inf, dtype=np.float64)
    parent = np.full(h * w, -1, dtype=np.int64)
    if mult is None:
        mult = np.ones((h, w), dtype=np.float32)
    if sources.any():
        _dijkstra(nav, mult, sources, float(res), _DR, _DC, _LEN, _C1, _C2, dist, parent)
    return dist.reshape(h, w).astype(np.float32), parent.reshape(h, w)


@numba.njit(cache=True)
def _scan_region(mask, occ, lab, x0, z0, res, pts, plab, max_d, out, first):
    """Mark in ``out`` the cells of ``mask`` whose centre sees some sample point within max_d (any yaw).

    With ``first`` it stops at the first such cell and returns its flat index (-1 when there is none);
    otherwise it marks them all and returns -1. One kernel for both: beside the two former twin kernels
    (CPU time, one process, shared machine) it took 0.995-1.002x their time for whole regions and
    1.005-1.009x for first cells.
    """
    h, w = mask.shape
    reach = int(math.ceil(max_d / res)) + 1
    max_d2 = max_d * max_d
    for p in range(pts.shape[0]):
        px, pz = pts[p, 0], pts[p, 1]
        pc = int(math.floor((px - x0) / res))
        pr = int(math.floor((pz - z0) / res))
        for row in range(max(0, pr - reach), min(h, pr + reach + 1)):
            cz = z0 + (row + 0.5) * res
            for col in range(max(0, pc - reach), min(w, pc + reach + 1)):
                if not mask[row, col] or out[row, col]:
                    continue
                cx = x0 + (col + 0.5) * res
                dx, dz = px - cx, pz - cz
                if dx * dx + dz * dz > max_d2:
                    continue
                if los_clear(occ, lab, x0, z0, res, cx, cz, px, pz, plab[p]):
                    if first:
                        return row * w + col
                    out[row, col] = True
    return -1


def first_region_cell(mask: np.ndarray, occluder: np.ndarray, label: np.ndarray, x0: float, z0: float, res: float,
                 points: np.ndarray, point_labels: np.ndarray) -> int:
    """A cell (flat index) where the success region of the sample ``points`` (labels ``point_labels``)
    meets ``mask``, or -1 when they do not meet.

    With ``mask`` a subset of the navigable cells (e.g. the start's component) the answer is >= 0
    exactly when ``(success_region(world, t) & mask).any()`` for a world with these occluder and
    label grids and the points of ``target_points(world, t)``; the whole region is never computed.
    """
    if not len(points):
        return -1
    mask = np.ascontiguousarray(mask, dtype=np.bool_)
    return int(_scan_region(mask, occluder, label, float(x0), float(z0), float(res),
                            np.ascontiguousarray(points, dtype=np.float64),
                            np.ascontiguousarray(point_labels, dtype=np.int64), SUCCESS_DISTANCE,
                            np.zeros(mask.shape, dtype=np.bool_), True))


def success_region(world: NavWorld, target_type: str) -> np.ndarray:
    """bool (H, W): :func:`enterable` cells from whose centre turning toward some instance makes ``end`` succeed.

    Exactly the :func:`enterable` cells where :func:`adaptenv.sim.task.visible_instances` with a
    360-degree field of view is non-empty at the cell centre (same sample points, same line-of-sight
    walk): a region the agent cannot enter in its own motion is no region, so solvability, the
    distance fields and the episode sampler agree with what the agent (and the expert) can reach.
    """
    values = world.cache.get(("distance", target_type))
    if values is not None:  # the region is exactly where the field is 0 (its sources; every step costs > 0)
        return _expand(world, values == 0.0, False)
    key = ("region", target_type)
    if key not in world.cache:
        world.cache[key] = _compute_region(world, target_type)
    return world.cache[key]


def reuse_region(world: NavWorld, base: NavWorld, target_type: str) -> bool:
    """Give ``world`` (a few objects moved from ``base``) the success region of ``target_type`` that ``base`` has
    cached, when it is provably the same; True when it did.

    It is the same when both have the same grid and target instances, the same occluder and label cells within
    reach of every sample point (all that :func:`_scan_region` reads) and the same navigable cells two cells further
    (all that the 3 x 3 opening of :func:`enterable` reads there). Nothing is computed in ``base``.
    """
    key = ("region", target_type)
    if key in world.cache or ("distance", target_type) in world.cache:
        return False
    if key not in base.cache and ("distance", target_type) not in base.cache:
        return False
    g, b = world.grid, base.grid
    if (g.shape != b.shape or (g.x0, g.z0, g.resolution) != (b.x0, b.z0, b.resolution)
            or not _same_instances(world.instances_of(target_type), base.instances_of(target_type))):
        return False
    tp = target_points(base, target_type)
    if len(tp.points):
        cells = np.unique(np.stack(g.to_cell(tp.points[:, 0], tp.points[:, 1]), axis=1), axis=0)
        reach = int(math.ceil(SUCCESS_DISTANCE / g.resolution)) + 1
        if (_near_cells((world.occluder != base.occluder) | (g.label != b.label), cells, reach)
                or _near_cells((g.clearance >= AGENT_RADIUS) != (b.clearance >= AGENT_RADIUS), cells, reach + 2)):
            return False
    world.cache[key] = success_region(base, target_type).copy()
    return True


def _near_cells(mask: np.ndarray, cells: np.ndarray, reach: int) -> bool:
    """Whether a True cell of ``mask`` lies within ``reach`` rows and columns of one of ``cells`` ((N, 2) rows, cols)."""
    rows, cols = np.nonzero(mask)
    lo, hi = cells.min(axis=0) - reach, cells.max(axis=0) + reach
    box = (rows >= lo[0]) & (rows <= hi[0]) & (cols >= lo[1]) & (cols <= hi[1])
    rows, cols = rows[box], cols[box]
    return bool(len(rows)) and bool(((np.abs(rows[:, None] - cells[None, :, 0]) <= reach)
                                     & (np.abs(cols[:, None] - cells[None, :, 1]) <= reach)).any())


def _same_instances(a: list, b: list) -> bool:
    """Whether two lists of target instances are the same objects at the same place."""
    return len(a) == len(b) and all(x.object_id == y.object_id and x.label == y.label
                                    and np.array_equal(x.corners, y.corners) for x, y in zip(a, b, strict=True))


def _compute_region(world: NavWorld, target_type: str) -> np.ndarray:
    g = world.grid
    out = np.zeros(g.shape, dtype=np.bool_)
    tp = target_points(world, target_type)
    if len(tp.points):
        _scan_region(navigable(world), world.occluder, g.label, g.x0, g.z0, g.resolution,
                     tp.points, tp.label, SUCCESS_DISTANCE, out, False)
    return out & enterable(world)


def navigable(world: NavWorld) -> np.ndarray:
    """bool (H, W): cells where the agent disc fits (recomputed from the clearance: one comparison per
    cell; the cached :func:`cell_index` holds the same information for the simulator)."""
    return world.grid.navigable(AGENT_RADIUS)


def enterable(world: NavWorld) -> np.ndarray:
    """bool (H, W): navigable cells the agent can stop on in its own motion: the navigable mask opened
    by a 3 x 3 square, so a pocket or strip of navigable cells less than three cells (0.15 m) wide is
    dropped. The disc fits there, but 0.2 m moves along 6-degree headings step over or past it; a
    success region made only of such cells made episodes "solvable" that the expert ran to the step
    limit on. Corridors stay passable (the distance fields run over :func:`navigable`).
    """
    return ndimage.binary_opening(navigable(world), structure=_ENTER, border_value=0)


_ENTER = np.ones((3, 3), dtype=bool)


CHUNK_BITS = 7
CHUNK = 1 << CHUNK_BITS
"""Cells per chunk of :class:`CellIndex` (128: ranks within a chunk fit in a byte)."""
NOT_NAVIGABLE = 255
"""``CellIndex.rank`` of a cell that is not navigable (holds no field value)."""


@dataclass(frozen=True)
class CellIndex:
    """Row-major numbering of a world's navigable cells, shared by all its compact distance fields.

    Flat cell ``i`` (``row * W + col``) holds entry ``start[i // CHUNK] + rank[i]`` of a compact field,
    or no entry (the field is inf there) when ``rank[i] == NOT_NAVIGABLE``: 1 byte a cell, the same as
    a navigable mask, plus 4 bytes per CHUNK cells.
    """

    rank: np.ndarray
    """uint8 (H * W,): the cell's rank among the navigable cells of its chunk, NOT_NAVIGABLE if none."""
    start: np.ndarray
    """int64 (ceil(H * W / CHUNK),): navigable cells before each chunk."""
    cells: int
    """Navigable cells (the length of every compact field)."""

    @classmethod
    def from_mask(cls, nav: np.ndarray) -> CellIndex:
        """Number the True cells of ``nav`` (bool (H, W)) in row-major order."""
        flat = np.ascontiguousarray(nav, dtype=np.bool_).reshape(-1)
        chunks = -(-flat.size // CHUNK)
        padded = np.zeros(chunks * CHUNK, dtype=np.bool_)
        padded[:flat.size] = flat
        padded = padded.reshape(chunks, CHUNK)
        within = np.cumsum(padded, axis=1, dtype=np.int32) - 1
        rank = np.where(padded, within, NOT_NAVIGABLE).astype(np.uint8).reshape(-1)[:flat.size].copy()
        count = padded.sum(axis=1, dtype=np.int64)
        start = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64)
        return cls(rank, start, int(count.sum()))

    @property
    def mask(self) -> np.ndarray:
        """bool (H * W,): the navigable cells."""
        return self.rank != NOT_NAVIGABLE

    def entry(self, flat: np.ndarray) -> np.ndarray:
        """int64: the compact-field entry of each flat cell index, -1 where the cell is not navigable."""
        r = self.rank[flat]
        return np.where(r != NOT_NAVIGABLE, self.start[flat // CHUNK] + r, -1)


def cell_index(world: NavWorld) -> CellIndex:
    """The world's :class:`CellIndex` of navigable cells (cached in ``world.cache``)."""
    key = ("cells",)
    if key not in world.cache:
        world.cache[key] = CellIndex.from_mask(navigable(world))
    return world.cache[key]


def compact_field(world: NavWorld, target_type: str) -> np.ndarray:
    """float32 (cells,): the distance field on the navigable cells, in :func:`cell_index` order (cached).

    This is what ``world.cache`` keeps; :func:`distance_field` expands it to the grid.
    """
    key = ("distance", target_type)
    if key not in world.cache:
        index = cell_index(world)
        region = success_region(world, target_type)
        full = shortest_paths(navigable(world), region, world.grid.resolution)[0]
        world.cache[key] = np.ascontiguousarray(full.reshape(-1)[index.mask])
        world.cache.pop(("region", target_type), None)  # now derived from the field: saves H*W bytes
    return world.cache[key]


def _expand(world: NavWorld, values: np.ndarray, fill) -> np.ndarray:
    """A per-navigable-cell array spread over the grid (H, W), ``fill`` elsewhere."""
    out = np.full(world.grid.shape, fill, dtype=values.dtype)
    out.reshape(-1)[cell_index(world).mask] = values
    return out


def distance_field(world: NavWorld, target_type: str) -> np.ndarray:
    """float32 (H, W): geodesic distance (m) to the success region; 0 inside, inf where unreachable.

    Expanded from :func:`compact_field`; while a caller holds the array, later calls return that same
    array (a weak reference in ``world.cache``, which holds no memory), so it is not rebuilt.
    """
    key = ("distance_grid", target_type)
    ref = world.cache.get(key)
    full = ref() if ref is not None else None
    if full is None:
        full = _expand(world, compact_field(world, target_type), np.float32(np.inf))
        world.cache[key] = weakref.ref(full)
    return full


def field_at(world: NavWorld, field: np.ndarray, x, z) -> np.ndarray:
    """Read a per-cell field at world points (vectorized).

    A point whose own cell is infinite (not navigable or unreachable) takes the minimum over its
    3x3 neighbourhood of field + distance to that cell's centre, so a continuous agent standing
    on a cell edge never reads inf; points with no finite neighbour read inf.
    """
    return _read_at(world, lambda r, c: field[r, c], x, z)


def _read_at(world: NavWorld, read, x, z) -> np.ndarray:
    """:func:`field_at` with the field given as ``read(rows, cols)`` (in-bounds cells -> values)."""
    g = world.grid
    x, z = np.asarray(x, dtype=float), np.asarray(z, dtype=float)
    row, col = g.to_cell(x, z)
    h, w = g.shape
    inside = g.in_bounds(row, col)
    out = np.full(np.shape(row), np.inf, dtype=np.float64)
    out[inside] = read(row[inside], col[inside])
    bad = ~np.isfinite(out)
    if bad.any():
        rb, cb, xb, zb = row[bad], col[bad], x[bad], z[bad]
        best = np.full(rb.shape, np.inf)
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                rr, cc = rb + dr, cb + dc
                ok = (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w)
                val = np.full(rb.shape, np.inf)
                val[ok] = read(rr[ok], cc[ok])
                cx, cz = g.cell_center(rr, cc)
                best = np.minimum(best, val + np.hypot(cx - xb, cz - zb))
        out[bad] = best
    return out


def geodesic_distance(world: NavWorld, target_type: str, x, z):
    """Geodesic distance (m) from world points to the target's success region (float for scalars).

    Reads the compact field directly (no grid-sized array per call), with :func:`field_at`'s rule.
    """
    values, index, w = compact_field(world, target_type), cell_index(world), world.grid.shape[1]

    def read(r: np.ndarray, c: np.ndarray) -> np.ndarray:
        e = index.entry(np.asarray(r, dtype=np.int64) * w + c)
        return np.where(e >= 0, values[np.maximum(e, 0)], np.float32(np.inf)) if values.size else \
            np.full(e.shape, np.inf, dtype=np.float32)

    out = _read_at(world, read, x, z)
    return float(out) if out.ndim == 0 else out


def optimal_path_length(world: NavWorld, episode: Episode) -> float:
    """The SPL denominator: geodesic distance from the start to the success region (inf if unsolvable)."""
    return float(geodesic_distance(world, episode.target_type, episode.start[0], episode.start[1]))


def is_solvable(world: NavWorld, episode: Episode) -> bool:
    """Whether the success region can be reached from the episode's start."""
    return math.isfinite(optimal_path_length(world, episode))
