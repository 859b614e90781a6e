"""A raster of the floor plan: what blocks, what it is, how far the nearest obstacle is.

The grid is the one navigable-space definition shared by the simulator (collisions, scans,
geodesic distances), the procedural generator and the validation of edits: a disc of radius r
fits at a cell when the cell's clearance is at least r. Cells are ``resolution`` meters square;
row i, column j covers z in [z0 + i*res, z0 + (i+1)*res) and x in [x0 + j*res, ...).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from PIL import Image, ImageDraw
from scipy import ndimage

from adaptenv.scene.geometry import DOOR_FRAME, SceneGeometry

DEFAULT_RESOLUTION = 0.05

#: Cell labels: free space, outside the house, wall, door (frame or closed leaf), window.
LABEL_FREE, LABEL_OUTSIDE, LABEL_WALL, LABEL_DOOR, LABEL_WINDOW = -1, 0, 1, 2, 3
#: Floor object k of ``SceneGeometry.floor_objects`` has label LABEL_OBJECT0 + k.
LABEL_OBJECT0 = 16
_MARGIN_CELLS = 3


@dataclass
class OccupancyGrid:
    """Blocked cells, their labels, distance to the nearest obstacle, and the room of each cell."""

    x0: float
    z0: float
    resolution: float
    blocked: np.ndarray
    """bool (H, W): walls, closed doors, windows, floor furniture and everything outside the rooms."""
    label: np.ndarray
    """int16 (H, W): LABEL_* of each blocked cell, LABEL_FREE elsewhere."""
    nearest_label: np.ndarray
    """int16 (H, W): label of the obstacle nearest to each cell (what a ray ending here hit)."""
    clearance: np.ndarray
    """float32 (H, W): distance (m) from the cell centre to the nearest obstacle; 0 on obstacles."""
    room: np.ndarray
    """int16 (H, W): index into ``room_ids`` of the room containing the cell, -1 outside."""
    room_ids: tuple[str, ...]
    object_ids: tuple[str, ...]
    """Id of floor object k (label LABEL_OBJECT0 + k)."""
    object_types: tuple[str, ...]

    @property
    def shape(self) -> tuple[int, int]:
        return self.blocked.shape

    @property
    def nbytes(self) -> int:
        """Memory held by the arrays."""
        return sum(a.nbytes for a in (self.blocked, self.label, self.nearest_label, self.clearance, self.room))

    def to_cell(self, x, z) -> tuple[np.ndarray, np.ndarray]:
        """World (x, z) -> (row, col) integer cell indices (unclipped)."""
        col = np.floor((np.asarray(x, dtype=float) - self.x0) / self.resolution).astype(np.int64)
        row = np.floor((np.asarray(z, dtype=float) - self.z0) / self.resolution).astype(np.int64)
        return row, col

    def cell_center(self, row, col) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) -> world (x, z) of the cell centre."""
        return (self.x0 + (np.asarray(col) + 0.5) * self.resolution,
                self.z0 + (np.asarray(row) + 0.5) * self.resolution)

    def in_bounds(self, row, col) -> np.ndarray:
        h, w = self.shape
        row, col = np.asarray(row), np.asarray(col)
        return (row >= 0) & (row < h) & (col >= 0) & (col < w)

    def clearance_at(self, x, z) -> np.ndarray:
        """Clearance (m) at world points; 0 outside the grid."""
        row, col = self.to_cell(x, z)
        ok = self.in_bounds(row, col)
        out = np.zeros(np.shape(row), dtype=np.float32)
        out[ok] = self.clearance[row[ok], col[ok]]
        return out

    def navigable(self, radius: float) -> np.ndarray:
        """bool (H, W): cells where a disc of this radius fits."""
        return self.clearance >= radius

    def components(self, radius: float) -> tuple[np.ndarray, int]:
        """Connected regions (4-connected) of navigable cells: (labels, count); label 0 = not navigable."""
        labels, n = ndimage.label(self.navigable(radius))
        return labels, int(n)

    def room_at(self, x: float, z: float) -> str | None:
        row, col = self.to_cell(x, z)
        if not self.in_bounds(row, col):
            return None
        k = int(self.room[row, col])
        return self.room_ids[k] if k >= 0 else None


def _draw_polygon(draw: ImageDraw.ImageDraw, pts, x0: float, z0: float, res: float, value: int) -> None:
    # Pixel (col, row) has its centre at integer coordinates in PIL's frame.
    xy = [((x - x0) / res - 0.5, (z - z0) / res - 0.5) for x, z in pts]
    draw.polygon(xy, fill=value, outline=value)


def _draw_segment(draw: ImageDraw.ImageDraw, a, b, x0: float, z0: float, res: float, value: int) -> None:
    draw.line([((a[0] - x0) / res - 0.5, (a[1] - z0) / res - 0.5), ((b[0] - x0) / res - 0.5, (b[1] - z0) / res - 0.5)],
              fill=value, width=1)


def rasterize(geometry: SceneGeometry, resolution: float = DEFAULT_RESOLUTION) -> OccupancyGrid:
    """Rasterize a scene's floor plan, walls, openings and floor furniture.

    Label images are drawn with PIL in 32-bit integer mode; the clearance comes from an exact
    Euclidean distance transform, reduced by half a cell so it never overstates free space.
    """
    res = float(resolution)
    min_x, min_z, max_x, max_z = geometry.bounds
    x0, z0 = min_x - _MARGIN_CELLS * res, min_z - _MARGIN_CELLS * res
    w = int(np.ceil((max_x - x0) / res)) + _MARGIN_CELLS
    h = int(np.ceil((max_z - z0) / res)) + _MARGIN_CELLS

    room_img = Image.new("I", (w, h), -1)
    room_draw = ImageDraw.Draw(room_img)
    room_ids = tuple(geometry.rooms)
    for k, rid in enumerate(room_ids):
        _draw_polygon(room_draw, list(geometry.rooms[rid].exterior.coords)[:-1], x0, z0, res, k)
    room = np.asarray(room_img, dtype=np.int32).astype(np.int16)

    label_img = Image.new("I", (w, h), LABEL_FREE)
    draw = ImageDraw.Draw(label_img)
    floor = geometry.floor_objects
    for k, fp in enumerate(floor):
        _draw_polygon(draw, fp.outline, x0, z0, res, LABEL_OBJECT0 + k)
    for a, b in geometry.blocking_segments():
        _draw_segment(draw, a, b, x0, z0, res, LABEL_WALL)
    for win in geometry.windows:
        _draw_segment(draw, win.p0, win.p1, x0, z0, res, LABEL_WINDOW)
    frame_img = Image.new("I", (w, h), 0)
    frame_draw = ImageDraw.Draw(frame_img)
    for door in geometry.doors:
        if not door.passable:
            _draw_segment(draw, door.p0, door.p1, x0, z0, res, LABEL_DOOR)
            continue
        p0, p1 = np.array(door.p0), np.array(door.p1)
        u = (p1 - p0) / max(np.linalg.norm(p1 - p0), 1e-12)
        _draw_segment(frame_draw, p0 - DOOR_FRAME * u, p0, x0, z0, res, 1)
        _draw_segment(frame_draw, p1, p1 + DOOR_FRAME * u, x0, z0, res, 1)
    label = np.asarray(label_img, dtype=np.int32).astype(np.int16)
    # Door frames relabel wall cells only; they never block anything new.
    label[(np.asarray(frame_img) > 0) & (label == LABEL_WALL)] = LABEL_DOOR
    label[(room < 0) & (label == LABEL_FREE)] = LABEL_OUTSIDE

    blocked = label != LABEL_FREE
    dist, (ri, ci) = ndimage.distance_transform_edt(~blocked, return_indices=True)
    clearance = np.maximum(dist * res - 0.5 * res, 0.0).astype(np.float32)
    clearance[blocked] = 0.0
    nearest_label = label[ri, ci]
    return OccupancyGrid(x0, z0, res, blocked, label, nearest_label, clearance, room, room_ids,
                         tuple(f.object_id for f in floor), tuple(f.object_type for f in floor))
