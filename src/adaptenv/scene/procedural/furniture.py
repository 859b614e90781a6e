"""Floor-object stage: furniture chosen by room type and placed against walls, in corners or mid-room.

A *unit* is what gets placed as one rigid piece: a single object, or a group such as a dining
table with its chairs or a desk with its chair. Every unit is placed with a yaw that is a
multiple of 90 degrees, so its floor box is axis-aligned and every test is a few array
comparisons. As in ProcTHOR, a placed unit claims its footprint and a clearance zone (0.5 m in
front of wall units, 0.35 m around mid-room units); later footprints avoid both, and later
clearance zones avoid footprints. Door zones (in front of every door, doorframe and open wall,
on both sides) are kept free of footprints. The same placement engine re-places the movable
furniture of an existing house (:func:`replace_movables`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely
from scipy import ndimage
from shapely.geometry import Polygon

from adaptenv.scene.assets import AssetCatalog, AssetInfo, is_movable, object_role
from adaptenv.scene.geometry import footprint_corners, opening_segment, wall_floor_segment, yaw_axes
from adaptenv.scene.house import House, HouseObject, Room, Vec3, move_object
from adaptenv.scene.procedural.config import GenerationConfig, StageFailed
from adaptenv.scene.procedural.doors import split_assets
from adaptenv.vocabulary import CHAIR_TABLE_TYPES

Anchor = str  # "corner" | "edge" | "middle"

#: Anchors that override (or add to) the ProcTHOR annotations for a few types.
ANCHOR_OVERRIDES: dict[str, tuple[Anchor, ...]] = {
    "Television": ("edge",),  # floor-standing TVs stand with their back to a wall
    "DiningTable": ("middle",),
    "CoffeeTable": ("middle",),
    "Chair": ("corner",),
    "HousePlant": ("corner", "edge"),
    "Toilet": ("edge", "corner"),
    "Sink": ("edge",),
    "Bed": ("edge", "corner"),
}
#: Types never placed as fillers (no split assets, odd on the floor, or handled as group members).
EXCLUDED_FILLERS = frozenset({"Chair", "Cart", "BaseballBat", "BasketBall", "Boots", "Plunger", "GarbageBag",
                              "Sink", "Television", "Toilet", "Fridge", "CounterTop", "Bed"})
#: Anchors of group members placed on their own when their group fits nowhere.
SOLO_ANCHORS: dict[str, tuple[Anchor, ...]] = {"Chair": ("corner", "edge"), "Stool": ("corner", "edge")}
#: Tables that chairs belong to when a house is rearranged.
#: Types that need a minimum height to stand on the floor (basins and tiny plants go on counters).
MIN_FLOOR_HEIGHT = {"Sink": 0.6, "HousePlant": 0.6}
#: Types that ProcTHOR never marks kinematic (they may be pushed around).
NON_KINEMATIC = frozenset({"GarbageCan", "HousePlant", "FloorLamp", "Box", "DogBed", "LaundryHamper"})
#: Added to the agent radius when keeping a room's doors connected (the check dilates boxes, the
#: simulator discs; the slack covers rasterization).
PASSAGE_SLACK = 0.05
#: Pairs that face each other across the room when both stand against walls.
FACING = {"Sofa": "Television", "Television": "Sofa"}
#: Gap (m) between a table and the chairs around it.
CHAIR_GAP = 0.05
_EPS = 1e-6


# ------------------------------------------------------------------------------------------------ units


@dataclass
class Member:
    """One object of a unit: its asset, its pose in the unit's frame, and the object if it exists."""

    asset: AssetInfo
    x: float = 0.0
    z: float = 0.0
    yaw: float = 0.0
    obj: HouseObject | None = None


@dataclass
class Unit:
    """A rigid group placed at once; the first member (the principal) defines the frame and anchors."""

    members: list[Member]
    anchors: tuple[Anchor, ...]
    box: tuple[float, float, float, float] = field(init=False)
    """Local bounding box (x0, z0, x1, z1) of every member's footprint; local -z is the back."""
    _world: dict[float, tuple[float, float, float, float]] = field(init=False, default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        pts = np.concatenate([footprint_corners(m.x, m.z, m.asset.size[0], m.asset.size[2], m.yaw)
                              for m in self.members])
        self.box = (float(pts[:, 0].min()), float(pts[:, 1].min()), float(pts[:, 0].max()), float(pts[:, 1].max()))

    @property
    def object_type(self) -> str:
        return self.members[0].asset.object_type

    def world_box(self, yaw: float) -> tuple[float, float, float, float]:
        """Offsets of the unit's box from the principal's centre once turned to ``yaw`` (multiple of 90)."""
        if yaw in self._world:
            return self._world[yaw]
        ux, uz = yaw_axes(yaw)
        x0, z0, x1, z1 = self.box
        pts = np.array([x * ux + z * uz for x in (x0, x1) for z in (z0, z1)])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        self._world[yaw] = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
        return self._world[yaw]

    def poses(self, cx: float, cz: float, yaw: float) -> list[tuple[Member, float, float, float]]:
        """World (x, z, yaw) of every member when the principal stands at (cx, cz) with ``yaw``."""
        ux, uz = yaw_axes(yaw)
        out = []
        for m in self.members:
            p = np.array([cx, cz]) + m.x * ux + m.z * uz
            out.append((m, float(p[0]), float(p[1]), (yaw + m.yaw) % 360.0))
        return out


def anchors_of(object_type: str, catalog: AssetCatalog) -> tuple[Anchor, ...]:
    """Where a type may stand: ANCHOR_OVERRIDES, else the ProcTHOR inCorner/onEdge/inMiddle flags."""
    if object_type in ANCHOR_OVERRIDES:
        return ANCHOR_OVERRIDES[object_type]
    info = catalog.type_info(object_type)
    out = tuple(a for a, ok in (("corner", info.in_corner), ("edge", info.on_edge), ("middle", info.in_middle)) if ok)
    return out or ("edge",)


_POOLS: dict[int, tuple[AssetCatalog, dict[tuple[str, str], list[AssetInfo]]]] = {}


def floor_assets(catalog: AssetCatalog, object_type: str, split: str) -> list[AssetInfo]:
    """Assets of a type that can stand on the floor (e.g. pedestal sinks, big plants, straight counters).

    Cached per catalog object (the catalog is immutable).
    """
    entry = _POOLS.get(id(catalog))
    if entry is None or entry[0] is not catalog:
        entry = _POOLS[id(catalog)] = (catalog, {})
    key = (object_type, split)
    if key not in entry[1]:
        entry[1][key] = _floor_assets(catalog, object_type, split)
    return entry[1][key]


def _floor_assets(catalog: AssetCatalog, object_type: str, split: str) -> list[AssetInfo]:
    pool = split_assets(catalog, object_type, split)
    low = MIN_FLOOR_HEIGHT.get(object_type, 0.0)
    pool = [a for a in pool if a.size[1] >= low]
    if object_type == "CounterTop":
        pool = [a for a in pool if a.asset_id.startswith("Countertop_I_")]
    if object_type == "Desk":  # L-shaped corner desks would fill a box much bigger than themselves
        pool = [a for a in pool if a.size[2] <= 1.0]
    return pool


def _pick(rng: np.random.Generator, pool: list[AssetInfo]) -> AssetInfo | None:
    return pool[int(rng.integers(len(pool)))] if pool else None


def _dining_group(table: AssetInfo, chair: AssetInfo, per_side: int, ends: bool) -> list[Member]:
    """A table with chairs along its long sides (and optionally its ends), each chair facing the table."""
    tx, tz = table.size[0], table.size[2]
    cz = chair.size[2]
    members = [Member(table)]
    long_x = tx >= tz
    length, depth = (tx, tz) if long_x else (tz, tx)
    offsets = [0.0] if per_side == 1 else [-length / 4, length / 4]
    for side in (-1, 1):
        d = side * (depth / 2 + CHAIR_GAP + cz / 2)
        for o in offsets:
            if long_x:
                members.append(Member(chair, o, d, 0.0 if side < 0 else 180.0))
            else:
                members.append(Member(chair, d, o, 90.0 if side < 0 else 270.0))
    if ends:
        for side in (-1, 1):
            d = side * (length / 2 + CHAIR_GAP + cz / 2)
            if long_x:
                members.append(Member(chair, d, 0.0, 90.0 if side < 0 else 270.0))
            else:
                members.append(Member(chair, 0.0, d, 0.0 if side < 0 else 180.0))
    return members


def make_units(rng: np.random.Generator, catalog: AssetCatalog, cfg: GenerationConfig, object_type: str) -> list[Unit]:
    """Candidate units for one type, best first (a dining table with 4-6 chairs, then with 2, ...)."""
    asset = _pick(rng, floor_assets(catalog, object_type, cfg.split))
    if asset is None:
        return []
    anchors = anchors_of(object_type, catalog)
    chair = _pick(rng, [a for a in floor_assets(catalog, "Chair", cfg.split) if not a.asset_id.startswith("RoboTHOR_office")])
    if object_type == "DiningTable" and chair is not None:
        length = max(asset.size[0], asset.size[2])
        per_side = 2 if length >= 2 * chair.size[0] + 0.3 else 1
        options = [_dining_group(asset, chair, per_side, rng.random() < 0.3), _dining_group(asset, chair, 1, False)]
        return [Unit(m, anchors) for m in options] + [Unit([Member(asset)], ("edge",))]
    if object_type == "Desk" and chair is not None and rng.random() < 0.8:
        front = asset.size[2] / 2 + CHAIR_GAP + chair.size[2] / 2
        return [Unit([Member(asset), Member(chair, 0.0, front, 180.0)], ("edge",)), Unit([Member(asset)], anchors)]
    return [Unit([Member(asset)], anchors)]


# ------------------------------------------------------------------------------------------ room floors


@dataclass
class RoomFloor:
    """A rectilinear room as a grid of rectangles (between its distinct vertex coordinates), for fast
    box-inside-room tests, plus its wall runs with inward normals."""

    room_id: str
    room_type: str
    polygon: Polygon
    xs: np.ndarray
    zs: np.ndarray
    outside: np.ndarray
    """(len(xs), len(zs)) prefix sums of the outside-cell mask."""
    runs: list[tuple[np.ndarray, np.ndarray, np.ndarray]]
    """Wall runs (p, q, inward unit normal), collinear edges merged."""

    @classmethod
    def from_room(cls, room: Room) -> RoomFloor:
        pts = [(p.x, p.z) for p in room.floorPolygon]
        poly = Polygon(pts)
        xs = np.unique(np.round([p[0] for p in pts], 6))
        zs = np.unique(np.round([p[1] for p in pts], 6))
        cx, cz = np.meshgrid((xs[:-1] + xs[1:]) / 2, (zs[:-1] + zs[1:]) / 2, indexing="ij")
        out_cells = ~shapely.contains_xy(poly, cx, cz)
        outside = np.zeros((len(xs), len(zs)), dtype=np.int64)
        outside[1:, 1:] = np.cumsum(np.cumsum(out_cells, axis=0), axis=1)
        sign = -1.0 if _signed_area(pts) < 0 else 1.0
        runs: list[list[np.ndarray]] = []
        for i, a in enumerate(pts):
            b = pts[(i + 1) % len(pts)]
            pa, pb = np.array(a, dtype=float), np.array(b, dtype=float)
            d = pb - pa
            if np.linalg.norm(d) < 1e-9:
                continue
            if runs and abs(_cross(runs[-1][1] - runs[-1][0], d)) < 1e-9 and np.dot(runs[-1][1] - runs[-1][0], d) > 0:
                runs[-1][1] = pb
            else:
                runs.append([pa, pb])
        if len(runs) > 1 and abs(_cross(runs[0][1] - runs[0][0], runs[-1][1] - runs[-1][0])) < 1e-9 \
                and np.dot(runs[0][1] - runs[0][0], runs[-1][1] - runs[-1][0]) > 0:
            runs[0][0] = runs[-1][0]
            runs.pop()
        # Clockwise polygons (ProcTHOR's) have the floor on the right of each edge.
        out_runs = []
        for pa, pb in runs:
            u = (pb - pa) / np.linalg.norm(pb - pa)
            n = np.array([u[1], -u[0]]) if sign < 0 else np.array([-u[1], u[0]])
            out_runs.append((pa, pb, n))
        return cls(room.id, room.roomType, poly, xs, zs, outside, out_runs)

    def contains(self, boxes: np.ndarray) -> np.ndarray:
        """bool (K,): which boxes (K, 4) as (x0, z0, x1, z1) lie inside the room."""
        b = np.atleast_2d(boxes)
        x0, z0, x1, z1 = b[:, 0] + _EPS, b[:, 1] + _EPS, b[:, 2] - _EPS, b[:, 3] - _EPS
        ok = (x0 >= self.xs[0]) & (x1 <= self.xs[-1]) & (z0 >= self.zs[0]) & (z1 <= self.zs[-1]) & (x1 > x0) & (z1 > z0)
        i0 = np.clip(np.searchsorted(self.xs, x0, "right") - 1, 0, len(self.xs) - 1)
        i1 = np.clip(np.searchsorted(self.xs, x1, "left"), 0, len(self.xs) - 1)
        j0 = np.clip(np.searchsorted(self.zs, z0, "right") - 1, 0, len(self.zs) - 1)
        j1 = np.clip(np.searchsorted(self.zs, z1, "left"), 0, len(self.zs) - 1)
        s = self.outside
        count = s[i1, j1] - s[i0, j1] - s[i1, j0] + s[i0, j0]
        return ok & (count == 0)

    @property
    def area(self) -> float:
        return float(self.polygon.area)


def _signed_area(pts: list[tuple[float, float]]) -> float:
    return 0.5 * sum(pts[i][0] * pts[(i + 1) % len(pts)][1] - pts[(i + 1) % len(pts)][0] * pts[i][1]
                     for i in range(len(pts)))


def _cross(u: np.ndarray, v: np.ndarray) -> float:
    return float(u[0] * v[1] - u[1] * v[0])


def _yaw_of(n: np.ndarray) -> float:
    """Yaw (degrees, multiple of 90) that faces the direction n."""
    return float(round(math.degrees(math.atan2(n[0], n[1])) / 90.0) * 90.0 % 360.0)


# ------------------------------------------------------------------------------------------- placement


class Layout:
    """Footprints and clearance zones claimed so far, across the whole house (boxes x0, z0, x1, z1)."""

    def __init__(self, cfg: GenerationConfig, door_zones: np.ndarray):
        self.cfg = cfg
        self.solid = np.empty((0, 4))
        self.zones = np.empty((0, 4))
        self.doors = np.asarray(door_zones, dtype=float).reshape(-1, 4)

    def add(self, box: np.ndarray, zone: np.ndarray | None) -> None:
        self.solid = np.vstack([self.solid, box[None]])
        if zone is not None:
            self.zones = np.vstack([self.zones, zone[None]])

    @staticmethod
    def _hits(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """bool (K,): whether each box of a (K, 4) overlaps (with positive area) any box of b (M, 4)."""
        if len(b) == 0 or len(a) == 0:
            return np.zeros(len(a), dtype=bool)
        return ((a[:, None, 0] < b[None, :, 2] - _EPS) & (b[None, :, 0] < a[:, None, 2] - _EPS)
                & (a[:, None, 1] < b[None, :, 3] - _EPS) & (b[None, :, 1] < a[:, None, 3] - _EPS)).any(axis=1)

    def valid(self, floor: RoomFloor, boxes: np.ndarray, zones: np.ndarray, middle: np.ndarray) -> np.ndarray:
        """Which candidates fit: box and zone inside the room, box clear of everything claimed, zone clear
        of footprints; mid-room units also keep their zone clear of other zones and door zones, and a
        passage to every wall, so they never close off part of the room."""
        g, p, k = self.cfg.object_gap, self.cfg.passage, len(boxes)
        inside = floor.contains(np.concatenate([boxes, zones, boxes + np.array([-p, -p, p, p])]))
        ok = inside[:k] & inside[k:2 * k]
        ok &= ~self._hits(boxes, np.concatenate([self.solid + np.array([-g, -g, g, g]), self.zones, self.doors]))
        ok &= ~self._hits(zones, self.solid)
        mid = np.nonzero(middle & ok)[0]
        if len(mid):
            ok[mid] &= inside[2 * k:][mid] & ~self._hits(zones[mid], np.concatenate([self.doors, self.zones]))
        return ok


def _edge_candidates(rng: np.random.Generator, unit: Unit, floor: RoomFloor, cfg: GenerationConfig, corner: bool,
                     n_edge: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Poses, boxes and front zones of the unit with its back to each wall run (at the ends for corners)."""
    gap, m = cfg.wall_gap, cfg.edge_margin
    out = []
    for p, q, n in floor.runs:
        yaw = _yaw_of(n)
        ox0, oz0, ox1, oz1 = unit.world_box(yaw)
        axis = 0 if abs(q[0] - p[0]) > abs(q[1] - p[1]) else 1  # the axis the wall runs along
        lo, hi = min(p[axis], q[axis]) + gap, max(p[axis], q[axis]) - gap
        width = (ox1 - ox0) if axis == 0 else (oz1 - oz0)
        if hi - lo < width:
            continue
        s = np.array([lo, hi - width]) if corner else rng.uniform(lo, hi - width, n_edge)
        wall = p[1 - axis]
        if axis == 0:  # wall along x at z = wall; n = (0, +-1)
            cz = np.full_like(s, wall + gap - oz0 if n[1] > 0 else wall - gap - oz1)
            cx = s - ox0
        else:  # wall along z at x = wall; n = (+-1, 0)
            cx = np.full_like(s, wall + gap - ox0 if n[0] > 0 else wall - gap - ox1)
            cz = s - oz0
        boxes = np.stack([cx + ox0, cz + oz0, cx + ox1, cz + oz1], axis=1)
        zones = boxes.copy()
        k = 1 - axis  # the axis the unit faces along
        if n[k] > 0:
            zones[:, k], zones[:, k + 2] = boxes[:, k + 2], boxes[:, k + 2] + m
        else:
            zones[:, k], zones[:, k + 2] = boxes[:, k] - m, boxes[:, k]
        out.append((np.stack([cx, cz, np.full_like(s, yaw)], axis=1), boxes, zones))
    return out


def _middle_candidates(rng: np.random.Generator, unit: Unit, floor: RoomFloor, cfg: GenerationConfig,
                       n_middle: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses, boxes and surrounding zones of the unit at random mid-room spots and right angles."""
    mm = cfg.middle_margin
    x_lo, z_lo, x_hi, z_hi = floor.polygon.bounds
    yaws = rng.integers(4, size=n_middle) * 90.0
    off = np.array([unit.world_box(float(y)) for y in (0.0, 90.0, 180.0, 270.0)])[(yaws // 90).astype(int)]
    w, d = off[:, 2] - off[:, 0], off[:, 3] - off[:, 1]
    bx = x_lo + mm + rng.random(n_middle) * np.maximum(x_hi - x_lo - 2 * mm - w, 0.0)
    bz = z_lo + mm + rng.random(n_middle) * np.maximum(z_hi - z_lo - 2 * mm - d, 0.0)
    boxes = np.stack([bx, bz, bx + w, bz + d], axis=1)
    poses = np.stack([bx - off[:, 0], bz - off[:, 1], yaws], axis=1)
    return poses, boxes, boxes + np.array([-mm, -mm, mm, mm])


def _candidates(rng: np.random.Generator, unit: Unit, floor: RoomFloor, cfg: GenerationConfig,
                n_edge: int = 5, n_middle: int = 24) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Candidate poses (K, 3: cx, cz, yaw), boxes (K, 4), zones (K, 4) and mid-room flags (K,)."""
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, bool]] = []
    for anchor in unit.anchors:
        if anchor in ("edge", "corner"):
            parts += [(*c, False) for c in _edge_candidates(rng, unit, floor, cfg, anchor == "corner", n_edge)]
        elif anchor == "middle":
            parts.append((*_middle_candidates(rng, unit, floor, cfg, n_middle), True))
    if not parts:
        empty = np.empty((0, 4))
        return np.empty((0, 3)), empty, empty, np.empty(0, dtype=bool)
    middle = np.concatenate([np.full(len(p[0]), p[3]) for p in parts])
    return (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]),
            np.concatenate([p[2] for p in parts]), middle)


class RoomPassages:
    """A coarse raster of one room that keeps its doors connected to each other.

    Cells are free when a disc of ``radius`` fits there (walls and placed footprints dilated by the
    radius, footprints as boxes: stricter than the simulator's disc). A placement that would cut
    one door zone of the room off from another is refused.
    """

    def __init__(self, floor: RoomFloor, door_zones: np.ndarray, radius: float, resolution: float = 0.1):
        self.res, self.radius = resolution, radius
        x0, z0, x1, z1 = floor.polygon.bounds
        self.x0, self.z0 = x0, z0
        nx, nz = max(1, int(math.ceil((x1 - x0) / resolution))), max(1, int(math.ceil((z1 - z0) / resolution)))
        cx = x0 + (np.arange(nx) + 0.5) * resolution
        cz = z0 + (np.arange(nz) + 0.5) * resolution
        inside = shapely.contains_xy(floor.polygon, cx[:, None], cz[None, :])
        padded = np.pad(inside, 1)
        dist = ndimage.distance_transform_edt(padded)[1:-1, 1:-1] * resolution - resolution / 2
        self.free = inside & (dist >= radius)
        self.ports: list[tuple[int, int]] = []
        for zb in door_zones:
            i0, i1, j0, j1 = self._cells(zb, 0.0)
            if i0 >= i1 or j0 >= j1:
                continue
            sub = np.where(self.free[i0:i1, j0:j1], dist[i0:i1, j0:j1], -1.0)
            if sub.max() > 0:
                i, j = np.unravel_index(int(np.argmax(sub)), sub.shape)
                self.ports.append((i0 + int(i), j0 + int(j)))

    def _cells(self, box: np.ndarray, pad: float) -> tuple[int, int, int, int]:
        """Index ranges [i0, i1) x [j0, j1) of the cells whose centres lie in the box grown by ``pad``."""
        r = self.res
        nx, nz = self.free.shape
        i0 = max(0, int(math.ceil((box[0] - pad - self.x0) / r - 0.5)))
        i1 = min(nx, int(math.floor((box[2] + pad - self.x0) / r - 0.5)) + 1)
        j0 = max(0, int(math.ceil((box[1] - pad - self.z0) / r - 0.5)))
        j1 = min(nz, int(math.floor((box[3] + pad - self.z0) / r - 0.5)) + 1)
        return i0, i1, j0, j1

    def block(self, box: np.ndarray) -> None:
        """Block the box (dilated by the radius) unconditionally (e.g. a fixture)."""
        i0, i1, j0, j1 = self._cells(box, self.radius)
        self.free[i0:i1, j0:j1] = False

    def try_block(self, box: np.ndarray) -> bool:
        """Block the box (dilated by the radius) unless that disconnects two doors; whether it did."""
        i0, i1, j0, j1 = self._cells(box, self.radius)
        if len(self.ports) < 2:
            self.free[i0:i1, j0:j1] = False
            return True
        new = self.free.copy()
        new[i0:i1, j0:j1] = False
        labels, _ = ndimage.label(new)
        ids = {int(labels[p]) for p in self.ports}
        if len(ids) != 1 or 0 in ids:
            return False
        self.free = new
        return True


def place_unit(rng: np.random.Generator, unit: Unit, floor: RoomFloor, layout: Layout, cfg: GenerationConfig,
               prefer_yaw: float | None = None, passages: RoomPassages | None = None,
               max_checks: int = 6) -> tuple[float, float, float] | None:
    """Find a pose for the unit in this room and claim its space; None when nothing fits.

    With ``prefer_yaw`` (e.g. a sofa facing the TV), fitting poses with that yaw are tried first.
    With ``passages``, poses that would cut the room's doors apart are refused (``max_checks``
    fitting poses are tried).
    """
    poses, boxes, zones, middle = _candidates(rng, unit, floor, cfg)
    if len(poses) == 0:
        return None
    ok = np.nonzero(layout.valid(floor, boxes, zones, middle))[0]
    if len(ok) == 0:
        return None
    ok = ok[rng.permutation(len(ok))]
    if prefer_yaw is not None:
        first = np.abs(poses[ok, 2] - prefer_yaw % 360.0) < 1e-6
        ok = np.concatenate([ok[first], ok[~first]])
    for i in ok[:max_checks]:
        if passages is None or passages.try_block(boxes[i]):
            layout.add(boxes[i], zones[i])
            return float(poses[i, 0]), float(poses[i, 1]), float(poses[i, 2])
    return None


def door_zones(house: House, cfg: GenerationConfig) -> np.ndarray:
    """Boxes (M, 4) kept free in front of every door and open wall, on both sides."""
    walls = {w.id: w for w in house.walls}
    out = []
    d, s = cfg.door_clearance, cfg.door_side_clearance

    def zone(a: np.ndarray, b: np.ndarray, side: float) -> None:
        u = (b - a) / max(np.linalg.norm(b - a), 1e-12)
        n = np.array([-u[1], u[0]])
        pts = np.array([a - s * u, b + s * u])
        pts = np.concatenate([pts + d * n, pts - d * n])
        if side == 0.0:
            pts = np.concatenate([pts, [a, b]])
        out.append([pts[:, 0].min(), pts[:, 1].min(), pts[:, 0].max(), pts[:, 1].max()])

    for door in house.doors:
        if door.wall0 in walls:
            seg = opening_segment(door, walls, "door")
            zone(np.array(seg.p0), np.array(seg.p1), 1.0)
    for w in house.walls:
        if w.empty:
            a, b = wall_floor_segment(w)
            u = (b - a) / max(np.linalg.norm(b - a), 1e-12)
            zone(a + s * u, b - s * u, 1.0)
    return np.array(out, dtype=float).reshape(-1, 4)


# ------------------------------------------------------------------------------------- the floor stage


def _room_plan(rng: np.random.Generator, floor: RoomFloor, catalog: AssetCatalog, cfg: GenerationConfig,
               few_rooms: bool = False) -> list[str]:
    """Object types to try in a room, in order: essential and priority types, target-type fillers
    (a garbage can, often a plant; always both when the house has few rooms), weighted fillers."""
    rt = floor.room_type
    essential = list(cfg.essential_types.get(rt, ()))
    plan = essential + [t for t in cfg.priority_types.get(rt, ()) if t not in essential]
    if rt == "Kitchen":
        plan.insert(1, "CounterTop") if rng.random() < 0.6 else None
        if floor.area > 12 and rng.random() < 0.5:
            plan.append("DiningTable")
    if rt == "LivingRoom" and "DiningTable" in plan and (floor.area < 14 or rng.random() < 0.4):
        plan.remove("DiningTable")
    if rt == "Bedroom" and rng.random() < 0.5:
        plan.append("Desk")
    plan.append("GarbageCan")
    if few_rooms or rng.random() < 0.7:
        plan.append("HousePlant")
    fillers = sorted(t for t, info in catalog.types.items()
                     if info.on_floor and info.weight_in(rt) > 0 and t not in EXCLUDED_FILLERS
                     and floor_assets(catalog, t, cfg.split))
    if not fillers:
        return plan
    weights = np.array([3.0 if catalog.type_info(t).weight_in(rt) >= 2 else 1.0 for t in fillers])
    n = int(round(cfg.furniture_density * floor.area / 5.0 + rng.uniform(-0.5, 0.5)))
    for _ in range(max(0, n)):
        t = fillers[int(rng.choice(len(fillers), p=weights / weights.sum()))]
        if t in plan and not catalog.type_info(t).multiple_per_room:
            continue
        plan.append(t)
    return plan


def _new_object(member: Member, oid: str, x: float, z: float, yaw: float) -> HouseObject:
    a = member.asset
    return HouseObject(id=oid, assetId=a.asset_id, position=Vec3(x=round(x, 4), y=round(a.size[1] / 2, 4), z=round(z, 4)),
                       rotation=Vec3(x=0.0, y=round(yaw, 4), z=0.0), kinematic=a.object_type not in NON_KINEMATIC)


def _furnish_room(rng: np.random.Generator, room: Room, floor: RoomFloor, layout: Layout, catalog: AssetCatalog,
                  cfg: GenerationConfig, few_rooms: bool) -> list[HouseObject]:
    """Objects for one room, following its plan; priority types get a few asset draws each."""
    num = room.id.split("|")[1]
    priority = cfg.priority_types.get(room.roomType, ())
    passages = RoomPassages(floor, layout.doors, cfg.agent_radius + PASSAGE_SLACK)
    objects: list[HouseObject] = []
    yaws: dict[str, float] = {}
    k = 0
    for object_type in _room_plan(rng, floor, catalog, cfg, few_rooms):
        partner = FACING.get(object_type)
        prefer = (yaws[partner] + 180.0) % 360.0 if partner in yaws else None
        pose = None
        for _ in range(3 if object_type in priority else 1):
            for unit in make_units(rng, catalog, cfg, object_type):
                pose = place_unit(rng, unit, floor, layout, cfg, prefer, passages)
                if pose is not None:
                    break
            if pose is not None:
                break
        if pose is None:
            continue
        yaws[object_type] = pose[2]
        placed = unit.poses(*pose)
        for j, (m, x, z, yaw) in enumerate(placed):
            oid = f"{m.asset.object_type}|{num}|{k}" + (f"|{j}" if len(placed) > 1 else "")
            objects.append(_new_object(m, oid, x, z, yaw))
        k += 1
    return objects


def stage_floor_objects(house: House, *, rng: np.random.Generator, catalog: AssetCatalog, cfg: GenerationConfig) -> None:
    """Furniture for every room: priority types first, then fillers, each where it fits.

    A room is furnished again (up to four times) until its essential types (``cfg.essential_types``,
    e.g. a bed in a bedroom) are in; then the attempt fails and the pipeline retries.
    """
    layout = Layout(cfg, door_zones(house, cfg))
    objects: list[HouseObject] = []
    for room in house.rooms:
        floor = RoomFloor.from_room(room)
        need = set(cfg.essential_types.get(room.roomType, ()))
        for _ in range(4):
            saved = (layout.solid, layout.zones)
            placed = _furnish_room(rng, room, floor, layout, catalog, cfg, len(house.rooms) <= 2)
            if need <= {catalog.asset(o.assetId).object_type for o in placed}:
                break
            layout.solid, layout.zones = saved
        else:
            raise StageFailed(f"{room.id} ({room.roomType}) has no space for its {', '.join(sorted(need))}")
        objects += placed
    house.objects = objects


# ------------------------------------------------------------------------------------------ rearrange


def _footprint_box(obj: HouseObject, asset: AssetInfo) -> np.ndarray:
    c = footprint_corners(obj.position.x, obj.position.z, asset.size[0], asset.size[2], obj.rotation.y)
    return np.array([c[:, 0].min(), c[:, 1].min(), c[:, 0].max(), c[:, 1].max()])


def _existing_units(objs: list[HouseObject], catalog: AssetCatalog) -> list[Unit]:
    """Group chairs with the table or desk they stand at (within 0.4 m); other objects stand alone."""
    assets = {o.id: catalog.asset(o.assetId) for o in objs}
    tables = [o for o in objs if assets[o.id].object_type in CHAIR_TABLE_TYPES]
    groups: dict[str, list[HouseObject]] = {o.id: [o] for o in objs}
    for o in objs:
        if assets[o.id].object_type not in ("Chair", "Stool", "OfficeChair") or not tables:
            continue
        poly = Polygon(footprint_corners(o.position.x, o.position.z, assets[o.id].size[0], assets[o.id].size[2],
                                         o.rotation.y))
        dists = [Polygon(footprint_corners(t.position.x, t.position.z, assets[t.id].size[0], assets[t.id].size[2],
                                           t.rotation.y)).distance(poly) for t in tables]
        best = int(np.argmin(dists))
        if dists[best] <= 0.4:
            groups[tables[best].id].append(o)
            del groups[o.id]
    units = []
    for members in groups.values():
        p = members[0]
        ux, uz = yaw_axes(p.rotation.y)
        ms = []
        for o in members:
            d = np.array([o.position.x - p.position.x, o.position.z - p.position.z])
            ms.append(Member(assets[o.id], float(d @ ux), float(d @ uz), (o.rotation.y - p.rotation.y) % 360.0, o))
        units.append(Unit(ms, anchors_of(assets[p.id].object_type, catalog)))
    return units


def _keep_old_pose(unit: Unit, floor: RoomFloor, layout: Layout, passages: RoomPassages) -> bool:
    """Claim the unit's current place if it is axis-aligned, still free and keeps the doors connected."""
    p = unit.members[0].obj
    yaw = p.rotation.y % 360.0
    if abs(yaw - round(yaw / 90.0) * 90.0) > 1e-6:
        return False
    ox0, oz0, ox1, oz1 = unit.world_box(yaw)
    box = np.array([[p.position.x + ox0, p.position.z + oz0, p.position.x + ox1, p.position.z + oz1]])
    if not layout.valid(floor, box, box, np.array([False]))[0] or not passages.try_block(box[0]):
        return False
    layout.add(box[0], None)
    return True


def _move_unit(unit: Unit, pose: tuple[float, float, float]) -> None:
    """Move every member's object (and its children) to the unit's new pose."""
    for m, x, z, yaw in unit.poses(*pose):
        o = m.obj
        move_object(o, x - o.position.x, z - o.position.z, (yaw - o.rotation.y) % 360.0)
        o.position = Vec3(**{**o.position.model_dump(), "x": round(o.position.x, 4), "z": round(o.position.z, 4)})
        o.rotation = Vec3(**{**o.rotation.model_dump(), "y": round(o.rotation.y % 360.0, 4)})


def replace_movables(house: House, *, rng: np.random.Generator, catalog: AssetCatalog, cfg: GenerationConfig,
                     priority: tuple[str, ...] = ()) -> list[str]:
    """Place every movable floor object of the house anew (in its own room), in place.

    Fixtures, wall decor and objects outside rooms stay where they are and are obstacles. Units
    that fit nowhere keep their old pose when it is still free, else they are removed. Children
    move rigidly with their parents. Returns the ids of removed objects.
    """
    floors = [RoomFloor.from_room(r) for r in house.rooms]
    layout = Layout(cfg, door_zones(house, cfg))
    by_room: dict[int, list[HouseObject]] = {i: [] for i in range(len(floors))}
    for obj in house.objects:
        asset = catalog.assets.get(obj.assetId)
        if asset is None:
            continue
        role = object_role(asset.object_type, obj.position.y - asset.size[1] / 2, False)
        if role != "floor":
            continue
        box = _footprint_box(obj, asset)
        room = next((i for i, f in enumerate(floors) if f.contains(box)[0]), None)
        if is_movable(asset.object_type, role) and room is not None:
            by_room[room].append(obj)
        else:
            layout.add(box, None)
    removed: list[str] = []
    for i, floor in enumerate(floors):
        passages = RoomPassages(floor, layout.doors, cfg.agent_radius + PASSAGE_SLACK)
        for box in layout.solid[floor.contains(layout.solid)]:  # the fixtures of this room
            passages.block(box)

        def rank(u: Unit) -> tuple[bool, float]:
            return (not any(m.asset.object_type in priority for m in u.members),
                    -(u.box[2] - u.box[0]) * (u.box[3] - u.box[1]))

        queue = sorted(_existing_units(by_room[i], catalog), key=rank)
        yaws: dict[str, float] = {}
        while queue:
            unit = queue.pop(0)
            partner = FACING.get(unit.object_type)
            prefer = (yaws[partner] + 180.0) % 360.0 if partner in yaws else None
            pose = place_unit(rng, unit, floor, layout, cfg, prefer, passages)
            if pose is not None:
                _move_unit(unit, pose)
                yaws[unit.object_type] = pose[2]
            elif _keep_old_pose(unit, floor, layout, passages):
                continue
            elif len(unit.members) > 1:
                # A group that fits nowhere is split up: its members are placed one by one.
                queue[:0] = [Unit([Member(m.asset, obj=m.obj)], SOLO_ANCHORS.get(m.asset.object_type)
                                  or anchors_of(m.asset.object_type, catalog)) for m in unit.members]
            else:
                removed.append(unit.members[0].obj.id)
    if removed:
        gone = set(removed)
        house.objects = [o for o in house.objects if o.id not in gone]
    return removed
