"""What the agent perceives of the objects its rays hit: their class (``labels``) or only their shape (``shape``).

Two perception modes share one simulator:

- ``labels`` (the original mode): each ray reports the semantic class of what it hits, so the agent is
  told which object is a fridge.
- ``shape`` (the recognising mode): each ray reports what a depth or RGB-D sensor can measure of the
  object it hits, and not its class. The agent still gets the target type by name and must learn,
  from the homes it trains in, which shapes are that type.

The shape features (``SHAPE_FEATURES``, metres, 0 on rays that hit no object) are the hit object's
**height** (its top above the floor: the highest point of its segment in a depth image) and the
**long and short sides of its footprint** (the horizontal extent of its segment, seen from enough
sides, as a 3-D bounding box fitted to the point cloud gives it). These are the catalog's sizes of
each asset (ProcTHOR's ``boundingBox``), so two assets of one type differ as they do in the
catalog, and an unseen asset of a type is a new shape. Walls, doors and windows keep their classes:
a sensor tells a wall from furniture by its geometry (planar, floor to ceiling).

In the shape mode nothing of the class reaches the network: objects read as one generic class
(``CLASS_OBJECT``), the flag "this ray hits the target type" is zero, and the target bits of the map
memory (``sim.egomap``) are cleared. Teachers keep the labelled observation: the map explorer marks
its own map from the classes, as a teacher may.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from adaptenv.errors import ConfigError
from adaptenv.scene.occupancy import LABEL_OBJECT0
from adaptenv.sim.egomap import TARGET
from adaptenv.sim.scan import RAY_COS, RAY_SIN
from adaptenv.sim.spec import MAX_RANGE, N_RAYS

PERCEPTIONS: tuple[str, ...] = ("labels", "shape")
SHAPE_FEATURES = ("height", "long_side", "short_side")
"""Per-ray shape features of the recognising mode, metres (0 where the ray hits no object)."""
N_SHAPE = len(SHAPE_FEATURES)
SHAPE_MAX = 100.0
"""Bound of a shape feature in the Gymnasium observation space (m; the catalog's largest side is 3.07 m)."""
CLASS_OBJECT = 4
"""The one class every object reads as in the shape mode (the first object class id; walls, doors and windows
keep 1-3)."""
MAP_TARGET_MASK = 0xFF & ~(TARGET | TARGET << 4)
"""AND-mask that clears the target bits of a packed map crop (fine bit 2, coarse bit 6)."""
_SHAPES_KEY = ("perception", "object_shapes")


def check_perception(value: str, flag: str = "--perception") -> str:
    """``value`` when it names a perception mode, else one ConfigError naming ``flag`` and the choices."""
    if value not in PERCEPTIONS:
        raise ConfigError(f"{flag} {value!r} is unknown; use one of {', '.join(PERCEPTIONS)}")
    return value


def object_shapes(world) -> np.ndarray:
    """float32 (n_floor_objects, N_SHAPE): height, long and short footprint side of each floor object (cached)."""
    table = world.cache.get(_SHAPES_KEY)
    if table is None:
        floor = world.geometry.floor_objects
        table = np.zeros((len(floor), N_SHAPE), dtype=np.float32)
        for k, fp in enumerate(floor):
            table[k] = (fp.height, max(fp.size), min(fp.size))
        world.cache[_SHAPES_KEY] = table
    return table


@dataclass(frozen=True)
class PackedShapes:
    """The cell labels and object shapes of several worlds, aligned with ``physics.PackedGrids``."""

    labels: np.ndarray
    """int16, every world's ``grid.label`` raster flattened and concatenated in world order."""
    table: np.ndarray
    """float32 (n, N_SHAPE): every world's :func:`object_shapes`, concatenated."""
    table_offset: np.ndarray
    """int64 (E,): each world's first row of ``table``."""

    @classmethod
    def from_worlds(cls, worlds) -> PackedShapes:
        tables = [object_shapes(w) for w in worlds]
        sizes = np.array([len(t) for t in tables], dtype=np.int64)
        labels = (np.ascontiguousarray(worlds[0].grid.label, dtype=np.int16).reshape(-1) if len(worlds) == 1 else
                  np.concatenate([np.asarray(w.grid.label, dtype=np.int16).ravel() for w in worlds]))
        table = np.concatenate(tables) if tables else np.zeros((0, N_SHAPE), np.float32)
        return cls(labels, np.ascontiguousarray(table.reshape(-1, N_SHAPE)),
                   np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64))


@numba.njit(cache=True)
def _ray_shapes(labels, table, toffs, offs, hs, ws, x0s, z0s, ress, env, x, z, yaw, depth, ray_cos, ray_sin,
                max_range, out):
    """Fill ``out`` (B, N_RAYS, N_SHAPE) with the shape of the object each ray stops in (0 elsewhere).

    The ray's end is ``depth * max_range`` along its direction; half a hundredth of a cell further it
    lies inside the cell the scan stopped in, whose label names the object."""
    for i in range(x.shape[0]):
        e = env[i]
        a = np.radians(yaw[i])
        sy, cy = np.sin(a), np.cos(a)
        res = ress[e]
        for r in range(ray_cos.shape[0]):
            for f in range(out.shape[2]):
                out[i, r, f] = 0.0
            if depth[i, r] >= 1.0:
                continue
            du = sy * ray_cos[r] + cy * ray_sin[r]
            dv = cy * ray_cos[r] - sy * ray_sin[r]
            t = depth[i, r] * max_range + 0.005 * res
            col = int(np.floor((x[i] + t * du - x0s[e]) / res))
            row = int(np.floor((z[i] + t * dv - z0s[e]) / res))
            if row < 0 or col < 0 or row >= hs[e] or col >= ws[e]:
                continue
            k = np.int64(labels[offs[e] + row * ws[e] + col]) - LABEL_OBJECT0
            if k < 0:
                continue
            for f in range(out.shape[2]):
                out[i, r, f] = table[toffs[e] + k, f]


def ray_shapes(shapes: PackedShapes, grids, env: np.ndarray, x: np.ndarray, z: np.ndarray, yaw: np.ndarray,
               depth: np.ndarray, max_range: float = MAX_RANGE) -> np.ndarray:
    """float32 (B, N_RAYS, N_SHAPE): the shape features of what each agent's rays hit (see the module docstring).

    ``grids`` is the ``PackedGrids`` of the same worlds as ``shapes``; ``depth`` the scan's normalized depth."""
    out = np.empty((len(x), N_RAYS, N_SHAPE), dtype=np.float32)
    _ray_shapes(shapes.labels, shapes.table, shapes.table_offset, grids.offset, grids.height, grids.width,
                grids.x0, grids.z0, grids.resolution, np.asarray(env, np.int64), np.asarray(x, np.float64),
                np.asarray(z, np.float64), np.asarray(yaw, np.float64), np.asarray(depth, np.float32), RAY_COS,
                RAY_SIN, float(max_range), out)
    return out


def sensor_classes(semantic: np.ndarray) -> np.ndarray:
    """The classes the shape mode reports: walls, doors and windows as they are, every object as ``CLASS_OBJECT``."""
    return np.minimum(np.asarray(semantic), CLASS_OBJECT)
