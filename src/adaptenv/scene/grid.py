"""The paper's normalized 100x100 grid: one uniform mapping between house meters and grid units.

The house's bounding box (over room floor polygons) is scaled uniformly so that its longer side
spans 0..100; the shorter side spans 0..100 * short/long. Grid x grows with world +x ("right" on
the map) and grid y with world +z ("up" on the map); (0, 0) is the house's (min x, min z) corner.
Every grid coordinate in adaptenv (renders, prompts, analyses, edits) goes through this class.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

GRID_SIZE = 100.0


@dataclass(frozen=True)
class NormalizedGrid:
    """Uniform map between world (x, z) in meters and normalized grid (gx, gy) in 0..100."""

    min_x: float
    min_z: float
    extent: float
    """Length in meters of the house's longer side (what 100 grid units stand for)."""

    @classmethod
    def from_bounds(cls, min_x: float, min_z: float, max_x: float, max_z: float) -> NormalizedGrid:
        extent = max(max_x - min_x, max_z - min_z)
        if extent <= 0:
            raise ValueError("the house bounds are empty; a house needs at least one room with area")
        return cls(float(min_x), float(min_z), float(extent))

    @classmethod
    def for_house(cls, house) -> NormalizedGrid:
        """The grid of a :class:`~adaptenv.scene.house.House` (bounds of its room polygons)."""
        xs = [p.x for r in house.rooms for p in r.floorPolygon]
        zs = [p.z for r in house.rooms for p in r.floorPolygon]
        return cls.from_bounds(min(xs), min(zs), max(xs), max(zs))

    @property
    def units_per_meter(self) -> float:
        return GRID_SIZE / self.extent

    def to_grid(self, x: ArrayLike, z: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """World (x, z) meters -> grid (gx, gy) units."""
        s = self.units_per_meter
        return (np.asarray(x, dtype=float) - self.min_x) * s, (np.asarray(z, dtype=float) - self.min_z) * s

    def to_world(self, gx: ArrayLike, gy: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Grid (gx, gy) units -> world (x, z) meters."""
        m = 1.0 / self.units_per_meter
        return np.asarray(gx, dtype=float) * m + self.min_x, np.asarray(gy, dtype=float) * m + self.min_z

    def units_to_meters(self, units: ArrayLike) -> np.ndarray:
        """A length or displacement in grid units -> meters."""
        return np.asarray(units, dtype=float) / self.units_per_meter

    def meters_to_units(self, meters: ArrayLike) -> np.ndarray:
        """A length or displacement in meters -> grid units."""
        return np.asarray(meters, dtype=float) * self.units_per_meter

    def point(self, x: float, z: float) -> tuple[float, float]:
        """Scalar convenience: world point -> (gx, gy) as plain floats."""
        gx, gy = self.to_grid(x, z)
        return float(gx), float(gy)
