"""Where a top-down map's drawing goes: the world-to-pixel transform and the image's layout.

:mod:`adaptenv.render.topdown` computes both and draws; :mod:`adaptenv.render.labels` places labels with them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from adaptenv.scene.grid import NormalizedGrid


@dataclass(frozen=True)
class MapTransform:
    """World (x, z) meters -> image pixels with one uniform scale; +x is right, +z is up.

    World (grid.min_x, grid.min_z), the grid's (0, 0), lands on ``origin``: the bottom-left
    corner of the drawing area.
    """

    grid: NormalizedGrid
    scale: float
    """Pixels per meter."""
    origin: tuple[float, float]
    size_m: tuple[float, float]
    """World width (x) and height (z) of the drawing area, m."""

    def to_px(self, x, z) -> tuple[np.ndarray, np.ndarray]:
        """World (x, z) -> pixel (px, py); arrays in, arrays out."""
        px = self.origin[0] + (np.asarray(x, dtype=float) - self.grid.min_x) * self.scale
        py = self.origin[1] - (np.asarray(z, dtype=float) - self.grid.min_z) * self.scale
        return px, py

    def point(self, x: float, z: float) -> tuple[float, float]:
        """Scalar world point -> pixel."""
        return (self.origin[0] + (float(x) - self.grid.min_x) * self.scale,
                self.origin[1] - (float(z) - self.grid.min_z) * self.scale)

    def grid_to_px(self, gx, gy) -> tuple[np.ndarray, np.ndarray]:
        """Normalized grid (gx, gy) -> pixel, through the same NormalizedGrid mapping."""
        return self.to_px(*self.grid.to_world(gx, gy))

    def to_world(self, px, py) -> tuple[np.ndarray, np.ndarray]:
        """Pixel -> world (x, z)."""
        x = (np.asarray(px, dtype=float) - self.origin[0]) / self.scale + self.grid.min_x
        z = (self.origin[1] - np.asarray(py, dtype=float)) / self.scale + self.grid.min_z
        return x, z

    @property
    def area(self) -> tuple[float, float, float, float]:
        """Pixel box (left, top, right, bottom) of the house's bounding box."""
        left, bottom = self.origin
        return left, bottom - self.size_m[1] * self.scale, left + self.size_m[0] * self.scale, bottom


@dataclass(frozen=True)
class MapLayout:
    """Image size, margins and fonts of one render; both the drawing and tests use it."""

    width: int
    height: int
    transform: MapTransform
    font_size: int
    """Base font size (px): tick labels, captions and room names."""
    label_size: int
    """Font size of object id labels."""
    caption_top: float
    header_bottom: float
    """Lowest pixel row of the caption lines; labels stay below it."""
    legend_top: float
    legend_rows: list[list[str]]
    text_left: float = 0.0
    """Left edge of the caption lines: the map's left margin (the map itself is centred in a widened panel)."""
