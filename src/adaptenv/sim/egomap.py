"""A map memory the agent builds itself: a top-down grid from its own scans and dead-reckoned pose.

Nothing privileged goes in. Each agent's map lives in the frame of its episode's start (origin at
the start position, the start heading as "forward"), and its pose in that frame is integrated from
its own actions: ``prev_action`` and ``collided`` of each observation say how the pose changed (a
0.2 m move unless the move was blocked; a 30 or 6 degree turn always). This is exact in this
simulator, whose moves either happen in full or not at all.

Every step the scan marks the map, one bit per channel in a ``uint8`` per cell:

- ``FREE`` (bit 0): a ray passed through the cell (sampled every half cell up to the hit);
- ``OBSTACLE`` (bit 1): a ray stopped in the cell, or a blocked move bumped into it;
- ``TARGET`` (bit 2): a ray whose semantic class is the target type stopped in the cell;
- ``VISITED`` (bit 3): the agent stood in the cell.

Rays are densified like the explorer's (``INTERPOLATE`` rays between neighbours at the smaller of
the two depths) so that the fan leaves no gaps at range. A coarse copy (each cell the OR of
``COARSE`` x ``COARSE`` fine cells) is kept alongside for the wide view.

The observation :meth:`EgoMap.crop` is egocentric: two ``CROP`` x ``CROP`` windows rotated to the
heading (agent at the centre, facing up, row 0 ahead), the fine one (``CELL`` m cells, 6.4 m across by
default) and the coarse one (``CELL * COARSE`` m cells, 25.6 m across), packed as 8 bits per pixel:
bits 0-3 the fine window's channels, bits 4-7 the coarse window's. :func:`unpack` spreads them to
(..., 8, CROP, CROP) 0/1 values (float32, or any dtype asked for). ``NavEnv(map=True)`` and
``NavVectorEnv(map=True)`` (``adaptenv.sim.env``) keep an EgoMap and return the unpacked crop as ``obs["map"]``.

Example::

    emap = EgoMap(batch=len(episodes))
    obs, _ = sim.reset(episodes)
    emap.update(obs, first=np.ones(len(episodes), bool))
    packed = emap.crop()             # uint8 (B, 32, 32)
    channels = unpack(packed)        # float32 (B, 8, 32, 32)
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import DTypeLike

from adaptenv.sim.scan import RAY_OFFSETS_DEG
from adaptenv.sim.spec import (
    AGENT_RADIUS,
    MAX_RANGE,
    MOVE_DELTA,
    N_ACTIONS,
    NO_ACTION,
    YAW_DELTA,
)

FREE, OBSTACLE, TARGET, VISITED = 1, 2, 4, 8
"""Channel bits of a map cell."""
SEEN = FREE | OBSTACLE
"""A cell with either bit has been seen (:meth:`EgoMap.seen_counts`)."""
CHANNELS = ("free", "obstacle", "target", "visited")
N_CHANNELS = len(CHANNELS)
CELL = 0.2
"""Side of a fine map cell (m): one move."""
SIZE = 192
"""Cells on a side of an agent's whole map (38.4 m: larger than any house it starts in, start in the centre)."""
COARSE = 4
"""Fine cells per coarse cell on a side."""
CROP = 32
"""Pixels on a side of each egocentric window."""
INTERPOLATE = 2
"""Rays interpolated between neighbouring scan rays when marking."""
MAP_CHANNELS = 2 * N_CHANNELS
"""Channels of the unpacked observation: the fine window's four, then the coarse window's four."""

_YAW = np.asarray(YAW_DELTA + (0.0,), dtype=np.float64)  # NO_ACTION changes nothing
_MOVE = np.asarray(MOVE_DELTA + (0.0,), dtype=np.float64)
_OFFSETS = np.ascontiguousarray(RAY_OFFSETS_DEG, dtype=np.float64)
_BUMP = AGENT_RADIUS + 0.5 * CELL
"""Distance ahead (m) of the cell a blocked move marks as an obstacle."""


@numba.njit(cache=True, inline="always")
def _mark_cell(grid, coarse, seen, i, row, col, bits, f):
    """OR ``bits`` into agent i's cell (row, col) (ignored outside the map); count it in ``seen[i]`` when it gets its
    first FREE or OBSTACLE bit. A cell that holds ``bits`` already is left alone: its coarse cell holds them too."""
    n = grid.shape[1]
    if 0 <= row < n and 0 <= col < n:
        old = grid[i, row, col]
        if old & bits == bits:
            return
        if old & SEEN == 0 and bits & SEEN != 0:
            seen[i] += 1
        grid[i, row, col] = old | bits
        coarse[i, row // f, col // f] |= bits


@numba.njit(cache=True, inline="always")
def _mark(grid, coarse, seen, i, x, z, bits, cell, f):
    """:func:`_mark_cell` of the cell holding map-frame point (x, z) of agent i."""
    n = grid.shape[1]
    _mark_cell(grid, coarse, seen, i, int(math.floor(z / cell)) + n // 2, int(math.floor(x / cell)) + n // 2, bits, f)


@numba.njit(cache=True, parallel=True)
def _update(grid, coarse, seen, pose, first, prev_action, collided, depth, sem, target, offsets, yaw_delta, move_delta,
            max_range, n_interp, cell, f, bump):
    """Integrate each agent's pose from its last action, then mark its scan (see the module docstring)."""
    b = grid.shape[0]
    n = grid.shape[1]
    n_rays = offsets.shape[0]
    for i in numba.prange(b):  # agents are independent: each writes only its own rows
        a = prev_action[i]
        if first[i]:
            grid[i, :, :] = 0
            coarse[i, :, :] = 0
            seen[i] = 0
            pose[i, 0] = 0.0
            pose[i, 1] = 0.0
            pose[i, 2] = 0.0
        else:
            d = move_delta[a]
            if d != 0.0:
                t = math.radians(pose[i, 2])
                if collided[i]:
                    s = 1.0 if d > 0 else -1.0
                    _mark(grid, coarse, seen, i, pose[i, 0] + s * bump * math.sin(t), pose[i, 1] + s * bump * math.cos(t),
                          OBSTACLE, cell, f)
                else:
                    pose[i, 0] += d * math.sin(t)
                    pose[i, 1] += d * math.cos(t)
            pose[i, 2] = (pose[i, 2] + yaw_delta[a]) % 360.0
        x, z, yaw = pose[i, 0], pose[i, 1], pose[i, 2]
        _mark(grid, coarse, seen, i, x, z, VISITED | FREE, cell, f)
        for k in range(n_rays):
            for s in range(n_interp + 1 if k < n_rays - 1 else 1):
                if s == 0:
                    dd, off, cls = depth[i, k], offsets[k], sem[i, k]
                else:
                    fr = s / (n_interp + 1)
                    dd = min(depth[i, k], depth[i, k + 1])
                    off = offsets[k] + fr * (offsets[k + 1] - offsets[k])
                    cls = sem[i, k] if sem[i, k] == sem[i, k + 1] else -1
                t = math.radians(yaw + off)
                ux, uz = math.sin(t), math.cos(t)
                steps = int(dd / (0.5 * cell))
                last_row, last_col = -1, -1  # samples are half a cell apart: skip the one that repeats a cell
                for j in range(steps + 1):
                    r = j * 0.5 * cell
                    row = int(math.floor((z + r * uz) / cell)) + n // 2
                    col = int(math.floor((x + r * ux) / cell)) + n // 2
                    if row != last_row or col != last_col:
                        _mark_cell(grid, coarse, seen, i, row, col, FREE, f)
                        last_row, last_col = row, col
                if dd < max_range - 1e-6:
                    r = dd + 0.25 * cell
                    bits = OBSTACLE | TARGET if cls == target[i] else OBSTACLE
                    _mark(grid, coarse, seen, i, x + r * ux, z + r * uz, bits, cell, f)


@numba.njit(cache=True, parallel=True)
def _crop(grid, coarse, pose, out, crop, cell, f):
    """Egocentric windows of every agent, rotated to its heading, packed 8 bits per pixel into ``out``."""
    b = grid.shape[0]
    n = grid.shape[1]
    nc = coarse.shape[1]
    half = crop / 2.0
    for i in numba.prange(b):
        x, z = pose[i, 0], pose[i, 1]
        t = math.radians(pose[i, 2])
        fx, fz = math.sin(t), math.cos(t)  # forward
        rx, rz = math.cos(t), -math.sin(t)  # right (yaw + 90 degrees)
        for r in range(crop):
            ahead = half - r - 0.5
            for q in range(crop):
                right = q - half + 0.5
                # fine window
                px = x + (ahead * fx + right * rx) * cell
                pz = z + (ahead * fz + right * rz) * cell
                col = int(math.floor(px / cell)) + n // 2
                row = int(math.floor(pz / cell)) + n // 2
                v = 0
                if 0 <= row < n and 0 <= col < n:
                    v = grid[i, row, col] & 15
                # coarse window
                ccell = cell * f
                px = x + (ahead * fx + right * rx) * ccell
                pz = z + (ahead * fz + right * rz) * ccell
                col = int(math.floor(px / ccell)) + nc // 2
                row = int(math.floor(pz / ccell)) + nc // 2
                if 0 <= row < nc and 0 <= col < nc:
                    v |= (coarse[i, row, col] & 15) << 4
                out[i, r, q] = v


class EgoMap:
    """The map memory of ``batch`` agents (see the module docstring); numpy state, compiled kernels.

    ``grid`` (B, SIZE, SIZE) and ``coarse`` (B, SIZE / COARSE, SIZE / COARSE) hold the channel bits;
    ``pose`` (B, 3) is each agent's integrated (x, z, yaw) in its start frame (m, m, degrees); ``seen`` (B,) counts
    each agent's fine cells with a ``SEEN`` bit, kept by the kernel as it marks.
    """

    def __init__(self, batch: int, *, size: int = SIZE, crop: int = CROP, cell: float = CELL, coarse: int = COARSE):
        if size % (2 * coarse):
            raise ValueError(f"size ({size}) must be a multiple of 2 * coarse ({2 * coarse}), so that the coarse "
                             "grid's centre is the fine grid's; pick such a size")
        self.size, self.crop_size, self.cell, self.coarse_factor = int(size), int(crop), float(cell), int(coarse)
        self.grid = np.zeros((batch, size, size), dtype=np.uint8)
        self.coarse = np.zeros((batch, size // coarse, size // coarse), dtype=np.uint8)
        self.pose = np.zeros((batch, 3), dtype=np.float64)
        self.seen = np.zeros(batch, dtype=np.int64)

    @property
    def batch(self) -> int:
        return self.grid.shape[0]

    def update(self, obs: dict[str, np.ndarray], first: np.ndarray) -> None:
        """Move each agent by its last action (a fresh map where ``first`` or prev_action is none), then mark its scan."""
        b = self.batch
        prev = np.asarray(obs["prev_action"], dtype=np.int64).reshape(b)
        if prev.size and (prev.min() < 0 or prev.max() > N_ACTIONS):
            raise ValueError(f"prev_action must be in [0, {N_ACTIONS}], got {prev.min()}..{prev.max()}")
        first = np.asarray(first, dtype=np.bool_).reshape(b) | (prev == NO_ACTION)
        _update(self.grid, self.coarse, self.seen, self.pose, first, prev,
                np.asarray(obs["collided"], dtype=np.int64).reshape(b),
                np.ascontiguousarray(obs["depth"], dtype=np.float64).reshape(b, -1) * MAX_RANGE,
                np.ascontiguousarray(obs["semantic"], dtype=np.int64).reshape(b, -1),
                np.asarray(obs["target"], dtype=np.int64).reshape(b), _OFFSETS, _YAW, _MOVE, MAX_RANGE,
                INTERPOLATE, self.cell, self.coarse_factor, _BUMP)

    def reset(self, indices: np.ndarray) -> None:
        """Forget agents ``indices``: empty maps, the current pose becomes the origin (the memory-wipe check)."""
        idx = np.asarray(indices, dtype=np.int64).reshape(-1)
        self.grid[idx] = 0
        self.coarse[idx] = 0
        self.seen[idx] = 0
        self.pose[idx] = 0.0

    def seen_counts(self) -> np.ndarray:
        """int64 (B,): fine cells each agent has seen (FREE or OBSTACLE set) since its map started; a copy."""
        return self.seen.copy()

    def crop(self, out: np.ndarray | None = None) -> np.ndarray:
        """uint8 (B, CROP, CROP): the egocentric windows, packed (bits 0-3 fine, 4-7 coarse)."""
        if out is None:
            out = np.empty((self.batch, self.crop_size, self.crop_size), dtype=np.uint8)
        _crop(self.grid, self.coarse, self.pose, out, self.crop_size, self.cell, self.coarse_factor)
        return out

    def take(self, indices: np.ndarray) -> EgoMap:
        """A copy holding only agents ``indices`` (same settings)."""
        idx = np.asarray(indices, dtype=np.int64).reshape(-1)
        other = EgoMap(0, size=self.size, crop=self.crop_size, cell=self.cell, coarse=self.coarse_factor)
        other.grid, other.coarse, other.pose = self.grid[idx].copy(), self.coarse[idx].copy(), self.pose[idx].copy()
        other.seen = self.seen[idx].copy()
        return other

    def to_world(self, i: int, start: tuple[float, float, float]) -> np.ndarray:
        """World (x, z) of the centres of agent i's fine cells, (SIZE, SIZE, 2), given its true start pose.

        For checks and drawings only: the agent itself never knows ``start``.
        """
        n = self.size
        c = (np.arange(n) - n // 2 + 0.5) * self.cell
        mx, mz = np.meshgrid(c, c)  # map frame: column -> x, row -> z
        t = math.radians(start[2])
        wx = start[0] + mx * math.cos(t) + mz * math.sin(t)
        wz = start[1] - mx * math.sin(t) + mz * math.cos(t)
        return np.stack([wx, wz], axis=-1)


def unpack(packed: np.ndarray, dtype: DTypeLike = np.float32) -> np.ndarray:
    """0/1 values of ``dtype`` (float32 by default), (..., MAP_CHANNELS, CROP, CROP), from packed crops (..., CROP, CROP)."""
    bits = (packed[..., None, :, :] >> np.arange(MAP_CHANNELS, dtype=np.uint8)[:, None, None]) & 1
    return bits.astype(dtype, copy=False)


__all__ = ["CELL", "CHANNELS", "COARSE", "CROP", "EgoMap", "FREE", "MAP_CHANNELS", "N_CHANNELS", "OBSTACLE",
           "SEEN", "SIZE", "TARGET", "VISITED", "unpack"]
