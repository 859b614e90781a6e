"""A house compiled for simulation: occupancy raster, semantic and occluder grids, target instances.

``compile_world(house)`` does all per-house work once; stepping, scanning, success checks and
distance fields then only read these arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, is_dataclass

import numpy as np

from adaptenv.scene.geometry import Footprint, SceneGeometry
from adaptenv.scene.house import House
from adaptenv.scene.occupancy import (
    DEFAULT_RESOLUTION,
    LABEL_DOOR,
    LABEL_OBJECT0,
    LABEL_OUTSIDE,
    LABEL_WALL,
    LABEL_WINDOW,
    OccupancyGrid,
    rasterize,
)
from adaptenv.sim.spec import CLASS_DOOR, CLASS_NONE, CLASS_WALL, CLASS_WINDOW, class_id


@dataclass(frozen=True)
class TargetInstance:
    """One object the agent may be sent to find."""

    object_id: str
    object_type: str
    center: tuple[float, float]
    corners: np.ndarray
    """Footprint corners (4, 2) in (x, z)."""
    label: int
    """Its label in the occupancy grid (LABEL_OBJECT0 + index)."""


@dataclass
class NavWorld:
    """Everything the simulator needs about one house, as arrays."""

    name: str
    geometry: SceneGeometry
    grid: OccupancyGrid
    semantic: np.ndarray
    """int16 (H, W): semantic class (``spec`` class ids) of the obstacle nearest to each cell."""
    occluder: np.ndarray
    """bool (H, W): cells that block line of sight (walls, closed doors, windows, outside, tall furniture)."""
    instances: list[TargetInstance]
    start: tuple[float, float, float] | None
    """Start pose (x, z, yaw) from the house metadata, if any."""
    cache: dict = field(default_factory=dict)
    """Per-world memo for derived arrays (e.g. distance fields by target type)."""
    task_targets: tuple[str, ...] = ()
    """Target types that training episodes drawn in this world ask for (empty: every available type); the
    closed loop sets it to the type its edits aimed at (``LoopConfig.focus_training``)."""

    def instances_of(self, object_type: str) -> list[TargetInstance]:
        return [t for t in self.instances if t.object_type == object_type]

    @property
    def object_types(self) -> list[str]:
        """Types of floor objects present, sorted."""
        return sorted({t.object_type for t in self.instances})

    @property
    def nbytes(self) -> int:
        """Memory held by the world's arrays (grid, semantic, occluder and cached fields), each array once."""
        cached = sum({id(a): a.nbytes for a in self.cached_arrays()}.values())
        return self.grid.nbytes + self.semantic.nbytes + self.occluder.nbytes + cached

    def cached_arrays(self) -> list[np.ndarray]:
        """The NumPy arrays in ``cache``, including those inside cached dataclasses, lists and tuples
        (e.g. target points, the expert's guidance fields); weak references hold none."""
        out: list[np.ndarray] = []
        for value in self.cache.values():
            _collect_arrays(value, out)
        return out


def _collect_arrays(value, out: list[np.ndarray]) -> None:
    """Append the NumPy arrays of a cache entry (an array, a dataclass or a sequence of them) to ``out``."""
    if isinstance(value, np.ndarray):
        out.append(value)
    elif is_dataclass(value) and not isinstance(value, type):
        for f in fields(value):
            _collect_arrays(getattr(value, f.name), out)
    elif isinstance(value, (list, tuple)):
        for v in value:
            _collect_arrays(v, out)


def occluding_labels(floor: list[Footprint]) -> np.ndarray:
    """Which occupancy labels block sight, indexed by label: ``occluding_labels(floor)[grid.label]``
    is the occluder grid.

    Outside, walls, doors and windows block it, a floor object when it is tall enough
    (``Footprint.occludes``), a free cell never: bool (LABEL_OBJECT0 + len(floor) + 1,), whose last
    entry is LABEL_FREE's (-1).
    """
    tall = np.zeros(LABEL_OBJECT0 + len(floor) + 1, dtype=bool)
    tall[[LABEL_OUTSIDE, LABEL_WALL, LABEL_DOOR, LABEL_WINDOW]] = True
    tall[LABEL_OBJECT0:LABEL_OBJECT0 + len(floor)] = [fp.occludes for fp in floor]
    return tall


def compile_world(house: House, name: str = "house", resolution: float = DEFAULT_RESOLUTION,
                  geometry: SceneGeometry | None = None) -> NavWorld:
    """Rasterize a house and derive the semantic and occluder grids and the target instances."""
    geometry = geometry or SceneGeometry.from_house(house)
    grid = rasterize(geometry, resolution)
    floor = geometry.floor_objects

    lut = np.full(LABEL_OBJECT0 + len(floor), CLASS_NONE, dtype=np.int16)
    lut[LABEL_OUTSIDE] = CLASS_WALL
    lut[LABEL_WALL] = CLASS_WALL
    lut[LABEL_DOOR] = CLASS_DOOR
    lut[LABEL_WINDOW] = CLASS_WINDOW
    for k, fp in enumerate(floor):
        lut[LABEL_OBJECT0 + k] = class_id(fp.object_type)
    # nearest_label is never LABEL_FREE (-1) while any obstacle exists; guard anyway.
    semantic = np.where(grid.nearest_label >= 0, lut[np.maximum(grid.nearest_label, 0)], CLASS_NONE).astype(np.int16)

    occluder = occluding_labels(floor)[grid.label]

    instances = [TargetInstance(fp.object_id, fp.object_type, fp.center, fp.corners, LABEL_OBJECT0 + k)
                 for k, fp in enumerate(floor)]
    return NavWorld(name, geometry, grid, semantic, occluder, instances, house.agent_pose())
