"""Door approach zones: the floor in front of and behind each passable doorway that furniture must not park across.

ProcTHOR keeps door clearances when it furnishes a room (``allenai/procthor``,
``procthor/generation/doors.py`` at commit 53d5bd4): before any floor object is placed, a polygon
per door is cut out of each adjoining room's free area (``objects.py``, ``_cut_out_doors``), spanning
the door's width and reaching ``PREFERRED_ENTRANCE_PADDING`` = 0.5 m on the entrance side and the
door's swing plus ``PADDING_IN_FRONT_OF_DOOR`` = 0.35 m on the side it opens to; open connections
get ``OPEN_ROOM_PADDING`` = 0.35 m per side. So no object in a ProcTHOR house stands in that zone.

adaptenv keeps a simpler, symmetric zone: the door's width by :data:`APPROACH_DEPTH` m on each
side. Edits may narrow a doorway's approach (furniture may reach into the zone) but may not
cover more than :data:`MAX_APPROACH_COVER` of the door's width there, measured as the union of
the furniture-in-zone projected onto the door line: a dresser flush across an open doorway
covers most of its width and is rejected, a chair beside the frame is not.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import shapely
from shapely.geometry import Polygon

from adaptenv.scene.geometry import SceneGeometry

#: Depth (m) of the approach zone on each side of a doorway (ProcTHOR's entrance padding).
APPROACH_DEPTH = 0.5
#: Largest share of a door's width that furniture may cover inside its approach zone.
MAX_APPROACH_COVER = 0.5


@dataclass(frozen=True)
class ApproachZone:
    """One passable doorway's approach zone and the door line it is measured along."""

    door_id: str
    p0: np.ndarray
    u: np.ndarray
    """Unit vector along the door, from p0."""
    width: float
    zone: Polygon

    @cached_property
    def bounds(self) -> tuple[float, float, float, float]:
        """(min x, min z, max x, max z) of the zone, m."""
        return tuple(float(b) for b in self.zone.bounds)


def approach_zones(geometry: SceneGeometry, depth: float = APPROACH_DEPTH) -> list[ApproachZone]:
    """The approach zone of every passable doorway (doors and doorframes; closed doors have none)."""
    out = []
    for d in geometry.doors:
        p0, p1 = np.array(d.p0, dtype=float), np.array(d.p1, dtype=float)
        width = float(np.linalg.norm(p1 - p0))
        if not d.passable or width < 1e-6:
            continue
        zone = shapely.LineString([d.p0, d.p1]).buffer(depth, cap_style="flat")
        out.append(ApproachZone(d.id, p0, (p1 - p0) / width, width, zone))
    return out


def covered_width(zone: ApproachZone, polygons: list[Polygon]) -> float:
    """Length (m) of the door line covered by the parts of ``polygons`` inside the zone (union of projections)."""
    spans = []
    for poly in polygons:
        if not zone.zone.intersects(poly):
            continue
        part = zone.zone.intersection(poly)
        if part.is_empty or part.area <= 1e-9:
            continue
        pts = np.asarray(shapely.get_coordinates(part), dtype=float)
        t = (pts - zone.p0) @ zone.u
        spans.append((max(float(t.min()), 0.0), min(float(t.max()), zone.width)))
    total, end = 0.0, -np.inf
    for a, b in sorted(spans):
        if b <= end:
            continue
        total += b - max(a, end)
        end = b
    return total


def blocked_approaches(zones: list[ApproachZone], polygons: dict[str, Polygon], before: dict[str, float] | None = None
                       ) -> list[tuple[str, float, float, list[str]]]:
    """Doorways whose approach is covered past :data:`MAX_APPROACH_COVER` of their width and more than
    ``before`` (covered width by door id, e.g. in the original scene): (door id, covered m, width m, object ids)."""
    out = []
    for z in zones:
        cover = covered_width(z, list(polygons.values()))
        if cover <= MAX_APPROACH_COVER * z.width or cover <= (before or {}).get(z.door_id, 0.0) + 1e-6:
            continue
        ids = sorted(k for k, p in polygons.items() if z.zone.intersects(p) and z.zone.intersection(p).area > 1e-9)
        out.append((z.door_id, cover, z.width, ids))
    return out
