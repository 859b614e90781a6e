"""The validation module: physical consistency and task feasibility of an edited scene.

:func:`validate_scene` is a pure function returning every problem (never raising on the first):

- ``outside_room`` / ``crosses_wall``: a floor footprint sticks out of the rooms or through a
  blocking wall (a tolerance of :data:`~adaptenv.scene.validate.PLACEMENT_TOLERANCE` m);
- ``overlap`` / ``overlap_grew``: two floor footprints overlap (area above :data:`AREA_EPS`)
  where they did not in ``original``, or a pre-existing overlap (chairs under a table) grew past
  :func:`~adaptenv.adapt.placement.allowed_overlap`;
- ``start_blocked``: the agent disc (``spec.AGENT_RADIUS``) does not fit at the start;
- ``room_unreachable`` / ``doorway_blocked``: a room, or a doorway's threshold, that the agent
  could reach from the start in ``original`` no longer can (navigable = clearance >= radius on
  the :mod:`adaptenv.scene.occupancy` raster, 4-connected);
- ``target_unreachable``: a target type's success region (``sim.geodesic``) is no longer
  reachable from the start (the start's geodesic distance is infinite);
- ``doorway_approach``: furniture covers more of a doorway's approach zone than
  :data:`~adaptenv.adapt.doorways.MAX_APPROACH_COVER` of its width, and more than in ``original``
  (:mod:`adaptenv.adapt.doorways`; ProcTHOR keeps these clearances free when it furnishes a house).

Without ``original`` the house is compared with itself: every room, passable doorway and target
type present must be reachable, and only the ProcTHOR pattern of seats tucked under tables (or
against each other) may overlap.

:class:`EditValidator` is the fast path the generators use: placement plus an incremental raster
(only the moved object's inflated footprint is re-drawn) and one connected-component labelling
per candidate, and the plausibility rules of :mod:`adaptenv.adapt.plausibility` on the moved object
(``implausible``: an edge-only object off its wall, furniture in a door's clearance, a group split, a
small object alone on open floor, a seat turned from its television, an object running past the end of
its wall, furniture in an open connection, a group left behind by its table, tall furniture in front of a
window; the rule's name starts the message). Objects of the episode's target types do not move (``target_moved``) unless
``move_targets``. Target types its cached success regions cannot prove reachable are decided exactly on
incrementally kept label and occluder grids (:class:`LabelRaster`, no world compiled; the slow
:func:`reference_target_problems` is the plain version tests compare with). Its public interface is
three methods: ``propose`` (a dry run returning a
:class:`Proposal`: the placement result and every problem, the scene unchanged), ``commit`` (apply
a proposal without problems; log it either way as an :class:`~adaptenv.adapt.edits.Edit`) and
``try_edit`` (both in one call).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
import shapely
from PIL import Image, ImageDraw
from scipy import ndimage

from adaptenv.adapt.doorways import approach_zones, blocked_approaches, covered_width
from adaptenv.adapt.edits import Edit, EditLog
from adaptenv.adapt.placement import (
    DEFAULT_STEP,
    PlacementContext,
    PlacementResult,
    allowed_overlap,
    place_units,
)
from adaptenv.adapt.placement_model import PlacementModel
from adaptenv.adapt.plausibility import PlausibilityReference, check_move
from adaptenv.errors import AdaptenvError
from adaptenv.scene.assets import AssetCatalog, load_catalog
from adaptenv.scene.geometry import Footprint, SceneGeometry, footprint_corners
from adaptenv.scene.house import House, is_interior_leaf_door, move_object, set_door_openness
from adaptenv.scene.occupancy import (
    DEFAULT_RESOLUTION,
    LABEL_DOOR,
    LABEL_FREE,
    LABEL_OBJECT0,
    LABEL_OUTSIDE,
    LABEL_WALL,
    LABEL_WINDOW,
    OccupancyGrid,
    rasterize,
)
from adaptenv.sim.geodesic import first_region_cell, geodesic_distance, success_region
from adaptenv.sim.spec import AGENT_RADIUS, SUCCESS_DISTANCE, TARGET_TYPES
from adaptenv.sim.task import sample_points
from adaptenv.sim.world import NavWorld, compile_world, occluding_labels
from adaptenv.vocabulary import SEAT_TYPES, TABLE_TYPES

#: Overlaps smaller than this (m^2) are touching, not overlapping.
AREA_EPS = 1e-4
#: How far (m) a footprint may stick out of its rooms or through a wall.
CONTAIN_TOLERANCE = 0.01

ProblemKind = Literal["invalid", "outside_room", "crosses_wall", "overlap", "overlap_grew", "start_blocked", "no_start",
                      "room_unreachable", "doorway_blocked", "target_unreachable", "doorway_approach",
                      "implausible", "target_moved"]


@dataclass(frozen=True)
class ValidationProblem:
    """One reason an edited scene is not acceptable."""

    kind: ProblemKind
    message: str
    object_ids: tuple[str, ...] = ()
    rule: str = ""
    """The plausibility rule broken (``implausible`` problems only)."""

    def __str__(self) -> str:
        return self.message


Start = tuple[float, float] | tuple[float, float, float]


# --------------------------------------------------------------------------- raster helpers

def disc_offsets(radius: float, resolution: float) -> np.ndarray:
    """bool (2R+1, 2R+1): cells whose blocked state makes the centre cell non-navigable.

    Matches :mod:`adaptenv.scene.occupancy`: clearance = float32(dist * res - res / 2), and a
    cell is navigable when its clearance >= radius.
    """
    r = int(math.ceil(radius / resolution + 1.0))
    di, dj = np.mgrid[-r:r + 1, -r:r + 1]
    clear = np.maximum(np.sqrt(di * di + dj * dj) * resolution - 0.5 * resolution, 0.0).astype(np.float32)
    return clear < radius


def _mask_window(corners: np.ndarray, x0: float, z0: float, res: float, pad: int,
                 shape: tuple[int, int]) -> tuple[int, int, np.ndarray]:
    """The footprint's raster mask in a padded window: (row0, col0, bool mask), clipped to the grid."""
    px = (corners[:, 0] - x0) / res - 0.5
    pz = (corners[:, 1] - z0) / res - 0.5
    c0 = max(int(math.floor(px.min())) - pad, 0)
    r0 = max(int(math.floor(pz.min())) - pad, 0)
    c1 = min(int(math.ceil(px.max())) + pad + 1, shape[1])
    r1 = min(int(math.ceil(pz.max())) + pad + 1, shape[0])
    w, h = max(c1 - c0, 1), max(r1 - r0, 1)
    img = Image.new("L", (w, h), 0)
    ImageDraw.Draw(img).polygon([(x - c0, z - r0) for x, z in zip(px, pz, strict=True)], fill=1, outline=1)
    return r0, c0, np.asarray(img, dtype=bool)


@dataclass
class _Inflated:
    """An object's inflated footprint: the cells where it makes the agent disc not fit."""

    r0: int
    c0: int
    mask: np.ndarray
    drawn: np.ndarray | None = None
    """The footprint's own cells in the same window (before inflating), when known."""


class NavRaster:
    """Incremental navigability: a per-cell count of obstacles whose inflated footprint covers the cell.

    ``count == 0`` is exactly ``rasterize(geometry).navigable(radius)``; moving one object only
    re-draws that object's window.
    """

    def __init__(self, geometry: SceneGeometry, *, resolution: float = DEFAULT_RESOLUTION,
                 radius: float = AGENT_RADIUS, occupancy: OccupancyGrid | None = None):
        occ = occupancy or rasterize(geometry, resolution)
        self.occupancy = occ
        self.x0, self.z0, self.res = occ.x0, occ.z0, occ.resolution
        self.shape = occ.shape
        self.radius = radius
        self.disc = disc_offsets(radius, self.res)
        self.pad = self.disc.shape[0] // 2
        static = ((occ.label >= 0) & (occ.label < LABEL_OBJECT0)) | (occ.room < 0)
        self.count = ndimage.binary_dilation(static, self.disc).astype(np.int16)
        self.ids = [f.object_id for f in geometry.floor_objects]
        self.types = [f.object_type for f in geometry.floor_objects]
        self.objects = [self.inflate(f.outline) for f in geometry.floor_objects]
        for inf in self.objects:
            self._add(inf, 1)
        self.room = occ.room

    def inflate(self, corners: np.ndarray) -> _Inflated:
        """Inflated footprint of a footprint (its outline (N, 2))."""
        r0, c0, m = _mask_window(corners, self.x0, self.z0, self.res, self.pad, self.shape)
        # Distance to the footprint's cells gives the disc dilation exactly (same rule as the raster).
        dist = ndimage.distance_transform_edt(~m) * self.res
        clear = np.maximum(dist - 0.5 * self.res, 0.0).astype(np.float32)
        return _Inflated(r0, c0, clear < self.radius, m)

    def _add(self, inf: _Inflated, sign: int, count: np.ndarray | None = None) -> None:
        count = self.count if count is None else count
        h, w = inf.mask.shape
        count[inf.r0:inf.r0 + h, inf.c0:inf.c0 + w] += sign * inf.mask

    def navigable(self) -> np.ndarray:
        return self.count == 0

    def navigable_with(self, i: int, inf: _Inflated) -> np.ndarray:
        """Navigable cells if object i had the inflated footprint ``inf`` instead of its current one."""
        count = self.count.copy()
        self._add(self.objects[i], -1, count)
        self._add(inf, 1, count)
        return count == 0

    def commit(self, i: int, inf: _Inflated) -> None:
        self._add(self.objects[i], -1)
        self._add(inf, 1)
        self.objects[i] = inf

    def cell(self, x: float, z: float) -> tuple[int, int] | None:
        col = int(math.floor((x - self.x0) / self.res))
        row = int(math.floor((z - self.z0) / self.res))
        h, w = self.shape
        return (row, col) if 0 <= row < h and 0 <= col < w else None


@dataclass(frozen=True)
class LabelWindow:
    """The label and occluder grids over a window (rows r0:r1, cols c0:c1) with one object moved."""

    r0: int
    c0: int
    label: np.ndarray
    occluder: np.ndarray
    footprint: _Inflated
    """The moved object's new raw footprint (cells it is drawn on)."""

    @property
    def box(self) -> tuple[slice, slice]:
        h, w = self.label.shape
        return slice(self.r0, self.r0 + h), slice(self.c0, self.c0 + w)


class LabelRaster:
    """Incremental label and occluder grids (``NavWorld.grid.label`` / ``NavWorld.occluder``).

    The label of a cell is its wall, door or window label when it has one; otherwise the label of the
    last floor object (highest index) drawn on it; otherwise outside (no room) or free, exactly as
    :func:`~adaptenv.scene.occupancy.rasterize` draws them. Moving one object re-labels only the
    window around its old and new footprints.
    """

    def __init__(self, occ: OccupancyGrid, floor: list[Footprint]):
        self.x0, self.z0, self.res, self.shape = occ.x0, occ.z0, occ.resolution, occ.shape
        self.static = np.isin(occ.label, (LABEL_WALL, LABEL_DOOR, LABEL_WINDOW))
        self.base = np.where(self.static, occ.label, np.where(occ.room < 0, LABEL_OUTSIDE, LABEL_FREE)).astype(np.int16)
        self.tall = occluding_labels(floor)  # as compile_world's occluder grid
        self.label = occ.label.copy()
        self.occluder = self.tall[self.label]
        self.masks = [self.footprint(f.outline) for f in floor]  # true outlines, as rasterize draws them
        self.boxes = np.array([self._box(m) for m in self.masks], dtype=np.int64).reshape(-1, 4)

    def footprint(self, corners: np.ndarray) -> _Inflated:
        """The cells a footprint (its outline (N, 2)) is drawn on."""
        return self.tight(_Inflated(*_mask_window(corners, self.x0, self.z0, self.res, 1, self.shape)))

    @staticmethod
    def tight(m: _Inflated) -> _Inflated:
        """The same cells in the smallest window holding them."""
        rows, cols = np.flatnonzero(m.mask.any(axis=1)), np.flatnonzero(m.mask.any(axis=0))
        if not len(rows):
            return _Inflated(m.r0, m.c0, m.mask[:0, :0])
        r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
        return _Inflated(m.r0 + int(r0), m.c0 + int(c0), m.mask[r0:r1, c0:c1])

    @staticmethod
    def _box(m: _Inflated) -> tuple[int, int, int, int]:
        h, w = m.mask.shape
        return m.r0, m.c0, m.r0 + h, m.c0 + w

    def window(self, i: int, new: _Inflated) -> LabelWindow:
        """Labels and occluders around object i's old and new footprints if it were drawn at ``new``."""
        a, b = self._box(self.masks[i]), self._box(new)
        r0, c0, r1, c1 = min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3])
        label = self.base[r0:r1, c0:c1].copy()
        free = ~self.static[r0:r1, c0:c1]
        bx = self.boxes
        hit = np.flatnonzero((bx[:, 0] < r1) & (bx[:, 2] > r0) & (bx[:, 1] < c1) & (bx[:, 3] > c0))
        if i not in hit:
            hit = np.sort(np.append(hit, i))
        for k in hit:  # in drawing order: a later object covers an earlier one
            m = new if k == i else self.masks[k]
            mr0, mc0, mr1, mc1 = self._box(m)
            lr0, lc0, lr1, lc1 = max(mr0, r0), max(mc0, c0), min(mr1, r1), min(mc1, c1)
            if lr0 >= lr1 or lc0 >= lc1:
                continue
            cells = m.mask[lr0 - mr0:lr1 - mr0, lc0 - mc0:lc1 - mc0] & free[lr0 - r0:lr1 - r0, lc0 - c0:lc1 - c0]
            label[lr0 - r0:lr1 - r0, lc0 - c0:lc1 - c0][cells] = LABEL_OBJECT0 + k
        return LabelWindow(r0, c0, label, self.tall[label], new)

    def quiet(self, i: int, new: _Inflated) -> bool:
        """Cheap sufficient test that moving object i to ``new`` changes no occluder: it is low, and
        neither its old nor its new footprint's window meets another object's or a cell outside the rooms."""
        if self.tall[LABEL_OBJECT0 + i]:
            return False
        bx = self.boxes
        for r0, c0, r1, c1 in (self._box(self.masks[i]), self._box(new)):
            hit = (bx[:, 0] < r1) & (bx[:, 2] > r0) & (bx[:, 1] < c1) & (bx[:, 3] > c0)
            hit[i] = False
            if hit.any() or (self.base[r0:r1, c0:c1] == LABEL_OUTSIDE).any():
                return False
        return True

    def changed_cells(self, win: LabelWindow) -> np.ndarray:
        """bool over the window: cells where some line of sight could change (occluder, or which
        object an occluding cell belongs to)."""
        occ0, lab0 = self.occluder[win.box], self.label[win.box]
        return (occ0 != win.occluder) | (occ0 & (lab0 != win.label))

    def with_window(self, win: LabelWindow) -> tuple[np.ndarray, np.ndarray]:
        """Full (label, occluder) grids with the window applied (copies; the raster is unchanged)."""
        label, occ = self.label.copy(), self.occluder.copy()
        label[win.box], occ[win.box] = win.label, win.occluder
        return label, occ

    def commit(self, i: int, win: LabelWindow) -> None:
        self.label[win.box] = win.label
        self.occluder[win.box] = win.occluder
        self.masks[i] = win.footprint
        self.boxes[i] = self._box(win.footprint)


def door_threshold_cells(geometry: SceneGeometry, occ: OccupancyGrid) -> dict[str, np.ndarray]:
    """Flat indices of the cells along each passable door's opening (where the agent crosses it)."""
    out = {}
    h, w = occ.shape
    for d in geometry.doors:
        if not d.passable:
            continue
        p0, p1 = np.array(d.p0), np.array(d.p1)
        n = max(2, int(math.ceil(np.linalg.norm(p1 - p0) / (occ.resolution / 2))) + 1)
        pts = p0 + np.linspace(0.0, 1.0, n)[:, None] * (p1 - p0)
        row, col = occ.to_cell(pts[:, 0], pts[:, 1])
        ok = occ.in_bounds(row, col)
        out[d.id] = np.unique(row[ok] * w + col[ok])
    return out


def _start_of(house: House, start: Start | None) -> tuple[float, float] | None:
    if start is not None:
        return float(start[0]), float(start[1])
    pose = house.agent_pose()
    return None if pose is None else (pose[0], pose[1])


# --------------------------------------------------------------------------- reachability

@dataclass
class Reachability:
    """What the agent can reach from the start: rooms, doorways and target types."""

    start_free: bool
    rooms: set[str] = field(default_factory=set)
    doors: set[str] = field(default_factory=set)
    targets: set[str] = field(default_factory=set)


def _reachable(nav: np.ndarray, start_cell: tuple[int, int] | None, room: np.ndarray, room_ids: tuple[str, ...],
               doors: dict[str, np.ndarray]) -> tuple[Reachability, np.ndarray | None]:
    """Rooms and doorways in the start's 4-connected navigable component (and that component)."""
    if start_cell is None or not nav[start_cell]:
        return Reachability(False), None
    labels, _ = ndimage.label(nav)
    comp = labels == labels[start_cell]
    hit = np.unique(room[comp])
    rooms = {room_ids[k] for k in hit if k >= 0}
    flat = comp.ravel()
    door_ok = {d for d, idx in doors.items() if len(idx) and flat[idx].any()}
    return Reachability(True, rooms, door_ok), comp


def _world_reaches(world: NavWorld, target_type: str, start: tuple[float, float]) -> bool:
    """Whether the target type's success region is reachable from the start (finite geodesic distance)."""
    return bool(world.instances_of(target_type)) and math.isfinite(geodesic_distance(world, target_type, *start))


def _geodesic_targets(house: House, geometry: SceneGeometry, start: tuple[float, float],
                      types: list[str], world: NavWorld | None = None) -> set[str]:
    """Target types whose success region is reachable from the start (finite geodesic distance); ``world``: the
    house's compiled world, used when it fits ``geometry`` (:func:`world_fits`)."""
    world = world if world_fits(world, geometry) else compile_world(house, geometry=geometry)
    return {t for t in types if _world_reaches(world, t, start)}


def world_fits(world: NavWorld | None, geometry: SceneGeometry) -> bool:
    """Whether ``world`` is a compiled world of ``geometry`` at the default resolution: the same footprints, walls,
    doors, windows and rooms (a world handed in to save compiling the house again, checked before it is trusted)."""
    if world is None or world.grid.resolution != DEFAULT_RESOLUTION:
        return False
    g = world.geometry
    return g is geometry or (g.footprints == geometry.footprints and g.walls == geometry.walls
                             and g.doors == geometry.doors and g.windows == geometry.windows
                             and g.rooms == geometry.rooms)


def _default_targets(geometry: SceneGeometry) -> list[str]:
    present = {f.object_type for f in geometry.floor_objects}
    return [t for t in TARGET_TYPES if t in present]


def scene_reachability(house: House, *, start: Start | None = None, targets: list[str] | None = None,
                       geometry: SceneGeometry | None = None, world: NavWorld | None = None) -> Reachability:
    """Rooms, doorways and target types reachable from the start of a house (the validation baseline);
    ``world``: the house's compiled world, used instead of rasterizing it again when it fits."""
    geometry = geometry or SceneGeometry.from_house(house)
    occ = world.grid if world_fits(world, geometry) else rasterize(geometry)
    s = _start_of(house, start)
    reach, _ = _reachable(occ.navigable(AGENT_RADIUS), None if s is None else _cell(occ, s), occ.room,
                          occ.room_ids, door_threshold_cells(geometry, occ))
    if reach.start_free and s is not None:
        reach.targets = _geodesic_targets(house, geometry, s, _default_targets(geometry) if targets is None else targets,
                                          world)
    return reach


def _cell(occ: OccupancyGrid, p: tuple[float, float]) -> tuple[int, int] | None:
    row, col = occ.to_cell(p[0], p[1])
    return (int(row), int(col)) if bool(occ.in_bounds(row, col)) else None


# --------------------------------------------------------------------------- validate_scene

def _doors_as_in(original: House, house: House) -> House:
    """``original`` with each door's openness as in ``house`` (``original`` itself when no door changed)."""
    now = {d.id: d.openness for d in house.doors}
    if all(now.get(d.id, d.openness) == d.openness for d in original.doors):
        return original
    out = original.model_copy(deep=True)
    for d in out.doors:
        d.openness = now.get(d.id, d.openness)
    return out


def _allowed_pair(a: str, b: str) -> bool:
    """The ProcTHOR pattern of overlaps allowed without an original: seats under tables or against seats."""
    return (a in SEAT_TYPES and (b in SEAT_TYPES or b in TABLE_TYPES)) or (b in SEAT_TYPES and a in TABLE_TYPES)


def _overlaps(geometry: SceneGeometry) -> dict[tuple[str, str], float]:
    floor = geometry.floor_objects
    polys = [f.polygon for f in floor]
    tree = shapely.STRtree(polys)
    out = {}
    left, right = tree.query(polys, predicate="intersects")
    for a, b in zip(left, right, strict=True):
        if a < b:
            area = polys[a].intersection(polys[b]).area
            if area > AREA_EPS:
                key = tuple(sorted((floor[a].object_id, floor[b].object_id)))
                out[key] = area
    return out


def _containment_problems(geometry: SceneGeometry, moved: set[str] | None) -> list[ValidationProblem]:
    out = []
    floor_area = geometry.floor.buffer(CONTAIN_TOLERANCE, join_style="mitre")
    segs = geometry.blocking_segments()
    lines = shapely.linestrings(segs) if len(segs) else np.array([])
    for f in geometry.floor_objects:
        if moved is not None and f.object_id not in moved:
            continue
        if not floor_area.covers(f.polygon):
            out.append(ValidationProblem("outside_room", f"{f.object_id} sticks out of the house's rooms; "
                                         "move it back inside", (f.object_id,)))
            continue
        sx, sz = f.size
        shrunk = shapely.Polygon(footprint_corners(f.center[0], f.center[1], max(sx - 2 * CONTAIN_TOLERANCE, 1e-3),
                                                   max(sz - 2 * CONTAIN_TOLERANCE, 1e-3), f.yaw)) \
            if f.shape is None else f.polygon.buffer(-CONTAIN_TOLERANCE, join_style="mitre")  # L/C counters
        if len(lines) and shapely.intersects(lines, shrunk).any():
            out.append(ValidationProblem("crosses_wall", f"{f.object_id} crosses a wall; move it into one room",
                                         (f.object_id,)))
    return out


def _approach_problems(geometry: SceneGeometry, orig_geometry: SceneGeometry) -> list[ValidationProblem]:
    """Doorway approach zones covered past the limit and more than in the original scene."""
    before = {z.door_id: covered_width(z, [f.polygon for f in orig_geometry.floor_objects])
              for z in approach_zones(orig_geometry)}
    polys = {f.object_id: f.polygon for f in geometry.floor_objects}
    return [ValidationProblem("doorway_approach", f"{', '.join(ids)} cover {cover:.2f} of the {width:.2f} m in front "
                              f"of doorway {d}; keep at least half of a doorway's approach clear", (d, *ids))
            for d, cover, width, ids in blocked_approaches(approach_zones(geometry), polys, before)]


def validate_scene(house: House, *, episode_targets: list[str] | None = None, start: Start | None = None,
                   original: House | None = None, catalog: AssetCatalog | None = None, world: NavWorld | None = None,
                   original_world: NavWorld | None = None) -> list[ValidationProblem]:
    """Every physical-plausibility and task-feasibility problem of a (possibly edited) house.

    Args:
        house: the scene to check.
        episode_targets: target types that must stay reachable; default: every target type that is
            reachable in ``original`` (or present, without ``original``).
        start: the agent's start (x, z[, yaw]); default: the house's metadata pose.
        original: the scene before editing; only problems new relative to it count.
        world, original_world: the compiled worlds of ``house`` and ``original`` when the caller has them
            (each is used only when it fits its house, :func:`world_fits`; the answer is the same).

    Returns:
        The problems, empty when the scene is valid.
    """
    catalog = catalog or load_catalog()
    geometry = SceneGeometry.from_house(house, catalog)
    problems: list[ValidationProblem] = []
    moved = None
    orig_geometry = None
    if original is not None:
        orig_geometry = SceneGeometry.from_house(original, catalog)
        before = {f.object_id: (f.center, f.yaw, f.asset_id) for f in orig_geometry.floor_objects}
        moved = {f.object_id for f in geometry.floor_objects
                 if before.get(f.object_id) != (f.center, f.yaw, f.asset_id)}  # an asset swap counts as a move
    problems += _containment_problems(geometry, moved)
    if orig_geometry is not None:
        problems += _approach_problems(geometry, orig_geometry)

    types = {f.object_id: f.object_type for f in geometry.floor_objects}
    base = _overlaps(orig_geometry) if orig_geometry is not None else None
    for (a, b), area in sorted(_overlaps(geometry).items()):
        if base is None:
            if not _allowed_pair(types[a], types[b]):
                problems.append(ValidationProblem("overlap", f"{a} and {b} overlap by {area:.3f} m^2; move one "
                                                  "of them apart", (a, b)))
        elif (a, b) not in base:
            problems.append(ValidationProblem("overlap", f"{a} and {b} overlap by {area:.3f} m^2 where they did "
                                              "not before; move one of them apart", (a, b)))
        elif area > allowed_overlap(base[(a, b)]):
            problems.append(ValidationProblem("overlap_grew", f"{a} and {b} overlap by {area:.3f} m^2, up from "
                                              f"{base[(a, b)]:.3f} m^2; pull them apart", (a, b)))

    s = _start_of(house, start)
    if s is None:
        problems.append(ValidationProblem("no_start", "the house has no start pose; set one with "
                                          "House.set_agent_pose or pass start="))
        return problems
    occ = world.grid if world_fits(world, geometry) else rasterize(geometry)
    doors = door_threshold_cells(geometry, occ)
    now, _ = _reachable(occ.navigable(AGENT_RADIUS), _cell(occ, s), occ.room, occ.room_ids, doors)
    if not now.start_free:
        problems.append(ValidationProblem("start_blocked", f"the agent does not fit at its start ({s[0]:.2f}, "
                                          f"{s[1]:.2f}); move the furniture away from it"))
        return problems
    if original is not None:
        # Doors opened or shut on purpose are part of the baseline; what the original reached must stay reached.
        base = _doors_as_in(original, house)
        before = scene_reachability(original, start=start or _start_of(original, None), targets=episode_targets,
                                    geometry=orig_geometry, world=original_world)
        need = before if base is original else scene_reachability(base, start=start or _start_of(original, None),
                                                                  targets=[])
        need_targets = before.targets if episode_targets is None else set(episode_targets) & before.targets
    else:
        navr = occ.navigable(AGENT_RADIUS)
        need = Reachability(True, {occ.room_ids[k] for k in np.unique(occ.room[navr]) if k >= 0}, set(doors))
        need_targets = set(episode_targets) if episode_targets is not None else set(_default_targets(geometry))
    for r in sorted(need.rooms - now.rooms):
        problems.append(ValidationProblem("room_unreachable", f"{r} ({geometry.room_types.get(r, '?')}) can no "
                                          "longer be reached from the start; clear the way to it", (r,)))
    for d in sorted(need.doors - now.doors):
        problems.append(ValidationProblem("doorway_blocked", f"the doorway {d} is no longer passable from the "
                                          "start; move the furniture out of it", (d,)))
    reached = _geodesic_targets(house, geometry, s, sorted(need_targets), world)
    for t in sorted(need_targets - reached):
        problems.append(ValidationProblem("target_unreachable", f"no {t} can be reached and seen from the start; "
                                          "clear a path to one", (t,)))
    return problems


# --------------------------------------------------------------------------- the fast path for generators

class StaleProposalError(AdaptenvError):
    """A proposal was committed to a scene other than the one it was checked against."""


@dataclass(frozen=True, eq=False)
class Proposal:
    """A dry-run edit from :meth:`EditValidator.propose`: the request, placement, problems, and what commit needs."""

    object_id: str
    dx_units: float
    dy_units: float
    rotation: float | None
    relocate: bool
    """Whether the move is a relocation (set down at the end, possibly in another room) rather than a march."""
    result: PlacementResult
    """Where placement put the object (``result.changed`` is False when it could not move at all)."""
    problems: tuple[ValidationProblem, ...]
    """Every reason the edited scene would be invalid; empty when the edit may be committed."""
    owner: object
    version: int
    """The validator and its state (number of committed edits) the proposal was checked against."""
    center: np.ndarray | None = None
    corners: np.ndarray | None = None
    inflated: _Inflated | None = None
    """The moved object's new centre, footprint corners and inflated raster footprint (when it moved)."""
    drawn: _Inflated | None = None
    """The moved object's new footprint cells (when it moved)."""
    footprint: Footprint | None = None
    outline: np.ndarray | None = None
    """The moved object's new footprint (as ``SceneGeometry.from_house`` has it) and true outline (when it moved)."""
    labels: LabelWindow | None = None
    """The label and occluder grids around the moved object's old and new footprints (when they were needed)."""
    exact_targets: frozenset[str] = frozenset()
    """The target types the cached success regions could not prove reachable (decided exactly)."""
    witnesses: tuple[tuple[str, int], ...] = ()
    """For each of those found reachable: a success-region cell (flat index) in the start's component."""

    @property
    def valid(self) -> bool:
        """Whether :meth:`EditValidator.commit` would apply it (no problems)."""
        return not self.problems


class EditValidator:
    """Try edits on a scene: place, validate incrementally, keep valid ones, log all.

    Example:
        >>> v = EditValidator(house, episode_targets=["Bed"])  # doctest: +SKIP
        >>> edit = v.try_edit("Chair|3|0|1", 20, 5, source="random")  # doctest: +SKIP
        >>> edit.accepted, edit.stop_reason, v.house  # doctest: +SKIP
        >>> p = v.propose("Chair|3|0|1", -10, 0)  # dry run: v.house is unchanged  # doctest: +SKIP
        >>> if p.valid: v.commit(p, source="search")  # doctest: +SKIP
    """

    def __init__(self, house: House, *, episode_targets: list[str] | None = None, start: Start | None = None,
                 original: House | None = None, step: float = DEFAULT_STEP, catalog: AssetCatalog | None = None,
                 copy: bool = True, plausibility: bool = True, move_targets: bool = False,
                 world: NavWorld | None = None, placement_model: PlacementModel | None = None):
        """``plausibility``: check the moved object against :mod:`adaptenv.adapt.plausibility` (off only for the
        random baselines); ``move_targets``: let objects of ``episode_targets``' types move (edits that relocate
        the target opt in); ``world``: the compiled world of ``house``, used instead of compiling it again when it
        fits (:func:`world_fits`); ``placement_model``: the reference of the ``unlike_reference`` rule (the shipped
        one when None)."""
        self._settings = dict(episode_targets=episode_targets, step=step, catalog=catalog, plausibility=plausibility,
                              move_targets=move_targets, placement_model=placement_model)
        self.catalog = catalog or load_catalog()
        self.house = house.model_copy(deep=True) if copy else house
        self.step = step
        self.geometry = SceneGeometry.from_house(self.house, self.catalog)
        self.ctx = PlacementContext.from_house(self.house, original=original, catalog=self.catalog,
                                               geometry=self.geometry)
        world = world if world_fits(world, self.geometry) else None
        self.raster = NavRaster(self.geometry, occupancy=world.grid if world is not None else None)
        occ = self.raster.occupancy
        self.labels = LabelRaster(occ, self.geometry.floor_objects)
        self._slot = {f.object_id: k for k, f in enumerate(self.geometry.footprints)}
        self._points: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._candidate_points: dict[tuple[int, bytes], tuple[np.ndarray, np.ndarray]] = {}
        self.room_ids = occ.room_ids
        self.doors = door_threshold_cells(self.geometry, occ)
        self.start = _start_of(self.house, start) if original is None else _start_of(original, start)
        self.start_cell = None if self.start is None else _cell(occ, self.start)
        base_house, base_geometry = (original, None) if original is not None else (self.house, self.geometry)
        need = scene_reachability(base_house, start=self.start, targets=episode_targets, geometry=base_geometry,
                                  world=world if original is None else None)
        if original is not None and (doored := _doors_as_in(original, self.house)) is not original:
            # doors opened or shut since the original: rooms and doorways are judged with them as they are now
            now = scene_reachability(doored, start=self.start, targets=[])
            need = replace(need, rooms=now.rooms, doors=now.doors)
        self.need_rooms = need.rooms
        self.need_doors = need.doors & set(self.doors)
        self.approach = approach_zones(self.geometry)
        self._approach_bounds = np.array([z.zone.bounds for z in self.approach], dtype=float).reshape(-1, 4)
        self._polygons: list[shapely.Polygon | None] = [None] * len(self.ctx.ids)  # of ctx.outlines, built when asked
        base = SceneGeometry.from_house(original, self.catalog) if original is not None else self.geometry
        self.approach_before = {z.door_id: covered_width(z, [f.polygon for f in base.floor_objects])
                                for z in approach_zones(base)}
        self.plausible = PlausibilityReference.of(original or self.house, self.catalog, base, placement_model) \
            if plausibility else None
        self.fixed_types = frozenset() if move_targets else frozenset(episode_targets or ())
        self.need_targets = need.targets if episode_targets is None else set(episode_targets) & need.targets
        self.tall = np.array([f.occludes for f in self.geometry.floor_objects], dtype=bool)
        self.of_type: dict[str, list[int]] = {}
        for k, ty in enumerate(self.raster.types):
            self.of_type.setdefault(ty, []).append(k)
        self.regions: dict[str, np.ndarray | None] = {}
        if self.start_cell is not None:
            self._refresh_regions(world or compile_world(self.house, geometry=self.geometry))
        self.objects = {obj.id: obj for obj in self.house.objects}
        self.log = EditLog()
        self._witness: dict[str, int] = {}
        self._target_witness: dict[str, np.ndarray] = {}  # per type: one cell of its cached region
        self._owner = object()  # proposals remember which validator, and which of its states, they were made on
        self._version = 0

    def _refresh_regions(self, world: NavWorld, types: set[str] | None = None) -> None:
        """Cache each needed target type's success region (flat indices) from an exactly compiled world."""
        for t in types if types is not None else self.need_targets:
            if not world.instances_of(t):
                self.regions[t] = None
                continue
            self.regions[t] = self._region_array(np.flatnonzero(success_region(world, t)))

    def _region_array(self, idx: np.ndarray) -> np.ndarray:
        """A cached region: (3, n) flat cell index, cell-centre x and z."""
        w = self.raster.shape[1]
        x = self.raster.x0 + (idx % w + 0.5) * self.raster.res
        z = self.raster.z0 + (idx // w + 0.5) * self.raster.res
        return np.stack([idx.astype(float), x, z])

    def _near(self, region: np.ndarray, box: np.ndarray) -> np.ndarray:
        """bool per region cell: within SUCCESS_DISTANCE (plus a margin) of a box ((2, 2): min and max x, z)."""
        m = SUCCESS_DISTANCE + 2 * self.raster.res
        lo, hi = box[0] - m, box[1] + m
        x, z = region[1], region[2]
        return (x >= lo[0]) & (x <= hi[0]) & (z >= lo[1]) & (z <= hi[1])

    def _changed_box(self, win: LabelWindow) -> np.ndarray | None:
        """World box ((2, 2)) of the window's cells where a line of sight may change; None if none does."""
        rows, cols = np.nonzero(self.labels.changed_cells(win))
        if not len(rows):
            return None
        res = self.raster.res
        lo = (self.raster.x0 + (win.c0 + cols.min()) * res, self.raster.z0 + (win.r0 + rows.min()) * res)
        hi = (self.raster.x0 + (win.c0 + cols.max() + 1) * res, self.raster.z0 + (win.r0 + rows.max() + 1) * res)
        return np.array([lo, hi])

    def _still_valid(self, region: np.ndarray, i: int, t: str, changed: np.ndarray | None) -> np.ndarray:
        """The part of a cached success region of ``t`` that stays valid when object i moves.

        Cells near the old footprint may have seen only that instance (if it is a ``t``); cells
        near a cell whose occluder (or occluding object) changes may lose their line of sight
        (``changed``: the box of those cells). Far cells keep both.
        """
        if self.raster.types[i] != t and changed is None:
            return region
        keep = np.ones(region.shape[1], dtype=bool)
        if self.raster.types[i] == t:
            old = self.ctx.outlines[i]
            keep &= ~self._near(region, np.array([old.min(axis=0), old.max(axis=0)]))
        if changed is not None:
            keep &= ~self._near(region, changed)
        return region[:, keep]

    # ---------------------------------------------------------------- checks
    def _check(self, nav: np.ndarray, moved: int, changed: np.ndarray | None
               ) -> tuple[list[ValidationProblem], list[str], np.ndarray | None]:
        """Problems of the candidate navigable raster (start, rooms, doorways), the target types the
        cached success regions cannot prove reachable (the exact check decides those), and the start's
        4-connected component (flat bool; None when the start is blocked)."""
        if self.start_cell is None:
            return [ValidationProblem("no_start", "the house has no start pose; set one with House.set_agent_pose")], \
                [], None
        if not nav[self.start_cell]:
            return [ValidationProblem("start_blocked", "the agent would no longer fit at its start")], [], None
        labels, _ = ndimage.label(nav)
        flat = labels.ravel()
        comp = flat[self.start_cell[0] * nav.shape[1] + self.start_cell[1]]
        problems = []
        for r in sorted(self.need_rooms):
            if not self._room_reached(r, labels, comp):
                problems.append(ValidationProblem("room_unreachable", f"{r} would become unreachable from the start",
                                                  (r,)))
        for d in sorted(self.need_doors):
            if not (flat[self.doors[d]] == comp).any():
                problems.append(ValidationProblem("doorway_blocked", f"the doorway {d} would be blocked", (d,)))
        unproven = [t for t in sorted(self.need_targets) if not self._proven(t, flat, comp, moved, changed)]
        return problems, unproven, flat == comp

    def _approach_check(self, moved: int, corners: np.ndarray) -> list[ValidationProblem]:
        """Doorway approach zones the moved object (true outline ``corners``) would cover past the limit."""
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        zb = self._approach_bounds  # a zone whose bounds miss the outline's box cannot meet it
        near = np.flatnonzero((zb[:, 0] <= hi[0]) & (zb[:, 2] >= lo[0]) & (zb[:, 1] <= hi[1]) & (zb[:, 3] >= lo[1]))
        if not len(near):
            return []
        box = shapely.box(lo[0], lo[1], hi[0], hi[1])
        zones = [z for z in (self.approach[k] for k in near) if shapely.intersects(z.zone, box)]
        if not zones:
            return []
        polys = {oid: shapely.Polygon(corners) if k == moved else self._polygon(k) for k, oid in enumerate(self.ctx.ids)}
        return [ValidationProblem("doorway_approach", f"{', '.join(ids)} would cover {cover:.2f} of the {width:.2f} m "
                                  f"in front of doorway {d}", (d, *ids))
                for d, cover, width, ids in blocked_approaches(zones, polys, self.approach_before)
                if self.ctx.ids[moved] in ids]

    def _plausibility_check(self, fp: Footprint) -> list[ValidationProblem]:
        """The plausibility rules the moved object (at its new footprint ``fp``) would break."""
        if self.plausible is None:
            return []
        current = {f.object_id: f for f in self.geometry.footprints}
        return [ValidationProblem("implausible", f"implausible ({v.rule}): {v.message}", (v.object_id, *v.others),
                                  rule=v.rule)
                for v in check_move(self.plausible, fp, current)]

    def _polygon(self, k: int) -> shapely.Polygon:
        """Object k's true footprint where it stands (``ctx.outlines[k]``) as a polygon, built once per pose."""
        poly = self._polygons[k]
        if poly is None:
            poly = self._polygons[k] = shapely.Polygon(self.ctx.outlines[k])
        return poly

    def _proven(self, t: str, flat: np.ndarray, comp: int, moved: int, changed: np.ndarray | None) -> bool:
        """Whether t's cached success region, still valid after the move, has a cell in the start's component.

        The cell that proved it last time (a cell of the cache) is tried first.
        """
        w = self._target_witness.get(t)
        if w is not None and flat[int(w[0, 0])] == comp and self._still_valid(w, moved, t, changed).shape[1]:
            return True
        region = self.regions.get(t)
        if region is None:
            return False
        region = self._still_valid(region, moved, t, changed)  # valid (as a subset) away from the move
        hit = np.flatnonzero(flat[region[0].astype(np.int64)] == comp)
        if len(hit):
            self._target_witness[t] = region[:, hit[:1]]
        return bool(len(hit))

    def _room_reached(self, room_id: str, labels: np.ndarray, comp: int) -> bool:
        flat = labels.ravel()
        w = self._witness.get(room_id)
        if w is not None and flat[w] == comp:
            return True
        k = self.room_ids.index(room_id)
        idx = np.flatnonzero((self.raster.room.ravel() == k) & (flat == comp))
        if len(idx):
            self._witness[room_id] = int(idx[0])
            return True
        return False

    def footprint_at(self, i: int, center: np.ndarray, yaw: float) -> Footprint:
        """Floor object i (``ctx`` index) at a pose, as the edited house would have it (nothing is moved)."""
        return self._footprint(i, center, yaw)

    def _footprint(self, i: int, center: np.ndarray, yaw: float) -> Footprint:
        """Object i's footprint at a pose, exactly as ``SceneGeometry.from_house`` of the edited house has it."""
        fp = self.geometry.footprints[self._slot[self.ctx.ids[i]]]
        return replace(fp, center=(float(center[0]), float(center[1])), yaw=float(yaw) % 360.0)

    def _instance_points(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Sample points of floor object k where it stands (as ``sim.task.target_points``) and their labels."""
        if k not in self._points:
            fp = self.geometry.footprints[self._slot[self.ctx.ids[k]]]
            pts = sample_points(fp.corners, self.raster.res)
            self._points[k] = (pts, np.full(len(pts), LABEL_OBJECT0 + k, dtype=np.int64))
        return self._points[k]

    def _target_points(self, t: str, ks: list[int], moved: int | None = None,
                       corners: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Sample points (and labels) of floor objects ``ks`` (of type t), object ``moved`` at ``corners``."""
        parts = [self._instance_points(k) for k in ks if k != moved]
        if moved in ks:
            key = (moved, corners.tobytes())
            if key not in self._candidate_points:  # kept until the next commit (which may reuse it)
                pts = sample_points(corners, self.raster.res)
                self._candidate_points[key] = (pts, np.full(len(pts), LABEL_OBJECT0 + moved, dtype=np.int64))
            parts.append(self._candidate_points[key])
        if not parts:
            return np.zeros((0, 2)), np.zeros(0, dtype=np.int64)
        return np.concatenate([p for p, _ in parts]), np.concatenate([lb for _, lb in parts])

    def _exact_witness(self, t: str, i: int, corners: np.ndarray, component: np.ndarray,
                       grids: tuple[np.ndarray, np.ndarray]) -> int:
        """A cell of t's exact success region (object i at ``corners``) in the start's component; -1 if none."""
        label, occ = grids
        pts, lab = self._target_points(t, self.of_type.get(t, []), i, corners)
        r = self.raster
        return first_region_cell(component.reshape(r.shape), occ, label, r.x0, r.z0, r.res, pts, lab)

    # ---------------------------------------------------------------- editing
    def propose(self, object_id: str, dx_units: float, dy_units: float, rotation: float | None = None, *,
                relocate: bool = False) -> Proposal:
        """Dry run of one edit: place the object (grid units, absolute yaw) and validate; the scene is unchanged.

        The returned :class:`Proposal` holds the placement result and every problem found; pass it
        to :meth:`commit` to apply it (only valid while no other edit has been committed).
        ``relocate``: set the object down at the displacement's end, possibly in another room
        (:func:`~adaptenv.adapt.placement.place`), instead of marching.
        """
        res = place_units(self.ctx, object_id, dx_units, dy_units, rotation, step=self.step, relocate=relocate)
        request = dict(object_id=object_id, dx_units=float(dx_units), dy_units=float(dy_units), rotation=rotation,
                       relocate=relocate, result=res, owner=self._owner, version=self._version)
        if res.stop_reason == "invalid":
            return Proposal(**request, problems=(ValidationProblem("invalid", res.message, (object_id,)),))
        if not res.changed:
            return Proposal(**request, problems=())
        i = self.ctx.index[object_id]
        if self.ctx.types[i] in self.fixed_types:
            return Proposal(**request, problems=(ValidationProblem(
                "target_moved", f"target_moved: {object_id} is an instance of the episode's target "
                f"{self.ctx.types[i]} and stays where it is; move another object", (object_id,)),))
        center = self.ctx.centers[i] + np.array(res.achieved)
        corners = self.ctx.corners(i, center, res.yaw_after)
        # the true footprint (its corners for a box)
        outline = corners if self.ctx.is_box(i) else self.ctx.outline(i, center, res.yaw_after)
        inf = self.raster.inflate(outline)
        exact_fp = self._footprint(i, center, res.yaw_after)
        exact = exact_fp.corners  # target sample points come from the corners, as in sim.task
        drawn = LabelRaster.tight(_Inflated(inf.r0, inf.c0, inf.drawn)) \
            if np.array_equal(exact_fp.outline, outline) else self.labels.footprint(exact_fp.outline)
        quiet = self.labels.quiet(i, drawn)
        win = None if quiet else self.labels.window(i, drawn)
        problems, unproven, component = self._check(self.raster.navigable_with(i, inf), i,
                                                    None if quiet else self._changed_box(win))
        if unproven:
            win = win or self.labels.window(i, drawn)
            # The cached regions prove most targets reachable; the exact success regions decide the rest
            # (a finite geodesic distance is a success-region cell in the start's 4-connected component),
            # on the candidate's label and occluder grids, stopping at the first cell that proves it.
            grids = self.labels.with_window(win)
            found = {t: self._exact_witness(t, i, exact, component, grids) for t in unproven}
            problems += [ValidationProblem("target_unreachable", f"no {t} could be reached from the start", (t,))
                         for t in unproven if found[t] < 0]
        else:
            found = {}
        problems += self._approach_check(i, outline) + self._plausibility_check(exact_fp)
        return Proposal(**request, problems=tuple(problems), center=center, corners=corners, inflated=inf,
                        drawn=drawn, footprint=exact_fp, outline=outline, labels=win,
                        exact_targets=frozenset(unproven),
                        witnesses=tuple((t, c) for t, c in found.items() if c >= 0))

    def commit(self, proposal: Proposal, *, source: str = "manual", intent: str = "") -> Edit:
        """Apply a proposal from :meth:`propose` when it has no problems, log it either way; returns the Edit.

        A rejected proposal (any problem) is logged as not accepted and changes nothing.

        Raises:
            StaleProposalError: the proposal was made by another validator, or before an edit
                committed since (the scene it was checked against is gone).
        """
        if proposal.owner is not self._owner:
            raise StaleProposalError(f"the proposal to move {proposal.object_id} was made by another EditValidator; "
                                     "call propose on this one")
        if proposal.version != self._version:
            raise StaleProposalError(f"the proposal to move {proposal.object_id} was made before another edit was "
                                     "committed; call propose again on the current scene")
        res = proposal.result
        if proposal.valid and res.changed:
            self._apply(self.ctx.index[res.object_id], proposal)
        return self._record(res, proposal, source, intent, invalid=res.stop_reason == "invalid")

    def try_edit(self, object_id: str, dx_units: float, dy_units: float, rotation: float | None = None, *,
                 source: str = "manual", intent: str = "", relocate: bool = False) -> Edit:
        """Place the object (grid units, absolute yaw), validate, keep it if valid; returns the logged Edit.

        The same as ``commit(propose(...))``.
        """
        return self.commit(self.propose(object_id, dx_units, dy_units, rotation, relocate=relocate), source=source,
                           intent=intent)

    def propose_door(self, door_id: str, openness: float) -> tuple[House | None, list[ValidationProblem]]:
        """Dry run of a door edit: the house with the door at ``openness`` (0 shut, 1 open) and every problem
        :func:`validate_scene` finds against the current scene (None and the reason for a door that cannot move)."""
        door = next((d for d in self.house.doors if d.id == door_id), None)
        if door is None or not is_interior_leaf_door(door):
            why = "the house has no such door" if door is None else "only interior doors with a leaf open and shut"
            return None, [ValidationProblem("invalid", f"door {door_id}: {why}; pick one of the house's interior "
                                            "doors", (door_id,))]
        new = self.house.model_copy(update={"doors": [d.model_copy() for d in self.house.doors]})
        set_door_openness(new, door_id, openness)
        return new, validate_scene(new, episode_targets=self._settings["episode_targets"], start=self.start,
                                   original=self.house, catalog=self.catalog)

    def set_door(self, door_id: str, openness: float, *, source: str = "manual", intent: str = "") -> Edit:
        """Open (``openness`` 1) or shut (0) an interior door when the scene stays valid, log it either way; returns
        the Edit. Rooms behind a shut door may become unreachable; the episode's targets may not."""
        new, problems = self.propose_door(door_id, openness)
        before = next((d.openness for d in self.house.doors if d.id == door_id), None)
        ok = new is not None and not problems
        edit = Edit(object_id=door_id, openness=float(openness), openness_before=before, accepted=ok,
                    stop_reason="reached" if ok else "invalid", problems=[str(p) for p in problems], source=source,
                    intent=intent)
        if ok and edit.changed:
            self._rebuild(new)
        self.log.append(edit)
        return edit

    def _rebuild(self, house: House) -> None:
        """Start over on ``house`` (a door changed what is reachable), keeping the log and the reference scene's
        plausibility rules and doorway-approach baselines."""
        log, plausible, approach_before = self.log, self.plausible, self.approach_before
        self.__init__(house, copy=False, start=self.start, **self._settings)
        self.log, self.plausible = log, plausible
        self.approach_before = {**self.approach_before, **{k: w for k, w in approach_before.items()
                                                           if k in self.approach_before}}

    def adopt(self, house: House) -> None:
        """Continue on ``house``, changed outside placement (an asset swap, :mod:`adaptenv.adapt.appearance`), keeping
        the log and the reference scene's rules."""
        self._rebuild(house)

    def _apply(self, i: int, proposal: Proposal) -> None:
        """Move object i to the proposal's pose in every cache (footprints, regions, context, raster, house)."""
        res, center = proposal.result, proposal.center
        win = proposal.labels or self.labels.window(i, proposal.drawn)
        changed = self._changed_box(win)
        for t in self.need_targets:
            if self.regions.get(t) is not None:
                self.regions[t] = self._still_valid(self.regions[t], i, t, changed)
            w = self._target_witness.get(t)
            if w is not None and not self._still_valid(w, i, t, changed).shape[1]:
                del self._target_witness[t]  # it left the cache
        fp = proposal.footprint if proposal.footprint is not None else self._footprint(i, center, res.yaw_after)
        self.geometry.footprints[self._slot[res.object_id]] = fp
        self._points.pop(i, None)
        key = (i, fp.corners.tobytes())
        if key in self._candidate_points:
            self._points[i] = self._candidate_points[key]
        self._candidate_points.clear()
        self.ctx.commit(i, center, res.yaw_after, proposal.outline, relocated=proposal.relocate)
        self._polygons[i] = None
        self.raster.commit(i, proposal.inflated)
        self.labels.commit(i, win)
        move_object(self.objects[res.object_id], res.achieved[0], res.achieved[1], res.yaw_after - res.yaw_before)
        for t, cell in proposal.witnesses:  # the exact check's proof stays in the cache
            old_cells = self.regions[t][0].astype(np.int64) if self.regions.get(t) is not None else np.zeros(0, int)
            self.regions[t] = self._region_array(np.union1d(old_cells, [cell]))
        self._version += 1

    def _record(self, res: PlacementResult, proposal: Proposal, source: str, intent: str,
                invalid: bool = False) -> Edit:
        problems, rotation = list(proposal.problems), proposal.rotation
        ok = not problems
        edit = Edit(object_id=res.object_id, dx_units=proposal.dx_units, dy_units=proposal.dy_units,
                    rotation=None if rotation is None else float(rotation) % 360.0, relocate=proposal.relocate,
                    achieved_dx=res.achieved[0] if ok else 0.0, achieved_dz=res.achieved[1] if ok else 0.0,
                    achieved_dx_units=res.achieved_units[0] if ok else 0.0,
                    achieved_dy_units=res.achieved_units[1] if ok else 0.0,
                    yaw_before=0.0 if invalid else res.yaw_before,
                    yaw_after=0.0 if invalid else (res.yaw_after if ok else res.yaw_before),
                    stop_reason=res.stop_reason, blocked_by=res.blocked_by, steps=res.steps, accepted=ok,
                    problems=[str(p) for p in problems], source=source, intent=intent)
        self.log.append(edit)
        return edit


def reference_target_problems(validator: EditValidator, proposal: Proposal) -> list[ValidationProblem]:
    """The plain reference for :meth:`EditValidator.propose`'s target check (slow; for tests).

    Compiles the candidate world (``compile_world``) and checks every needed target type: its success
    region must meet the start's 4-connected navigable component of that world.
    """
    res = proposal.result
    if not res.changed or validator.start is None:
        return []
    i = validator.ctx.index[res.object_id]
    fps = list(validator.geometry.footprints)
    fps[validator._slot[res.object_id]] = validator._footprint(i, proposal.center, res.yaw_after)
    world = compile_world(validator.house, geometry=replace(validator.geometry, footprints=fps))
    start = _cell(world.grid, validator.start)
    nav = world.grid.navigable(AGENT_RADIUS)
    if start is None or not nav[start]:
        return []
    labels, _ = ndimage.label(nav)
    component = labels == labels[start]
    return [ValidationProblem("target_unreachable", f"no {t} could be reached from the start", (t,))
            for t in sorted(validator.need_targets) if not (success_region(world, t) & component).any()]


def check_edit(house: House, object_id: str, dx_units: float, dy_units: float, rotation: float | None = None, *,
               episode_targets: list[str] | None = None, start: Start | None = None, original: House | None = None,
               step: float = DEFAULT_STEP, source: str = "manual", intent: str = "") -> tuple[House, Edit]:
    """One edit on a copy of ``house``: (the edited house, or an unchanged copy when rejected; its Edit)."""
    v = EditValidator(house, episode_targets=episode_targets, start=start, original=original, step=step)
    edit = v.try_edit(object_id, dx_units, dy_units, rotation, source=source, intent=intent)
    return v.house, edit
