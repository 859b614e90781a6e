"""Navigation physics: a disc agent moving and turning on the clearance raster of one or many houses.

A move of ``d`` meters along the heading is checked at sub-steps no longer than half a grid cell;
if the disc does not fit (clearance < radius) at any sub-step, the agent stays where it was and
the move counts as a collision. Because every point within ``radius`` of an obstacle has
clearance below ``radius``, no step length can tunnel through a wall or a thin footprint.
Turns always succeed. Several houses are packed into one flat array so a batch of agents in
different houses steps in one compiled loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from adaptenv.sim.spec import AGENT_RADIUS, MOVE_DELTA, YAW_DELTA

_YAW_DELTA = np.array(YAW_DELTA, dtype=np.float64)
_MOVE_DELTA = np.array(MOVE_DELTA, dtype=np.float64)


@dataclass(frozen=True)
class PackedGrids:
    """Clearance rasters of several houses in one flat float32 array (house k at ``offset[k]``)."""

    clearance: np.ndarray
    offset: np.ndarray
    height: np.ndarray
    width: np.ndarray
    x0: np.ndarray
    z0: np.ndarray
    resolution: np.ndarray

    @classmethod
    def from_worlds(cls, worlds) -> PackedGrids:
        """Pack the ``grid.clearance`` of each NavWorld (or anything with a ``.grid``).

        One world's float32 raster is used in place (a flat view, no copy); several are concatenated.
        """
        grids = [w.grid for w in worlds]
        sizes = [g.clearance.size for g in grids]
        offset = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        if len(grids) == 1:
            clearance = np.ascontiguousarray(grids[0].clearance, dtype=np.float32).reshape(-1)
        else:
            clearance = np.concatenate([g.clearance.ravel() for g in grids]).astype(np.float32)
        return cls(
            clearance,
            offset,
            np.array([g.shape[0] for g in grids], dtype=np.int64),
            np.array([g.shape[1] for g in grids], dtype=np.int64),
            np.array([g.x0 for g in grids], dtype=np.float64),
            np.array([g.z0 for g in grids], dtype=np.float64),
            np.array([g.resolution for g in grids], dtype=np.float64),
        )


@numba.njit(cache=True, inline="always")
def _clearance(clear, off, h, w, x0, z0, res, x, z):
    col = int(math.floor((x - x0) / res))
    row = int(math.floor((z - z0) / res))
    if row < 0 or row >= h or col < 0 or col >= w:
        return 0.0
    return clear[off + row * w + col]


@numba.njit(cache=True, inline="always")
def _move_one(clear, off, h, w, x0, z0, res, x, z, yaw, dyaw, d, radius):
    """One agent's action: returns the new (x, z, yaw, moved); a blocked move keeps (x, z)."""
    if d == 0.0:
        return x, z, (yaw + dyaw) % 360.0, True
    t = math.radians(yaw)
    dx, dz = d * math.sin(t), d * math.cos(t)
    n_sub = max(1, int(math.ceil(abs(d) / (0.5 * min(res, radius)))))
    for k in range(1, n_sub + 1):
        f = k / n_sub
        if _clearance(clear, off, h, w, x0, z0, res, x + f * dx, z + f * dz) < radius:
            return x, z, yaw, False
    return x + dx, z + dz, yaw, True


@numba.njit(cache=True)
def _step(clear, offs, hs, ws, x0s, z0s, ress, env, x, z, yaw, actions, radius, yaw_delta, move_delta, moved):
    for i in range(x.shape[0]):
        a = actions[i]
        e = env[i]
        x[i], z[i], yaw[i], moved[i] = _move_one(clear, offs[e], hs[e], ws[e], x0s[e], z0s[e], ress[e],
                                                 x[i], z[i], yaw[i], yaw_delta[a], move_delta[a], radius)


def step_poses(grids: PackedGrids, env: np.ndarray, x: np.ndarray, z: np.ndarray, yaw: np.ndarray,
               actions: np.ndarray, radius: float = AGENT_RADIUS) -> np.ndarray:
    """Apply one action per agent in place (x, z, yaw are float64 arrays); returns ``moved`` (bool).

    ``env[i]`` is the index of agent i's house in ``grids``. ``end`` leaves the pose unchanged and
    reports moved=True; a blocked move leaves it unchanged and reports moved=False.
    """
    moved = np.empty(x.shape[0], dtype=np.bool_)
    _step(grids.clearance, grids.offset, grids.height, grids.width, grids.x0, grids.z0, grids.resolution,
          env.astype(np.int64, copy=False), x, z, yaw, actions.astype(np.int64, copy=False), float(radius),
          _YAW_DELTA, _MOVE_DELTA, moved)
    return moved


def fits(grids: PackedGrids, env: np.ndarray, x: np.ndarray, z: np.ndarray, radius: float = AGENT_RADIUS) -> np.ndarray:
    """Whether the agent disc fits at each (x, z) (clearance >= radius)."""
    out = np.empty(np.shape(x), dtype=np.bool_)
    for i in range(out.shape[0]):
        e = int(env[i])
        c = _clearance(grids.clearance, grids.offset[e], grids.height[e], grids.width[e], grids.x0[e],
                       grids.z0[e], grids.resolution[e], float(x[i]), float(z[i]))
        out[i] = c >= radius
    return out
