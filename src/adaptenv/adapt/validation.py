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
per candidate; accepted edits update the scene, rejected ones leave it untouched, and both are
logged as :class:`~adaptenv.adapt.edits.Edit` records.
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
from adaptenv.scene.assets import AssetCatalog, load_catalog
from adaptenv.scene.geometry import SceneGeometry, footprint_corners
from adaptenv.scene.house import House, move_object
from adaptenv.scene.occupancy import DEFAULT_RESOLUTION, LABEL_OBJECT0, OccupancyGrid, rasterize
from adaptenv.sim.spec import AGENT_RADIUS, SUCCESS_DISTANCE, TARGET_TYPES
from adaptenv.sim.world import compile_world

#: Overlaps smaller than this (m^2) are touching, not overlapping.
AREA_EPS = 1e-4
#: How far (m) a footprint may stick out of its rooms or through a wall.
CONTAIN_TOLERANCE = 0.01
#: Seats that ProcTHOR tucks under tables (and packs against each other).
SEAT_TYPES = frozenset({"Chair", "Stool", "ArmChair"})
TABLE_TYPES = frozenset({"DiningTable", "Desk", "CoffeeTable", "SideTable"})
#: Cells up to this many cell sizes outside an object's inflated footprint are where the agent stands next to it.
APPROACH_CELLS = 2

ProblemKind = Literal["invalid", "outside_room", "crosses_wall", "overlap", "overlap_grew", "start_blocked", "no_start",
                      "room_unreachable", "doorway_blocked", "target_unreachable", "doorway_approach"]


@dataclass(frozen=True)
class ValidationProblem:
    """One reason an edited scene is not acceptable."""

    kind: ProblemKind
    message: str
    object_ids: tuple[str, ...] = ()

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
    """An object's inflated footprint (cells where it makes the agent disc not fit) and its ring."""

    r0: int
    c0: int
    mask: np.ndarray
    ring: np.ndarray
    """Flat indices of the cells just outside the inflated footprint (where the agent stands next to it)."""


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
        """Inflated footprint of a footprint (corners (4, 2)) and its approach ring."""
        pad = self.pad + APPROACH_CELLS
        r0, c0, m = _mask_window(corners, self.x0, self.z0, self.res, pad, self.shape)
        # Distance to the footprint's cells gives the disc dilation exactly (same rule as the raster).
        dist = ndimage.distance_transform_edt(~m) * self.res
        clear = np.maximum(dist - 0.5 * self.res, 0.0).astype(np.float32)
        inflated = clear < self.radius
        ring = ~inflated & (clear < self.radius + APPROACH_CELLS * self.res)
        rr, cc = np.nonzero(ring)
        return _Inflated(r0, c0, inflated, (rr + r0) * self.shape[1] + (cc + c0))

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


def _world_reaches(world, target_type: str, start: tuple[float, float]) -> bool:
    """Whether the target type's success region is reachable from the start (finite geodesic distance)."""
    from adaptenv.sim.geodesic import geodesic_distance

    return bool(world.instances_of(target_type)) and math.isfinite(geodesic_distance(world, target_type, *start))


def _geodesic_targets(house: House, geometry: SceneGeometry, start: tuple[float, float],
                      types: list[str]) -> set[str]:
    """Target types whose success region is reachable from the start (finite geodesic distance)."""
    world = compile_world(house, geometry=geometry)
    return {t for t in types if _world_reaches(world, t, start)}


def _default_targets(geometry: SceneGeometry) -> list[str]:
    present = {f.object_type for f in geometry.floor_objects}
    return [t for t in TARGET_TYPES if t in present]


def scene_reachability(house: House, *, start: Start | None = None, targets: list[str] | None = None,
                       geometry: SceneGeometry | None = None) -> Reachability:
    """Rooms, doorways and target types reachable from the start of a house (the validation baseline)."""
    geometry = geometry or SceneGeometry.from_house(house)
    occ = rasterize(geometry)
    s = _start_of(house, start)
    reach, _ = _reachable(occ.navigable(AGENT_RADIUS), None if s is None else _cell(occ, s), occ.room,
                          occ.room_ids, door_threshold_cells(geometry, occ))
    if reach.start_free and s is not None:
        reach.targets = _geodesic_targets(house, geometry, s, targets or _default_targets(geometry))
    return reach


def _cell(occ: OccupancyGrid, p: tuple[float, float]) -> tuple[int, int] | None:
    row, col = occ.to_cell(p[0], p[1])
    return (int(row), int(col)) if bool(occ.in_bounds(row, col)) else None


# --------------------------------------------------------------------------- validate_scene

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
                                                   max(sz - 2 * CONTAIN_TOLERANCE, 1e-3), f.yaw))
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
                   original: House | None = None, catalog: AssetCatalog | None = None) -> list[ValidationProblem]:
    """Every physical-plausibility and task-feasibility problem of a (possibly edited) house.

    Args:
        house: the scene to check.
        episode_targets: target types that must stay reachable; default: every target type that is
            reachable in ``original`` (or present, without ``original``).
        start: the agent's start (x, z[, yaw]); default: the house's metadata pose.
        original: the scene before editing; only problems new relative to it count.

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
        before = {f.object_id: (f.center, f.yaw) for f in orig_geometry.floor_objects}
        moved = {f.object_id for f in geometry.floor_objects if before.get(f.object_id) != (f.center, f.yaw)}
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
    occ = rasterize(geometry)
    doors = door_threshold_cells(geometry, occ)
    now, _ = _reachable(occ.navigable(AGENT_RADIUS), _cell(occ, s), occ.room, occ.room_ids, doors)
    if not now.start_free:
        problems.append(ValidationProblem("start_blocked", f"the agent does not fit at its start ({s[0]:.2f}, "
                                          f"{s[1]:.2f}); move the furniture away from it"))
        return problems
    if original is not None:
        need = scene_reachability(original, start=start or _start_of(original, None), targets=episode_targets,
                                  geometry=orig_geometry)
        need_targets = need.targets if episode_targets is None else set(episode_targets) & need.targets
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
    reached = _geodesic_targets(house, geometry, s, sorted(need_targets))
    for t in sorted(need_targets - reached):
        problems.append(ValidationProblem("target_unreachable", f"no {t} can be reached and seen from the start; "
                                          "clear a path to one", (t,)))
    return problems


# --------------------------------------------------------------------------- the fast path for generators

class EditValidator:
    """Try edits on a scene: place, validate incrementally, keep valid ones, log all.

    Example:
        >>> v = EditValidator(house, episode_targets=["Bed"])  # doctest: +SKIP
        >>> edit = v.try_edit("Chair|3|0|1", 20, 5, source="random")  # doctest: +SKIP
        >>> edit.accepted, edit.stop_reason, v.house  # doctest: +SKIP
    """

    def __init__(self, house: House, *, episode_targets: list[str] | None = None, start: Start | None = None,
                 original: House | None = None, step: float = DEFAULT_STEP, catalog: AssetCatalog | None = None,
                 copy: bool = True):
        self.catalog = catalog or load_catalog()
        self.house = house.model_copy(deep=True) if copy else house
        self.step = step
        self.geometry = SceneGeometry.from_house(self.house, self.catalog)
        self.ctx = PlacementContext.from_house(self.house, original=original, catalog=self.catalog,
                                               geometry=self.geometry)
        self.raster = NavRaster(self.geometry)
        occ = self.raster.occupancy
        self.room_ids = occ.room_ids
        self.doors = door_threshold_cells(self.geometry, occ)
        self.start = _start_of(self.house, start) if original is None else _start_of(original, start)
        self.start_cell = None if self.start is None else _cell(occ, self.start)
        base_house, base_geometry = (original, None) if original is not None else (self.house, self.geometry)
        need = scene_reachability(base_house, start=self.start, targets=episode_targets, geometry=base_geometry)
        self.need_rooms = need.rooms
        self.need_doors = need.doors & set(self.doors)
        self.approach = approach_zones(self.geometry)
        base = SceneGeometry.from_house(original, self.catalog) if original is not None else self.geometry
        self.approach_before = {z.door_id: covered_width(z, [shapely.Polygon(f.corners) for f in base.floor_objects])
                                for z in approach_zones(base)}
        self.need_targets = need.targets if episode_targets is None else set(episode_targets) & need.targets
        self.tall = np.array([f.occludes for f in self.geometry.floor_objects], dtype=bool)
        self.of_type: dict[str, list[int]] = {}
        for k, ty in enumerate(self.raster.types):
            self.of_type.setdefault(ty, []).append(k)
        self.regions: dict[str, np.ndarray | None] = {}
        if self.start_cell is not None:
            self._refresh_regions(compile_world(self.house, geometry=self.geometry))
        self.objects = {obj.id: obj for obj in self.house.objects}
        self.log = EditLog()
        self._witness: dict[str, int] = {}

    def _refresh_regions(self, world, types: set[str] | None = None) -> None:
        """Cache each needed target type's success region (flat indices) from an exactly compiled world."""
        from adaptenv.sim.geodesic import success_region

        w = self.raster.shape[1]
        for t in types if types is not None else self.need_targets:
            if not world.instances_of(t):
                self.regions[t] = None
                continue
            idx = np.flatnonzero(success_region(world, t))
            x = self.raster.x0 + (idx % w + 0.5) * self.raster.res
            z = self.raster.z0 + (idx // w + 0.5) * self.raster.res
            self.regions[t] = np.stack([idx.astype(float), x, z])

    def _near(self, region: np.ndarray, corners: np.ndarray) -> np.ndarray:
        """bool per region cell: within SUCCESS_DISTANCE (plus a margin) of the footprint's bounding box."""
        m = SUCCESS_DISTANCE + 2 * self.raster.res
        lo = corners.min(axis=0) - m
        hi = corners.max(axis=0) + m
        x, z = region[1], region[2]
        return (x >= lo[0]) & (x <= hi[0]) & (z >= lo[1]) & (z <= hi[1])

    def _still_valid(self, region: np.ndarray, i: int, t: str, new_corners: np.ndarray) -> np.ndarray:
        """The part of a cached success region of ``t`` that stays valid when object i moves.

        Cells near the old footprint may have seen only that instance (if it is a ``t``); cells
        near the new footprint may lose their line of sight (if it is tall). Far cells keep both.
        """
        keep = np.ones(region.shape[1], dtype=bool)
        if self.raster.types[i] == t:
            keep &= ~self._near(region, self.ctx.objects.verts[i])
        if self.tall[i]:
            keep &= ~self._near(region, new_corners)
        return region[:, keep]

    # ---------------------------------------------------------------- checks
    def _check(self, nav: np.ndarray, moved: int, inf, corners: np.ndarray) -> list[ValidationProblem]:
        """Problems of the candidate navigable raster (rooms, doorways, targets, start)."""
        if self.start_cell is None:
            return [ValidationProblem("no_start", "the house has no start pose; set one with House.set_agent_pose")]
        if not nav[self.start_cell]:
            return [ValidationProblem("start_blocked", "the agent would no longer fit at its start")]
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
        for t in sorted(self.need_targets):
            # A cached success region stays valid (as a subset) away from a moved occluder or t.
            region = self.regions.get(t)
            if region is not None and self._affects(moved, t):
                region = self._still_valid(region, moved, t, corners)
            if region is not None and (flat[region[0].astype(np.int64)] == comp).any():
                continue
            rings = [inf.ring if k == moved else self.raster.objects[k].ring for k in self.of_type.get(t, ())]
            if not any((flat[ring] == comp).any() for ring in rings):
                problems.append(ValidationProblem("target_unreachable", f"no {t} could be reached from the start",
                                                  (t,)))
        return problems + self._approach_check(moved, corners)

    def _approach_check(self, moved: int, corners: np.ndarray) -> list[ValidationProblem]:
        """Doorway approach zones the moved object (at ``corners``) would cover past the limit."""
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        zones = [z for z in self.approach if shapely.intersects(z.zone, shapely.box(lo[0], lo[1], hi[0], hi[1]))]
        if not zones:
            return []
        polys = {oid: shapely.Polygon(corners if k == moved else self.ctx.objects.verts[k])
                 for k, oid in enumerate(self.ctx.ids)}
        return [ValidationProblem("doorway_approach", f"{', '.join(ids)} would cover {cover:.2f} of the {width:.2f} m "
                                  f"in front of doorway {d}", (d, *ids))
                for d, cover, width, ids in blocked_approaches(zones, polys, self.approach_before)
                if self.ctx.ids[moved] in ids]

    def _affects(self, i: int, target_type: str) -> bool:
        """Whether moving object i can change where ``target_type`` is visible from (tall, or a target itself)."""
        return bool(self.tall[i]) or self.raster.types[i] == target_type

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

    def _trial_world(self, i: int, center: np.ndarray, yaw: float):
        """The compiled world with object i at a candidate pose (slow; for the exact fallback)."""
        floor_index = {f.object_id: k for k, f in enumerate(self.geometry.footprints)}
        fps = list(self.geometry.footprints)
        k = floor_index[self.ctx.ids[i]]
        fps[k] = replace(fps[k], center=(float(center[0]), float(center[1])), yaw=float(yaw) % 360.0)
        geometry = replace(self.geometry, footprints=fps)
        return compile_world(self.house, geometry=geometry), geometry

    # ---------------------------------------------------------------- editing
    def try_edit(self, object_id: str, dx_units: float, dy_units: float, rotation: float | None = None, *,
                 source: str = "manual", intent: str = "") -> Edit:
        """Place the object (grid units, absolute yaw), validate, keep it if valid; returns the logged Edit."""
        res = place_units(self.ctx, object_id, dx_units, dy_units, rotation, step=self.step)
        problems: list[ValidationProblem] = []
        if res.stop_reason == "invalid":
            problems = [ValidationProblem("invalid", res.message, (object_id,))]
            edit = self._record(res, dx_units, dy_units, rotation, source, intent, problems, invalid=True)
            return edit
        inf = None
        if res.changed:
            i = self.ctx.index[object_id]
            center = self.ctx.centers[i] + np.array(res.achieved)
            corners = self.ctx.corners(i, center, res.yaw_after)
            inf = self.raster.inflate(corners)
            problems = self._check(self.raster.navigable_with(i, inf), i, inf, corners)
            missing = {p.object_ids[0] for p in problems if p.kind == "target_unreachable"}
            world = None
            if missing and len(missing) == len(problems):
                # The cached regions and approach rings are conservative; the exact geodesic check decides.
                world, _ = self._trial_world(i, center, res.yaw_after)
                problems = [p for p in problems if not _world_reaches(world, p.object_ids[0], self.start)]
            if not problems:
                self._commit(i, center, res, inf, corners)
                if world is not None:
                    self._refresh_regions(world, missing)
        return self._record(res, dx_units, dy_units, rotation, source, intent, problems)

    def _commit(self, i: int, center: np.ndarray, res: PlacementResult, inf, corners: np.ndarray) -> None:
        fps = self.geometry.footprints
        k = next(k for k, f in enumerate(fps) if f.object_id == res.object_id)
        fps[k] = replace(fps[k], center=(float(center[0]), float(center[1])), yaw=res.yaw_after % 360.0)
        for t in self.need_targets:
            if self.regions.get(t) is not None and self._affects(i, t):
                self.regions[t] = self._still_valid(self.regions[t], i, t, corners)
        self.ctx.commit(i, center, res.yaw_after)
        self.raster.commit(i, inf)
        move_object(self.objects[res.object_id], res.achieved[0], res.achieved[1], res.yaw_after - res.yaw_before)

    def _record(self, res: PlacementResult, dx_units: float, dy_units: float, rotation: float | None, source: str,
                intent: str, problems: list[ValidationProblem], invalid: bool = False) -> Edit:
        ok = not problems
        edit = Edit(object_id=res.object_id, dx_units=float(dx_units), dy_units=float(dy_units),
                    rotation=None if rotation is None else float(rotation) % 360.0,
                    achieved_dx=res.achieved[0] if ok else 0.0, achieved_dz=res.achieved[1] if ok else 0.0,
                    achieved_dx_units=res.achieved_units[0] if ok else 0.0,
                    achieved_dy_units=res.achieved_units[1] if ok else 0.0,
                    yaw_before=0.0 if invalid else res.yaw_before,
                    yaw_after=0.0 if invalid else (res.yaw_after if ok else res.yaw_before),
                    stop_reason=res.stop_reason, blocked_by=res.blocked_by, steps=res.steps, accepted=ok,
                    problems=[str(p) for p in problems], source=source, intent=intent)
        self.log.append(edit)
        return edit


def check_edit(house: House, object_id: str, dx_units: float, dy_units: float, rotation: float | None = None, *,
               episode_targets: list[str] | None = None, start: Start | None = None, original: House | None = None,
               step: float = DEFAULT_STEP, source: str = "manual", intent: str = "") -> tuple[House, Edit]:
    """One edit on a copy of ``house``: (the edited house, or an unchanged copy when rejected; its Edit)."""
    v = EditValidator(house, episode_targets=episode_targets, start=start, original=original, step=step)
    edit = v.try_edit(object_id, dx_units, dy_units, rotation, source=source, intent=intent)
    return v.house, edit
