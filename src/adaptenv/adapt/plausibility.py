"""The plausibility audit: does every moved object still stand where a person would put it?

ProcTHOR furnishes a room by its placement annotations (``inCorner`` / ``onEdge`` / ``inMiddle``
per object type, in :meth:`~adaptenv.scene.assets.AssetCatalog.type_info`), its asset groups
(objects placed together: chairs at a table, a floor lamp beside an armchair, a sofa facing a TV
stand; ``scene/data/asset_groups.json``, derived from ProcTHOR) and door clearances. An edit that
breaks one of these makes a house no person would live in. Rules, each checked per moved floor
object against the house before editing (only what the move made worse counts):

- ``edge_off_wall``: an object of an edge-only type (``onEdge`` and not ``inMiddle``, minus the
  free-standing types of :data:`~adaptenv.adapt.realism.FREE_STANDING`) that stood with its back
  to a wall, facing the room, no longer does (moved off its wall, or turned to face it);
- ``door_approach``: the object reaches further into a passable doorway's approach zone than
  before: the door's width by :data:`DOOR_CLEARANCE` m on each side;
- ``group_split``: the object and a member of its asset group (formed in the original house:
  pairs of the group's types in one room within :data:`GROUP_DISTANCE` m) end up farther apart
  than that (or than they were, when farther);
- ``open_floor``: a small object (footprint up to :data:`SMALL_AREA` m^2) of a type ProcTHOR
  never places in the middle of a room, that stood by a wall or by furniture, now stands on open
  floor: more than :data:`OPEN_FLOOR` m from every wall and every other floor object;
- ``facing_broken``: a seat that faced the television (stand) of its room, the television that
  faced it, or a chair that faced its table (heading within 45 degrees of the direction to the
  partner's centre) now turns more than 60 degrees away;
- ``wall_overhang``: an edge of the object that runs along a wall (parallel within
  :data:`~adaptenv.scene.graph.AGAINST_WALL_ANGLE` degrees, within
  :data:`~adaptenv.scene.graph.AGAINST_WALL_DISTANCE` m) runs past the wall's end (into a doorway, an
  open connection or past a corner) by more than :data:`OVERHANG` m, and further than before;
- ``in_opening``: the object reaches further into an open connection between two rooms (a wall
  ProcTHOR marks ``empty``: no wall, no door) than before: the opening's length by
  :data:`OPENING_CLEARANCE` m on each side;
- ``group_left_behind``: the anchor of an asset group (a dining table or desk with its chairs, an
  armchair with its lamp, a sofa with its armchair) moved, and a member no longer stands where it
  stood relative to it: its centre, in the anchor's frame, is more than :data:`GROUP_SHIFT` m from
  where it was (a group moves together or not at all; a box anchor turned by 180 degrees counts as unturned);
- ``blocks_window``: a tall object stands in front of a window, or covers more of it than before:
  its footprint, within :data:`WINDOW_DEPTH` m of the window, covers more than :data:`WINDOW_EPS` m
  more of the window's width, and its top reaches above the window's middle (the sill plus
  :data:`WINDOW_COVER` of the window's height; ProcTHOR-10K windows have sills at 0.5-0.85 m and
  middles near 1.3 m, procedural ones middles at 1.2-1.6 m, so a sofa or a dresser stands under a
  window, a fridge or a bookshelf in front of it).

:func:`audit` compares an adapted house with its original; :class:`PlausibilityReference` and
:func:`check_move` are the per-edit form every generator's
:class:`~adaptenv.adapt.validation.EditValidator` uses.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field

import numba
import numpy as np
import shapely

from adaptenv.adapt.doorways import APPROACH_DEPTH, ApproachZone, approach_zones, covered_width
from adaptenv.adapt.placement_model import (
    HouseLayout,
    PlacementModel,
    default_model,
    group_pairs,
    object_features,
    placement_class,
    unlike,
)
from adaptenv.adapt.realism import FREE_STANDING
from adaptenv.errors import AdaptenvError
from adaptenv.scene.assets import AssetCatalog, load_catalog
from adaptenv.scene.geometry import Footprint, SceneGeometry, yaw_axes
from adaptenv.scene.graph import (
    AGAINST_WALL_ANGLE,
    AGAINST_WALL_DISTANCE,
    MIN_WALL_OVERLAP,
    NEXT_TO_DISTANCE,
    backs_onto,
)
from adaptenv.scene.house import House

RULES = ("edge_off_wall", "door_approach", "group_split", "open_floor", "facing_broken", "wall_overhang",
         "in_opening", "group_left_behind", "blocks_window", "unlike_reference")
__all__ = ["RULES", "PlausibilityAudit", "PlausibilityReference", "Violation", "audit", "breaks_rules", "check_move",
           "edge_only", "group_pairs"]
#: Depth (m) of a doorway's clearance zone on each side. ProcTHOR keeps the door's swing (its width, about
#: 0.65-1.0 m) plus 0.35 m free on the side a door opens to; edits do not know that side, so both get 1 m.
DOOR_CLEARANCE = 1.0
#: Area (m^2) by which an object may reach further into a door zone (touching, rounding).
ZONE_EPS = 0.01
#: Group members stand at most this far apart (m, between footprints): the scene graph's ``next_to``.
GROUP_DISTANCE = NEXT_TO_DISTANCE
#: Footprints up to this area (m^2) are small objects (plungers, bins, plants, lamps, stools, chairs).
SMALL_AREA = 0.35
#: A small object farther than this (m) from every wall and floor object stands on open floor.
OPEN_FLOOR = 0.3
#: A pair faces when the heading is within 45 degrees of the partner; the facing breaks past 60.
FACING_BEFORE, FACING_AFTER = math.cos(math.radians(45.0)), math.cos(math.radians(60.0))
#: Who faces whom (from ProcTHOR's television-sofa groups, and the chairs it turns to their tables).
FACING: dict[str, frozenset[str]] = {
    "Sofa": frozenset({"TVStand", "Television"}),
    "ArmChair": frozenset({"TVStand", "Television"}),
    "Television": frozenset({"Sofa", "ArmChair"}),
    "TVStand": frozenset({"Sofa", "ArmChair"}),
    "Chair": frozenset({"DiningTable", "Desk"}),
}
#: An edge along a wall may run past the wall's end by this much (m) before it overhangs.
OVERHANG = 0.1
#: Depth (m) of an open connection's clearance on each side (ProcTHOR keeps 0.35 m free; a margin added).
OPENING_CLEARANCE = APPROACH_DEPTH
#: How far (m) a group member's centre may end from where it stood relative to its moved anchor.
GROUP_SHIFT = 0.3
#: Depth (m) in front of a window where a tall object blocks it.
WINDOW_DEPTH = 0.6
#: A tall object reaches above the sill by this share of the window's height (0.5: above the window's middle).
WINDOW_COVER = 0.5
#: Width (m) by which a tall object may cover more of a window than before (touching the frame, rounding).
WINDOW_EPS = 0.1


@dataclass(frozen=True)
class Violation:
    """One broken rule for one moved object."""

    rule: str
    object_id: str
    message: str
    others: tuple[str, ...] = ()
    """The partner, door or wall-side object ids involved."""
    feature: str = ""
    """The placement model's feature (``unlike_reference`` only)."""

    def __str__(self) -> str:
        return f"{self.rule}: {self.message}"


def edge_only(catalog: AssetCatalog, object_type: str) -> bool:
    """Whether ProcTHOR places this type only on an edge (never in the middle), free-standing types aside."""
    info = catalog.type_info(object_type)
    return info.on_edge and not info.in_middle and object_type not in FREE_STANDING


def _small(catalog: AssetCatalog, fp: Footprint) -> bool:
    info = catalog.type_info(fp.object_type)
    return fp.size[0] * fp.size[1] <= SMALL_AREA and not info.in_middle and (info.on_edge or info.in_corner)


@dataclass(frozen=True)
class _Walls:
    """The blocking wall segments (walls minus passable doors) as arrays and one geometry."""

    p0: np.ndarray
    p1: np.ndarray
    lines: np.ndarray
    union: shapely.Geometry
    units: np.ndarray
    """(N, 2) unit direction of each segment."""
    lo: np.ndarray
    hi: np.ndarray
    """(N, 2) corners of each segment's bounding box."""
    _distances: dict[bytes, float] = field(default_factory=dict, compare=False, repr=False)
    """:meth:`distance` per outline already measured (its vertices' bytes): the objects that did not move are
    measured again on every check."""

    @classmethod
    def of(cls, geometry: SceneGeometry) -> _Walls:
        seg = geometry.blocking_segments().reshape(-1, 2, 2)
        lines = shapely.linestrings(seg) if len(seg) else np.array([], dtype=object)
        d = seg[:, 1] - seg[:, 0]
        return cls(seg[:, 0], seg[:, 1], lines, shapely.multilinestrings(list(lines)) if len(seg) else shapely.Point(),
                   d / np.maximum(np.linalg.norm(d, axis=1), 1e-12)[:, None], seg.min(axis=1), seg.max(axis=1))

    def against(self, fp: Footprint) -> bool:
        """The scene graph's ``against_wall``: the back edge along a wall, the front pointing into the room."""
        if not len(self.lines):
            return False
        (ax, az), (bx, bz) = fp.corners[:2].tolist()
        near = _segments_near(ax, az, bx, bz, self.lo, self.hi, self.p0, self.p1, AGAINST_WALL_DISTANCE)
        if (near == _TIE).any():  # GEOS decides distances this close to the limit
            k = np.flatnonzero(near == _TIE)
            near[k] = shapely.distance(shapely.linestrings(fp.corners[:2]), self.lines[k]) <= AGAINST_WALL_DISTANCE
        min_cos = math.cos(math.radians(AGAINST_WALL_ANGLE))
        return any(backs_onto(fp, self.p0[k], self.p1[k], min_cos) for k in np.flatnonzero(near == 1))

    def distance(self, fp: Footprint) -> float:
        """The distance (m) from the footprint's outline to the nearest blocking segment (inf when there is none)."""
        if not len(self.lines):
            return math.inf
        key = np.ascontiguousarray(fp.outline, dtype=np.float64).tobytes()
        d = self._distances.get(key)
        if d is None:
            d = self._distances[key] = float(shapely.distance(fp.polygon, self.union))
        return d

    def overhang(self, fp: Footprint) -> float:
        """How far (m) an edge of the footprint that runs along a wall runs past that wall's end (0 when none does).

        An edge runs along a wall when a blocking segment parallel to it (within AGAINST_WALL_ANGLE) lies within
        AGAINST_WALL_DISTANCE and covers at least MIN_WALL_OVERLAP of it, projected onto the edge; the overhang is
        the part of the edge no such segment covers.
        """
        if not len(self.lines):
            return 0.0
        a = np.ascontiguousarray(fp.outline, dtype=np.float64)
        near = _edges_along(a, self.units, self.lo, self.hi, self.p0, self.p1,
                            math.sin(math.radians(AGAINST_WALL_ANGLE)), AGAINST_WALL_DISTANCE)
        if (near == _TIE).any():  # GEOS decides distances this close to the limit
            e, k = np.nonzero(near == _TIE)
            edges = shapely.linestrings(np.stack([a[e], np.roll(a, -1, axis=0)[e]], axis=1))
            near[e, k] = shapely.distance(edges, self.lines[k]) <= AGAINST_WALL_DISTANCE
        return float(_uncovered(a, near == 1, self.p0, self.p1, MIN_WALL_OVERLAP))


_TIE = 2
""":func:`_edges_along`'s mark of a segment whose distance to the edge is within 1e-9 m of the limit."""


@numba.njit(cache=True)
def _segment_distance(ax, az, bx, bz, cx, cz, dx, dz):
    """Distance (m) between segments ab and cd: 0 when they cross, else the least of the four end-to-segment ones."""
    o1 = (bx - ax) * (cz - az) - (bz - az) * (cx - ax)
    o2 = (bx - ax) * (dz - az) - (bz - az) * (dx - ax)
    o3 = (dx - cx) * (az - cz) - (dz - cz) * (ax - cx)
    o4 = (dx - cx) * (bz - cz) - (dz - cz) * (bx - cx)
    if o1 * o2 < 0.0 and o3 * o4 < 0.0:
        return 0.0
    return min(min(_point_segment(ax, az, cx, cz, dx, dz), _point_segment(bx, bz, cx, cz, dx, dz)),
               min(_point_segment(cx, cz, ax, az, bx, bz), _point_segment(dx, dz, ax, az, bx, bz)))


@numba.njit(cache=True)
def _point_segment(px, pz, ax, az, bx, bz):
    """Distance (m) from point p to segment ab."""
    ux, uz = bx - ax, bz - az
    len2 = ux * ux + uz * uz
    t = 0.0 if len2 == 0.0 else min(1.0, max(0.0, ((px - ax) * ux + (pz - az) * uz) / len2))
    return math.hypot(px - (ax + t * ux), pz - (az + t * uz))


@numba.njit(cache=True)
def _segments_near(ax, az, bx, bz, lo, hi, p0, p1, reach):
    """int8 (segments,): 1 where a blocking segment lies within ``reach`` m of the segment ab, 0 where it does not,
    _TIE where its distance is within 1e-9 m of ``reach``."""
    m = p0.shape[0]
    out = np.zeros(m, dtype=np.int8)
    for k in range(m):
        gx = max(max(lo[k, 0] - max(ax, bx), min(ax, bx) - hi[k, 0]), 0.0)
        gz = max(max(lo[k, 1] - max(az, bz), min(az, bz) - hi[k, 1]), 0.0)
        if math.hypot(gx, gz) > reach + 1e-9:  # its bounding box is already farther
            continue
        d = _segment_distance(ax, az, bx, bz, p0[k, 0], p0[k, 1], p1[k, 0], p1[k, 1])
        out[k] = _TIE if abs(d - reach) <= 1e-9 else (1 if d <= reach else 0)
    return out


@numba.njit(cache=True)
def _edges_along(a, units, lo, hi, p0, p1, max_sin, reach):
    """int8 (edges, segments): 1 where a blocking segment runs along an outline edge (parallel within ``max_sin``
    and within ``reach`` m), 0 where it does not, _TIE where its distance is within 1e-9 m of ``reach``.

    Edge e runs from vertex e to the next; an edge shorter than 1e-6 m runs along nothing.
    """
    n, m = a.shape[0], p0.shape[0]
    out = np.zeros((n, m), dtype=np.int8)
    for e in range(n):
        ax, az = a[e, 0], a[e, 1]
        bx, bz = a[(e + 1) % n, 0], a[(e + 1) % n, 1]
        le = math.sqrt((bx - ax) * (bx - ax) + (bz - az) * (bz - az))
        if le < 1e-6:
            continue
        ux, uz = (bx - ax) / le, (bz - az) / le
        for k in range(m):
            if abs(units[k, 0] * uz - units[k, 1] * ux) > max_sin:
                continue
            gx = max(max(lo[k, 0] - max(ax, bx), min(ax, bx) - hi[k, 0]), 0.0)
            gz = max(max(lo[k, 1] - max(az, bz), min(az, bz) - hi[k, 1]), 0.0)
            if math.hypot(gx, gz) > reach + 1e-9:  # its bounding box is already farther
                continue
            d = _segment_distance(ax, az, bx, bz, p0[k, 0], p0[k, 1], p1[k, 0], p1[k, 1])
            out[e, k] = _TIE if abs(d - reach) <= 1e-9 else (1 if d <= reach else 0)
    return out


@numba.njit(cache=True)
def _uncovered(a, near, p0, p1, min_overlap):
    """The longest part (m) of an outline edge that the segments ``near`` it (bool (edges, segments)) leave
    uncovered, projected onto the edge, over the edges they cover at least ``min_overlap`` of (0 when none does)."""
    n, m = near.shape
    worst = 0.0
    spans = np.empty((m, 2))
    for e in range(n):
        ax, az = a[e, 0], a[e, 1]
        bx, bz = a[(e + 1) % n, 0], a[(e + 1) % n, 1]
        le = math.sqrt((bx - ax) * (bx - ax) + (bz - az) * (bz - az))
        if le < 1e-6:  # runs along nothing (as in _edges_along)
            continue
        ux, uz = (bx - ax) / le, (bz - az) / le
        count = 0
        for k in range(m):
            if not near[e, k]:
                continue
            t0 = (p0[k, 0] - ax) * ux + (p0[k, 1] - az) * uz
            t1 = (p1[k, 0] - ax) * ux + (p1[k, 1] - az) * uz
            s0, s1 = min(max(min(t0, t1), 0.0), le), min(max(max(t0, t1), 0.0), le)
            j = count  # insertion sort by start, then end
            while j > 0 and (spans[j - 1, 0] > s0 or (spans[j - 1, 0] == s0 and spans[j - 1, 1] > s1)):
                spans[j] = spans[j - 1]
                j -= 1
            spans[j, 0], spans[j, 1] = s0, s1
            count += 1
        if count == 0:
            continue
        covered, end = 0.0, 0.0
        for j in range(count):
            s0, s1 = spans[j, 0], spans[j, 1]
            if s1 > end:
                covered += s1 - max(s0, end)
                end = s1
        if covered >= min_overlap:
            worst = max(worst, le - covered)
    return worst


@dataclass(frozen=True)
class WindowZone:
    """A window's floor zone (its width by WINDOW_DEPTH m on each side) and the height a tall object reaches."""

    zone: ApproachZone
    tall_from: float
    """Objects whose top is above this height (m) block the window."""


def window_zones(house: House, geometry: SceneGeometry) -> list[WindowZone]:
    """The zone in front of every window of the house, with the height above which an object blocks it."""
    holes = {w.id: [v.y for v in w.holePolygon] for w in house.windows}
    out = []
    for w in geometry.windows:
        ys = holes.get(w.id)
        p0, p1 = np.array(w.p0, dtype=float), np.array(w.p1, dtype=float)
        width = float(np.linalg.norm(p1 - p0))
        if not ys or width < 1e-6:
            continue
        sill, top = min(ys), max(ys)
        zone = shapely.LineString([w.p0, w.p1]).buffer(WINDOW_DEPTH, cap_style="flat")
        out.append(WindowZone(ApproachZone(w.id, p0, (p1 - p0) / width, width, zone), sill + WINDOW_COVER * (top - sill)))
    return out


def opening_zones(geometry: SceneGeometry) -> list[ApproachZone]:
    """The clearance of every open connection between two rooms (an ``empty`` wall), OPENING_CLEARANCE m per side."""
    out = []
    for w in geometry.walls:
        p0, p1 = np.array(w.p0, dtype=float), np.array(w.p1, dtype=float)
        width = float(np.linalg.norm(p1 - p0))
        if not w.empty or len(set(w.rooms)) < 2 or width < 1e-6:
            continue
        zone = shapely.LineString([w.p0, w.p1]).buffer(OPENING_CLEARANCE, cap_style="flat")
        out.append(ApproachZone(w.wall_ids[0], p0, (p1 - p0) / width, width, zone))
    return out


def _offset(anchor: tuple[tuple[float, float], float], member: tuple[float, float], turn: float = 0.0) -> np.ndarray:
    """The member's centre in the anchor's frame (anchor = (centre, yaw); ``turn`` added to the anchor's yaw)."""
    ux, uz = yaw_axes(anchor[1] + turn)
    v = np.array(member) - np.array(anchor[0])
    return np.array([float(v @ ux), float(v @ uz)])


def _window_cover(w: WindowZone, fp: Footprint) -> float:
    """Width (m) of the window a tall footprint covers within the window's zone (0 for a low one)."""
    if fp.height <= w.tall_from or _apart(fp.bounds, w.zone.bounds) or not w.zone.zone.intersects(fp.polygon):
        return 0.0
    return covered_width(w.zone, [fp.polygon])


def _apart(a: tuple[float, ...], b: tuple[float, ...], gap: float = 0.0) -> bool:
    """Whether two (min x, min z, max x, max z) boxes lie more than ``gap`` m apart along x or z (then nothing
    inside one comes within ``gap`` of anything inside the other)."""
    return a[0] - b[2] > gap or b[0] - a[2] > gap or a[1] - b[3] > gap or b[1] - a[3] > gap


def _on_open_floor(fp: Footprint, walls: _Walls, others: list[Footprint]) -> bool:
    if walls.distance(fp) <= OPEN_FLOOR:
        return False
    box, gap = fp.bounds, OPEN_FLOOR + 1e-9
    polys = [o.polygon for o in others if o.object_id != fp.object_id and not _apart(box, o.bounds, gap)]
    return not polys or not bool(shapely.dwithin(fp.polygon, polys, OPEN_FLOOR).any())


def _faces(a: Footprint, b: Footprint) -> float:
    """Cosine between a's heading and the direction from a's centre to b's (in Python floats, with the arithmetic
    of numpy's norm and dot of two 2-vectors)."""
    vx, vz = b.center[0] - a.center[0], b.center[1] - a.center[1]
    n = math.sqrt(vx * vx + vz * vz)
    if n <= 1e-9:
        return 1.0
    yaw = math.radians(a.yaw)  # heading(a.yaw) is (sin, cos) of it
    return math.sin(yaw) * (vx / n) + math.cos(yaw) * (vz / n)


@dataclass(frozen=True)
class PlausibilityReference:
    """What the rules read from the house before editing (built once; every candidate is checked against it)."""

    poses: dict[str, tuple[tuple[float, float], float]]
    types: dict[str, str]
    anchored: frozenset[str]
    """Edge-only objects that stood against a wall."""
    small: frozenset[str]
    """Small objects of types never placed in the middle that did not stand on open floor."""
    groups: tuple[tuple[str, str, str, float], ...]
    """(anchor id, member id, group name, distance m) of the asset groups found."""
    facing: tuple[tuple[str, str], ...]
    """(a, b): a faced b."""
    zones: tuple[ApproachZone, ...]
    zone_area: dict[tuple[str, str], float]
    """(door id, object id) -> area (m^2) of the object inside the door's zone, where positive."""
    walls: _Walls = field(repr=False)
    overhang: dict[str, float] = field(default_factory=dict)
    """Object id -> :meth:`_Walls.overhang` where it stood, where positive."""
    openings: tuple[ApproachZone, ...] = ()
    opening_area: dict[tuple[str, str], float] = field(default_factory=dict)
    """(open wall id, object id) -> area (m^2) of the object inside the opening's zone, where positive."""
    windows: tuple[WindowZone, ...] = ()
    window_cover: dict[tuple[str, str], float] = field(default_factory=dict)
    """(window id, object id) -> width (m) of the window the object covered, where positive."""
    model: PlacementModel | None = None
    """The placement model the ``unlike_reference`` rule reads (None: that rule is off)."""
    layout: HouseLayout | None = field(default=None, repr=False)
    features: dict[str, dict[str, float]] = field(default_factory=dict, repr=False)
    """Object id -> its placement-model features where it stood."""
    classes: dict[str, str] = field(default_factory=dict)
    """Object type -> its placement class (:func:`~adaptenv.adapt.placement_model.placement_class`)."""

    @classmethod
    def of(cls, house: House, catalog: AssetCatalog | None = None, geometry: SceneGeometry | None = None,
           model: PlacementModel | None = None) -> PlausibilityReference:
        """``model``: the placement model of ``unlike_reference`` (the shipped procedural reference when None)."""
        catalog = catalog or load_catalog()
        model = model or default_model()
        geometry = geometry or SceneGeometry.from_house(house, catalog)
        floor = [f for f in geometry.floor_objects]
        walls = _Walls.of(geometry)
        room = {f.object_id: geometry.room_of_point(*f.center) for f in floor}
        anchored = frozenset(f.object_id for f in floor if edge_only(catalog, f.object_type) and walls.against(f))
        small = frozenset(f.object_id for f in floor if _small(catalog, f) and not _on_open_floor(f, walls, floor))
        groups, facing = [], []
        for a in floor:
            for m in floor:
                if a is m or room[a.object_id] is None or room[a.object_id] != room[m.object_id]:
                    continue
                name = next((g for at, mt, g in group_pairs() if (at, mt) == (a.object_type, m.object_type)), None)
                if name is not None:
                    d = float(shapely.distance(a.polygon, m.polygon))
                    if d <= GROUP_DISTANCE:
                        groups.append((a.object_id, m.object_id, name, d))
                if m.object_type in FACING.get(a.object_type, ()) and _faces(a, m) >= FACING_BEFORE:
                    facing.append((a.object_id, m.object_id))
        zones = tuple(approach_zones(geometry, DOOR_CLEARANCE))
        areas = {(z.door_id, f.object_id): z.zone.intersection(f.polygon).area for z in zones for f in floor
                 if z.zone.intersects(f.polygon)}
        openings = tuple(opening_zones(geometry))
        opening_area = {(z.door_id, f.object_id): z.zone.intersection(f.polygon).area for z in openings
                        for f in floor if z.zone.intersects(f.polygon)}
        windows = tuple(window_zones(house, geometry))
        cover = {(w.zone.door_id, f.object_id): _window_cover(w, f) for w in windows for f in floor}
        overhang = {f.object_id: walls.overhang(f) for f in floor}
        layout = HouseLayout.of(geometry)
        by_id = {f.object_id: f for f in floor}
        features = {f.object_id: object_features(layout, f, by_id) for f in floor if f.movable}
        classes = {f.object_type: placement_class(catalog, f.object_type) for f in floor}
        return cls({f.object_id: (f.center, f.yaw) for f in floor}, {f.object_id: f.object_type for f in floor},
                   anchored, small, tuple(groups), tuple(facing), zones,
                   {k: v for k, v in areas.items() if v > 0.0}, walls,
                   {k: v for k, v in overhang.items() if v > 0.0}, openings,
                   {k: v for k, v in opening_area.items() if v > 0.0}, windows,
                   {k: v for k, v in cover.items() if v > 0.0}, model, layout, features, classes)

    def moved(self, fp: Footprint) -> bool:
        """Whether a footprint stands elsewhere (or turned) compared with the original house."""
        before = self.poses.get(fp.object_id)
        if before is None:
            return True
        (x, z), yaw = before
        if fp.yaw == yaw and fp.center == (x, z):  # most objects never moved
            return False
        dyaw = abs((fp.yaw - yaw + 180.0) % 360.0 - 180.0)
        return math.hypot(fp.center[0] - x, fp.center[1] - z) > 1e-6 or dyaw > 1e-6


def check_move(ref: PlausibilityReference, fp: Footprint, current: Mapping[str, Footprint]) -> list[Violation]:
    """The rules ``fp`` (an object at its new pose) breaks, with every other object where ``current`` has it."""
    return list(_violations(ref, fp, current))


def breaks_rules(ref: PlausibilityReference, fp: Footprint, current: Mapping[str, Footprint]) -> bool:
    """Whether ``fp`` breaks any rule :func:`check_move` checks (it stops at the first one)."""
    return next(_violations(ref, fp, current), None) is not None


def _violations(ref: PlausibilityReference, fp: Footprint, current: Mapping[str, Footprint]) -> Iterator[Violation]:
    """:func:`check_move`'s violations one at a time, in its order."""
    oid = fp.object_id
    now = dict(current)
    now[oid] = fp
    if oid in ref.anchored and not ref.walls.against(fp):
        yield Violation("edge_off_wall", oid, f"{oid} ({fp.object_type}) no longer stands with its back to a "
                        "wall facing the room; its type stands only along walls")
    for door_id, grew in _zone_growth(ref.zones, ref.zone_area, fp):
        yield Violation("door_approach", oid, f"{oid} moves {grew:.2f} m^2 further into the "
                        f"{DOOR_CLEARANCE:g} m clearance in front of doorway {door_id}", (door_id,))
    for a, m, name, d0 in ref.groups:
        if oid not in (a, m) or a not in now or m not in now:
            continue
        d = float(shapely.distance(now[a].polygon, now[m].polygon))
        if d > max(GROUP_DISTANCE, d0 + 0.05):
            other = m if oid == a else a
            yield Violation("group_split", oid, f"{oid} ends {d:.2f} m from {other}, its {name} group "
                            "partner; move the group together or keep them side by side", (other,))
    for a, b in ref.facing:
        if oid in (a, b) and a in now and b in now and _faces(now[a], now[b]) < FACING_AFTER:
            yield Violation("facing_broken", oid, f"{a} no longer faces {b}", (b if oid == a else a,))
    yield from _person_rules(ref, fp, now)
    yield from _learned_rules(ref, fp, now)
    floor = None
    for k in sorted({oid} | {s for s in ref.small if s in now and s != oid and ref.moved(now[s])}):
        if k not in ref.small:
            continue
        floor = floor or [f for f in now.values() if f.role == "floor"]
        if _on_open_floor(now[k], ref.walls, floor):
            yield Violation("open_floor", k, f"{k} ({now[k].object_type}) stands alone on open floor; its "
                            "type stands by a wall or by furniture, never in the middle of a room")


def _zone_growth(zones, before: Mapping[tuple[str, str], float], fp: Footprint) -> list[tuple[str, float]]:
    """(door id, m^2) for each zone ``fp`` now covers more of than the object did in the reference house."""
    out = []
    for z in zones:
        if not _apart(fp.bounds, z.bounds) and z.zone.intersects(fp.polygon):
            grew = z.zone.intersection(fp.polygon).area - before.get((z.door_id, fp.object_id), 0.0)
            if grew > ZONE_EPS:
                out.append((z.door_id, grew))
    return out


def _person_rules(ref: PlausibilityReference, fp: Footprint, now: Mapping[str, Footprint]) -> Iterator[Violation]:
    """What a person sees at once: an overhang past a wall's end, furniture in an open connection, a group left
    behind by its anchor, a tall object in front of a window."""
    oid = fp.object_id
    over = ref.walls.overhang(fp)
    if over > OVERHANG and over > ref.overhang.get(oid, 0.0) + 0.05:
        yield Violation("wall_overhang", oid, f"{oid} ({fp.object_type}) runs {over:.2f} m past the end of the "
                        "wall it stands along; keep it along the wall")
    for door_id, grew in _zone_growth(ref.openings, ref.opening_area, fp):
        yield Violation("in_opening", oid, f"{oid} ({fp.object_type}) moves {grew:.2f} m^2 further into the "
                        f"open connection {door_id} between two rooms ({OPENING_CLEARANCE:g} m each side)",
                        (door_id,))
    for a, m, name, _ in ref.groups:
        if oid not in (a, m) or a not in now or m not in now or not ref.moved(now[a]):
            continue
        was = _offset(ref.poses[a], ref.poses[m][0])
        turns = (0.0, 180.0) if now[a].shape is None else (0.0,)
        shift = min(float(np.linalg.norm(_offset((now[a].center, now[a].yaw), now[m].center, t) - was)) for t in turns)
        if shift > GROUP_SHIFT:
            yield Violation("group_left_behind", oid, f"{m} ({ref.types.get(m, '?')}) stands {shift:.2f} m from "
                            f"where it stood beside {a} ({ref.types.get(a, '?')}), its {name} group anchor, which "
                            "moved; a group moves together", (m if oid == a else a,))
    for w in ref.windows:
        cover = _window_cover(w, fp)
        if cover > ref.window_cover.get((w.zone.door_id, oid), 0.0) + WINDOW_EPS:
            yield Violation("blocks_window", oid, f"{oid} ({fp.object_type}, {fp.height:.2f} m tall) stands in "
                            f"front of window {w.zone.door_id}, covering {cover:.2f} of its {w.zone.width:.2f} m",
                            (w.zone.door_id,))


def _learned_rules(ref: PlausibilityReference, fp: Footprint, now: Mapping[str, Footprint]) -> Iterator[Violation]:
    """``unlike_reference``: a feature of the moved object, or of another moved object of its room (old or new) that
    the move changes (its anchor, its nearest neighbour), outside the placement model's central 98% and further
    out than where it stood."""
    if ref.model is None or ref.layout is None:
        return
    oid = fp.object_id
    rooms = {ref.layout.room_at(*fp.center)}
    if oid in ref.poses:
        rooms.add(ref.layout.room_at(*ref.poses[oid][0]))
    for k in [oid, *sorted(k for k in ref.features if k != oid and k in now and ref.moved(now[k]))]:
        f = now[k]
        if k != oid and ref.layout.room_at(*f.center) not in rooms:
            continue
        for u in unlike(ref.model, ref.classes.get(f.object_type, "edge"), f.object_type,
                        object_features(ref.layout, f, now), ref.features.get(k)):
            yield Violation("unlike_reference", k, u.message(k, f.object_type), feature=u.feature)


@dataclass
class PlausibilityAudit:
    """The violations of an adapted house against its original, per moved object."""

    moved: list[str]
    violations: list[Violation]

    def counts(self) -> dict[str, int]:
        """Violations per rule (every rule listed, 0 when none)."""
        c = Counter(v.rule for v in self.violations)
        return {r: c.get(r, 0) for r in RULES}

    @property
    def total(self) -> int:
        return len(self.violations)


def audit(original: House, adapted: House, *, catalog: AssetCatalog | None = None,
          model: PlacementModel | None = None) -> PlausibilityAudit:
    """Check every floor object of ``adapted`` that moved against ``original`` (the house before editing);
    ``model``: the placement model of ``unlike_reference`` (the shipped procedural reference when None)."""
    catalog = catalog or load_catalog()
    ref = PlausibilityReference.of(original, catalog, model=model)
    geometry = SceneGeometry.from_house(adapted, catalog)
    now = {f.object_id: f for f in geometry.floor_objects}
    missing = sorted(set(ref.poses) - set(now))
    if missing:
        raise AdaptenvError(f"the adapted house has no floor object {missing[0]!r} of the original; audit a house "
                            "against the one it was adapted from")
    moved = [oid for oid, f in now.items() if ref.moved(f)]
    seen: set[tuple[str, str, tuple[str, ...], str]] = set()
    violations = []
    for oid in moved:
        for v in check_move(ref, now[oid], now):
            key = (v.rule, v.object_id, v.others, v.feature)
            if key not in seen and v.object_id in moved:
                seen.add(key)
                violations.append(v)
    return PlausibilityAudit(moved, violations)
