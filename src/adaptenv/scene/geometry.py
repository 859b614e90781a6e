"""Scene geometry in the floor plane: room polygons, merged walls, door and window openings, footprints.

All 2-D points are (x, z) in meters. Yaw convention (ProcTHOR/AI2-THOR): yaw 0 faces +z, 90 faces
+x; an object's local x axis maps to (cos t, -sin t) and its local z axis (its front) to
(sin t, cos t).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import shapely
from shapely.geometry import Polygon

from adaptenv.scene.assets import (
    OCCLUDER_MIN_HEIGHT,
    AssetCatalog,
    ObjectRole,
    is_movable,
    load_catalog,
    object_role,
)
from adaptenv.scene.grid import NormalizedGrid
from adaptenv.scene.model import House, HouseObject, Opening, Wall

#: Walls whose endpoints agree to this many decimals are the same wall.
_MERGE_DECIMALS = 3
#: Length (m) of wall on each side of an opening that counts as its door frame.
DOOR_FRAME = 0.1


def yaw_axes(yaw_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """World directions of an object's local x axis and local z axis (its front) at this yaw."""
    t = math.radians(yaw_deg)
    c, s = math.cos(t), math.sin(t)
    return np.array([c, -s]), np.array([s, c])


def heading(yaw_deg: float) -> np.ndarray:
    """Unit (x, z) direction the yaw faces."""
    return yaw_axes(yaw_deg)[1]


def footprint_corners(cx: float, cz: float, size_x: float, size_z: float, yaw_deg: float) -> np.ndarray:
    """Corners (4, 2) of a size_x by size_z rectangle centred at (cx, cz) and turned by yaw.

    Order: local (-x,-z), (+x,-z), (+x,+z), (-x,+z), i.e. back-left, back-right, front-right,
    front-left seen from behind the object.
    """
    t = math.radians(yaw_deg)
    c, s = math.cos(t), math.sin(t)
    hx, hz = size_x / 2.0, size_z / 2.0
    ax, az, bx, bz = hx * c, hx * -s, hz * s, hz * c  # half extents along the local x and z axes (yaw_axes)
    return np.array([[cx - ax - bx, cz - az - bz], [cx + ax - bx, cz + az - bz], [cx + ax + bx, cz + az + bz],
                     [cx - ax + bx, cz - az + bz]], dtype=float)


def pose_outline(local: np.ndarray, cx: float, cz: float, yaw_deg: float) -> np.ndarray:
    """World (x, z) points of local (x, z) points (..., 2) of an object centred at (cx, cz) turned by yaw."""
    ux, uz = yaw_axes(yaw_deg)
    local = np.asarray(local, dtype=float)
    return np.array([cx, cz]) + local[..., :1] * ux + local[..., 1:] * uz


def convex_pieces(local: np.ndarray) -> np.ndarray:
    """Convex pieces (C, 4, 2) whose union is the simple polygon ``local`` (N, 2).

    A 4-vertex convex outline (every box) is its own single piece; any other outline (an L or C
    counter, a user asset's footprint) is cut into triangles, each repeating its last vertex.
    """
    local = np.asarray(local, dtype=float)
    poly = Polygon(local)
    if len(local) == 4 and poly.convex_hull.area - poly.area <= 1e-9 * max(poly.area, 1e-12):
        return local[None].copy()
    tris = shapely.get_parts(shapely.constrained_delaunay_triangles(poly))
    pts = [np.asarray(t.exterior.coords)[:3] for t in tris if t.area > 1e-12]
    return np.array([[a, b, c, c] for a, b, c in pts], dtype=float).reshape(-1, 4, 2)


@dataclass(frozen=True)
class Footprint:
    """The floor rectangle of one object plus what consumers need to know about it."""

    object_id: str
    object_type: str
    asset_id: str
    center: tuple[float, float]
    size: tuple[float, float]
    """Full extents (x, z) in the object's local frame, m."""
    yaw: float
    height: float
    """Top of the object above the floor, m."""
    role: ObjectRole
    movable: bool
    shape: tuple[tuple[float, float], ...] | None = None
    """Local (x, z) outline for an asset that is not a box (L- and C-shaped counters, user assets)."""

    @cached_property
    def corners(self) -> np.ndarray:
        """Corners (4, 2) of the bounding rectangle (see :func:`footprint_corners`)."""
        return footprint_corners(self.center[0], self.center[1], self.size[0], self.size[1], self.yaw)

    @cached_property
    def local_outline(self) -> np.ndarray:
        """Local (x, z) vertices (N, 2) of the true floor outline: the shape when set, else the box."""
        if self.shape is None:
            return footprint_corners(0.0, 0.0, self.size[0], self.size[1], 0.0)
        return np.asarray(self.shape, dtype=float)

    @cached_property
    def outline(self) -> np.ndarray:
        """World (x, z) vertices (N, 2) of the true floor outline: the shape when set, else the corners.

        The one footprint every consumer uses: simulator and validation rasters, the renderer,
        collision-aware placement (through :attr:`local_pieces`), the in-room checks and the scene
        graph's relations.
        """
        if self.shape is None:
            return self.corners
        return pose_outline(self.local_outline, self.center[0], self.center[1], self.yaw)

    @cached_property
    def local_pieces(self) -> np.ndarray:
        """Convex pieces (C, 4, 2) of :attr:`local_outline` (one for a box), for separating-axis tests."""
        return convex_pieces(self.local_outline)

    @cached_property
    def bounds(self) -> tuple[float, float, float, float]:
        """(min x, min z, max x, max z) of :attr:`outline`, m."""
        xs, zs = self.outline.T.tolist()  # Python floats: quicker than numpy reductions on a few points
        return min(xs), min(zs), max(xs), max(zs)

    @cached_property
    def polygon(self) -> Polygon:
        """The true floor outline as a polygon (the bounding rectangle for boxes)."""
        return shapely.polygons(self.outline)

    @property
    def occludes(self) -> bool:
        """Tall objects block line of sight; low ones (beds, tables, chairs) do not."""
        return self.height >= OCCLUDER_MIN_HEIGHT


def footprint_room(fp: Footprint, rooms: dict[str, Polygon]) -> str | None:
    """The room an object stands in, by its true footprint: the room covering its centre when the centre
    lies on the footprint (every box), else the room holding most of the footprint (None: no room).

    The centre of an L or C counter's bounding box can lie in the floor it wraps around, even
    outside the room; its outline cannot.
    """
    centre = shapely.Point(fp.center)
    if fp.shape is None or fp.polygon.covers(centre):
        for rid, poly in rooms.items():
            if poly.covers(centre):
                return rid
    areas = {rid: poly.intersection(fp.polygon).area for rid, poly in rooms.items()}
    best = max(areas, key=areas.get, default=None)
    return best if best is not None and areas[best] > 0 else None


def object_footprint(obj: HouseObject, catalog: AssetCatalog, *, is_child: bool = False) -> Footprint:
    """Footprint of a house object from its asset's bounding box (and outline, if it is not a box)."""
    asset = catalog.asset(obj.assetId)
    sx, sy, sz = asset.size
    bottom = obj.position.y - sy / 2.0
    role = object_role(asset.object_type, bottom, is_child)
    return Footprint(obj.id, asset.object_type, obj.assetId, (obj.position.x, obj.position.z), (sx, sz),
                     obj.rotation.y % 360.0, obj.position.y + sy / 2.0, role,
                     is_movable(asset.object_type, role), asset.footprint)


def wall_floor_segment(wall: Wall) -> tuple[np.ndarray, np.ndarray]:
    """The wall's floor edge (p0, p1) in (x, z): its two lowest vertices in listed order."""
    pts = sorted(range(len(wall.polygon)), key=lambda i: (wall.polygon[i].y, i))[:2]
    a, b = sorted(pts)
    pa, pb = wall.polygon[a], wall.polygon[b]
    return np.array([pa.x, pa.z]), np.array([pb.x, pb.z])


def _segment_key(p0: np.ndarray, p1: np.ndarray) -> tuple:
    a = tuple(np.round(p0, _MERGE_DECIMALS))
    b = tuple(np.round(p1, _MERGE_DECIMALS))
    return (a, b) if a <= b else (b, a)


@dataclass(frozen=True)
class WallSegment:
    """A merged wall: one segment however many rooms (and the exterior) list it."""

    p0: tuple[float, float]
    p1: tuple[float, float]
    wall_ids: tuple[str, ...]
    rooms: tuple[str, ...]
    empty: bool
    """An open connection (ProcTHOR ``empty: true``): walkable, draws no wall."""


@dataclass(frozen=True)
class OpeningSegment:
    """A door or window as a world segment along its wall."""

    id: str
    kind: str  # "door" | "window"
    asset_id: str
    p0: tuple[float, float]
    p1: tuple[float, float]
    rooms: tuple[str, str]
    passable: bool

    @property
    def width(self) -> float:
        return float(math.dist(self.p0, self.p1))

    @property
    def midpoint(self) -> tuple[float, float]:
        return ((self.p0[0] + self.p1[0]) / 2.0, (self.p0[1] + self.p1[1]) / 2.0)


def opening_segment(opening: Opening, walls: dict[str, Wall], kind: str) -> OpeningSegment:
    """World segment of a door or window from its wall0-local hole polygon."""
    p0, p1 = wall_floor_segment(walls[opening.wall0])
    u = (p1 - p0) / max(np.linalg.norm(p1 - p0), 1e-12)
    xs = [v.x for v in opening.holePolygon]
    a, b = p0 + u * min(xs), p0 + u * max(xs)
    exterior = "exterior" in opening.wall1 or opening.room0 == opening.room1
    passable = kind == "door" and not exterior and (opening.openness is None or opening.openness > 0)
    return OpeningSegment(opening.id, kind, opening.assetId, (float(a[0]), float(a[1])), (float(b[0]), float(b[1])),
                          (opening.room0, opening.room1), passable)


def _subtract_intervals(length: float, holes: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Parts of [0, length] not covered by any hole interval."""
    out, start = [], 0.0
    for a, b in sorted(holes):
        if a > start:
            out.append((start, min(a, length)))
        start = max(start, b)
    if start < length:
        out.append((start, length))
    return [(a, b) for a, b in out if b - a > 1e-6]


@dataclass
class SceneGeometry:
    """Everything geometric about a house that simulation, rendering and editing need."""

    rooms: dict[str, Polygon]
    room_types: dict[str, str]
    walls: list[WallSegment]
    doors: list[OpeningSegment]
    windows: list[OpeningSegment]
    footprints: list[Footprint]
    """Top-level objects (floor furniture and wall decor); see ``floor_objects``."""
    children: dict[str, list[Footprint]] = field(default_factory=dict)
    """Small objects resting on each top-level object, by parent id."""
    grid: NormalizedGrid | None = None

    @classmethod
    def from_house(cls, house: House, catalog: AssetCatalog | None = None) -> SceneGeometry:
        """Derive the geometry of a house (assumes a house that passed validation)."""
        catalog = catalog or load_catalog()
        rooms = {r.id: Polygon([(p.x, p.z) for p in r.floorPolygon]) for r in house.rooms}
        room_types = {r.id: r.roomType for r in house.rooms}
        wall_by_id = {w.id: w for w in house.walls}

        merged: dict[tuple, dict] = {}
        for w in house.walls:
            p0, p1 = wall_floor_segment(w)
            key = _segment_key(p0, p1)
            m = merged.setdefault(key, {"p0": p0, "p1": p1, "ids": [], "rooms": [], "empty": False})
            m["ids"].append(w.id)
            if w.roomId != "exterior":
                m["rooms"].append(w.roomId)
            m["empty"] = m["empty"] or bool(w.empty)
        walls = [WallSegment(tuple(map(float, m["p0"])), tuple(map(float, m["p1"])), tuple(m["ids"]),
                             tuple(m["rooms"]), m["empty"]) for m in merged.values()]

        doors = [opening_segment(d, wall_by_id, "door") for d in house.doors if d.wall0 in wall_by_id]
        windows = [opening_segment(w, wall_by_id, "window") for w in house.windows if w.wall0 in wall_by_id]
        footprints, children = [], {}
        for obj in house.objects:
            footprints.append(object_footprint(obj, catalog))
            children[obj.id] = [object_footprint(c, catalog, is_child=True) for c in obj.children]
        return cls(rooms, room_types, walls, doors, windows, footprints, children, NormalizedGrid.for_house(house))

    @property
    def floor_objects(self) -> list[Footprint]:
        """Top-level objects standing on the floor: the furniture the agent bumps into."""
        return [f for f in self.footprints if f.role == "floor"]

    @property
    def movable_objects(self) -> list[Footprint]:
        return [f for f in self.footprints if f.movable]

    @cached_property
    def floor(self) -> Polygon:
        """Union of all room polygons."""
        return shapely.union_all(list(self.rooms.values()))

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(min x, min z, max x, max z) of the rooms."""
        return tuple(self.floor.bounds)

    def blocking_segments(self) -> np.ndarray:
        """Wall segments that stop the agent, (N, 2, 2): walls minus passable door holes and empty walls.

        Closed doors (the exterior door) and windows stay blocking.
        """
        out = []
        passable = [d for d in self.doors if d.passable]
        for w in self.walls:
            if w.empty:
                continue
            p0, p1 = np.array(w.p0), np.array(w.p1)
            length = float(np.linalg.norm(p1 - p0))
            if length < 1e-9:
                continue
            u = (p1 - p0) / length
            holes = []
            for d in passable:
                a, b = np.array(d.p0), np.array(d.p1)
                # The door lies on this wall when both ends are on the wall's line.
                if abs(_cross(u, a - p0)) < 1e-3 and abs(_cross(u, b - p0)) < 1e-3:
                    ta, tb = sorted((float(np.dot(a - p0, u)), float(np.dot(b - p0, u))))
                    if tb > 0 and ta < length:
                        holes.append((ta, tb))
            for a, b in _subtract_intervals(length, holes):
                out.append([p0 + a * u, p0 + b * u])
        return np.array(out, dtype=float).reshape(-1, 2, 2)

    def room_of_point(self, x: float, z: float) -> str | None:
        """Id of the room containing the point (boundary included), or None."""
        pt = shapely.Point(x, z)
        for rid, poly in self.rooms.items():
            if poly.covers(pt):
                return rid
        return None

    def footprint(self, object_id: str) -> Footprint:
        for f in self.footprints:
            if f.object_id == object_id:
                return f
        raise KeyError(object_id)


def _cross(u: np.ndarray, v: np.ndarray) -> float:
    return float(u[0] * v[1] - u[1] * v[0])
