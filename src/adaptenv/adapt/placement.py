"""Collision-aware placement: the paper's incremental march of an object toward a proposed pose.

Given an object and a requested displacement ``d`` (and optionally a new absolute yaw), the
object is (a) turned in place if the turned footprint is collision-free, else it keeps its yaw;
(b) moved along ``d`` to ``p(k) = p_orig + min(k * delta, |d|) * d / |d|`` for k = 1, 2, ...,
stopping before the first pose that collides and keeping the last collision-free pose
(Fig. 3 of the paper). Footprints are the true floor outlines of
:attr:`adaptenv.scene.geometry.Footprint.outline` (the shape the simulator, validation and renderer
use): an L- or C-shaped counter blocks its arms, not the floor it wraps around. A pose collides when
its footprint

- overlaps another floor object with positive depth (touching is fine), except pairs that
  already overlapped in the original scene (chairs tucked under a table): such a pair collides
  only when its intersection area exceeds :func:`allowed_overlap` of its original area;
- leaves the object's own room polygon (flush against a wall is fine). Objects never march into
  another room, not even through a doorway; whether the pose crossed a wall (``blocked_by_wall``)
  or an opening (``left_room``) is recorded.

A *relocation* (``relocate=True``, an extension of the paper for targets that G hides in another
room) does not march: the object is set down at ``p_orig + d`` if that pose is collision-free and
lies inside one room (any room), else it stays where it is.

Doorway clearance is not a placement constraint: :mod:`adaptenv.adapt.validation` checks it.
Children (objects resting on the moved one) move rigidly with it and are not collision-checked.

Speed: a :class:`PlacementContext` holds every obstacle as arrays once per scene (updated in place
by :meth:`PlacementContext.commit`); a footprint that is not convex is held as its convex pieces
(:attr:`~adaptenv.scene.geometry.Footprint.local_pieces`). :func:`place` keeps only the obstacles
whose bounding box meets the swept bounding box of the path, evaluates every step pose against them
at once with a separating-axis test in NumPy, and takes the first colliding step; pre-existing pairs
use exact areas and, when both footprints are convex, a concavity shortcut (the square root of the
intersection area of two convex shapes is concave along a straight translation). The result equals
the plain step-by-step loop :func:`reference_place` at ``delta`` resolution (tested).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely

from adaptenv.adapt.edits import StopReason
from adaptenv.scene.assets import AssetCatalog, load_catalog
from adaptenv.scene.geometry import (
    Footprint,
    SceneGeometry,
    footprint_corners,
    footprint_room,
    pose_outline,
)
from adaptenv.scene.grid import NormalizedGrid
from adaptenv.scene.house import House

#: Default march step delta (m).
DEFAULT_STEP = 0.05
#: Two footprints collide when they overlap deeper than this (m) on every separating axis.
OVERLAP_EPS = 1e-4
#: A footprint leaves its room when it sticks out deeper than this (m).
ROOM_EPS = 2e-3
#: Relative and absolute (m^2) growth allowed for the area of a pre-existing overlap.
PREEXISTING_GROWTH = 0.10
PREEXISTING_SLACK = 0.005
#: Half-size (m) of the box around a room whose complement is decomposed into obstacles.
_FAR = 1000.0



def allowed_overlap(original_area: float) -> float:
    """Largest intersection area (m^2) a pair that overlapped by ``original_area`` may reach."""
    return original_area * (1.0 + PREEXISTING_GROWTH) + PREEXISTING_SLACK


@dataclass
class ConvexSet:
    """Convex polygons as arrays for separating-axis tests: vertices, edge normals, projections."""

    verts: np.ndarray
    """(C, P, 2) vertices (degenerate polygons such as segments repeat vertices)."""
    normals: np.ndarray
    """(C, P, 2) unit edge normals (degenerate edges reuse a valid normal)."""
    lo: np.ndarray
    """(C, P) minimum projection of each polygon on each of its normals."""
    hi: np.ndarray
    aabb: np.ndarray
    """(C, 4) min x, min z, max x, max z."""

    @classmethod
    def build(cls, verts: np.ndarray) -> ConvexSet:
        verts = np.asarray(verts, dtype=float).reshape(-1, verts.shape[-2] if len(verts) else 4, 2)
        normals, lo, hi, aabb = _convex_arrays(verts)
        return cls(verts, normals, lo, hi, aabb)

    def __len__(self) -> int:
        return len(self.verts)

    def update(self, i: int, verts: np.ndarray) -> None:
        """Replace polygon i (same vertex count)."""
        n, lo, hi, aabb = _convex_arrays(verts[None])
        self.verts[i], self.normals[i], self.lo[i], self.hi[i], self.aabb[i] = verts, n[0], lo[0], hi[0], aabb[0]


def _convex_arrays(verts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    if len(verts) == 0:
        p = verts.shape[1] if verts.ndim == 3 else 4
        return np.zeros((0, p, 2)), np.zeros((0, p)), np.zeros((0, p)), np.zeros((0, 4))
    edges = np.roll(verts, -1, axis=1) - verts
    normals = np.stack([edges[..., 1], -edges[..., 0]], axis=-1)
    length = np.linalg.norm(normals, axis=-1)
    good = length > 1e-12
    normals = np.where(good[..., None], normals / np.maximum(length, 1e-12)[..., None], 0.0)
    # Degenerate edges (repeated vertices) take the polygon's first valid normal.
    first = np.argmax(good, axis=1)
    fallback = normals[np.arange(len(verts)), first]
    normals = np.where(good[..., None], normals, fallback[:, None, :])
    proj = np.einsum("cpd,cqd->cpq", normals, verts)
    aabb = np.concatenate([verts.min(axis=1), verts.max(axis=1)], axis=1)
    return normals, proj.min(axis=2), proj.max(axis=2), aabb


def _selected(obstacles: ConvexSet, idx: np.ndarray | None) -> tuple[np.ndarray, ...]:
    """(normals, lo, hi, verts) of the obstacles ``idx`` selects (all of them when None)."""
    if idx is None:
        return obstacles.normals, obstacles.lo, obstacles.hi, obstacles.verts
    return obstacles.normals[idx], obstacles.lo[idx], obstacles.hi[idx], obstacles.verts[idx]


def rect_depth(centers: np.ndarray, half: tuple[float, float], yaw: float, obstacles: ConvexSet,
               idx: np.ndarray | None = None) -> np.ndarray:
    """Separating-axis penetration depth (K, C) of a rectangle at K centres against C convex polygons.

    The depth is the shortest push, over the edge normals of both shapes, that separates the
    projections; it is positive exactly when the interiors intersect (touching gives 0, apart
    < 0). Segments (degenerate polygons) get their crossing depth: how far the rectangle sticks
    through the segment's line.
    """
    normals, lo, hi, verts = _selected(obstacles, idx)
    centers = np.asarray(centers, dtype=float).reshape(-1, 2)
    n_obs, n_pts = lo.shape
    if n_obs == 0:
        return np.full((len(centers), 0), -np.inf)
    axes = np.array(_axes(yaw))  # (2, 2): the rectangle's local x and z axes
    half_arr = np.array(half, dtype=float)
    flat = normals.reshape(-1, 2)
    # The rectangle on the obstacles' normals: centre projection +- radius.
    radius = np.abs(flat @ axes.T) @ half_arr  # (C*P,)
    c = centers @ flat.T  # (K, C*P)
    d_obs = np.minimum(c + (radius - lo.ravel()), (hi.ravel() + radius) - c)
    depth = d_obs.reshape(len(centers), n_obs, n_pts).min(axis=2)
    # The obstacles on the rectangle's two axes.
    p = verts @ axes.T  # (C, P, 2)
    pmin, pmax = p.min(axis=1), p.max(axis=1)  # (C, 2)
    pc = centers @ axes.T  # (K, 2)
    d_rect = np.minimum(pc[:, None, :] + (half_arr - pmin), (pmax + half_arr) - pc[:, None, :]).min(axis=2)
    return np.minimum(depth, d_rect)


def poly_depth(centers: np.ndarray, offsets: np.ndarray, obstacles: ConvexSet,
               idx: np.ndarray | None = None) -> np.ndarray:
    """:func:`rect_depth` of any convex polygon: its vertices ``offsets`` (Q, 2) relative to K centres.

    Degenerate polygons (repeated vertices, e.g. triangles padded to 4 vertices) are fine.
    """
    normals, lo, hi, verts = _selected(obstacles, idx)
    centers = np.asarray(centers, dtype=float).reshape(-1, 2)
    n_obs, n_pts = lo.shape
    if n_obs == 0:
        return np.full((len(centers), 0), -np.inf)
    offsets = np.asarray(offsets, dtype=float)
    flat = normals.reshape(-1, 2)
    # The polygon on the obstacles' normals: centre projection + [amin, amax].
    q = offsets @ flat.T  # (Q, C*P)
    c = centers @ flat.T  # (K, C*P)
    d_obs = np.minimum(c + (q.max(axis=0) - lo.ravel()), (hi.ravel() - q.min(axis=0)) - c)
    depth = d_obs.reshape(len(centers), n_obs, n_pts).min(axis=2)
    # The obstacles on the polygon's own normals.
    own, own_lo, own_hi, _ = _convex_arrays(offsets[None])
    n_own = own[0]  # (Q, 2)
    p = verts @ n_own.T  # (C, P, Q)
    pmin, pmax = p.min(axis=1), p.max(axis=1)  # (C, Q)
    pc = centers @ n_own.T  # (K, Q)
    d_own = np.minimum(pc[:, None, :] + (own_hi[0] - pmin), (pmax - own_lo[0]) - pc[:, None, :]).min(axis=2)
    return np.minimum(depth, d_own)


def _axes(yaw: float) -> tuple[np.ndarray, np.ndarray]:
    t = math.radians(yaw)
    c, s = math.cos(t), math.sin(t)
    return np.array([c, -s]), np.array([s, c])


def _rectilinear(poly: shapely.Polygon) -> bool:
    pts = np.asarray(poly.exterior.coords)
    d = np.diff(pts, axis=0)
    return bool(np.all((np.abs(d[:, 0]) < 1e-9) | (np.abs(d[:, 1]) < 1e-9)))


def room_complement(poly: shapely.Polygon) -> np.ndarray:
    """Convex pieces (C, 4, 2) covering the plane around a room (out to a far box) but not the room.

    Rectilinear rooms are cut into vertical slabs at their vertex x's, giving rectangles; other
    shapes are triangulated (triangles repeat their last vertex).
    """
    minx, minz, maxx, maxz = poly.bounds
    far = (minx - _FAR, minz - _FAR, maxx + _FAR, maxz + _FAR)
    if not _rectilinear(poly) or poly.interiors:
        rest = shapely.box(*far).difference(poly)
        tris = shapely.get_parts(shapely.constrained_delaunay_triangles(rest))
        out = [np.asarray(t.exterior.coords)[:3] for t in tris]
        return np.array([[a, b, c, c] for a, b, c in out], dtype=float).reshape(-1, 4, 2)
    xs = np.unique(np.concatenate([[far[0], far[2]], np.asarray(poly.exterior.coords)[:, 0]]))
    rects = []
    for xa, xb in zip(xs[:-1], xs[1:], strict=True):
        slab = shapely.box(xa, far[1], xb, far[3])
        inside = sorted((g.bounds[1], g.bounds[3]) for g in shapely.get_parts(poly.intersection(slab))
                        if g.area > 0)
        z = far[1]
        for a, b in inside:
            if a > z:
                rects.append((xa, z, xb, a))
            z = max(z, b)
        if z < far[3]:
            rects.append((xa, z, xb, far[3]))
    return np.array([[(x0, z0), (x1, z0), (x1, z1), (x0, z1)] for x0, z0, x1, z1 in rects], dtype=float)


def _segments_as_polys(segs: np.ndarray) -> np.ndarray:
    segs = np.asarray(segs, dtype=float).reshape(-1, 2, 2)
    return np.stack([segs[:, 0], segs[:, 1], segs[:, 1], segs[:, 0]], axis=1)


@dataclass
class PlacementContext:
    """Everything placement needs about one scene, as arrays; build once, :meth:`commit` moves."""

    grid: NormalizedGrid
    ids: list[str]
    """Floor objects (``SceneGeometry.floor_objects`` order)."""
    types: list[str]
    movable: np.ndarray
    centers: np.ndarray
    """(N, 2) footprint centres (x, z)."""
    sizes: np.ndarray
    """(N, 2) full footprint extents in the object's local (x, z)."""
    yaws: np.ndarray
    local_pieces: list[np.ndarray]
    """Per object: convex pieces (C_i, 4, 2) of its true footprint in its local frame (one for a box)."""
    objects: ConvexSet
    """Every object's pieces at its current pose, object after object (``owner`` maps them back)."""
    owner: np.ndarray
    """(M,) object index of each piece of ``objects``."""
    room_ids: list[str]
    room_of: np.ndarray
    """(N,) index into ``room_ids`` of each object's own room."""
    room_outside: list[ConvexSet]
    """Per room: convex pieces of everything outside it."""
    walls: ConvexSet
    wall_ids: list[tuple[str, ...]]
    """Wall ids (one per side) of each blocking wall segment."""
    openings: ConvexSet
    opening_ids: list[str]
    """Doors, windows and open (empty) walls, as segments; where ``left_room`` went through."""
    preexisting: dict[tuple[int, int], float] = field(default_factory=dict)
    """Allowed intersection area (m^2) of each pair (i < j) that overlapped in the original scene."""
    index: dict[str, int] = field(default_factory=dict)
    first: np.ndarray = field(default_factory=lambda: np.zeros(1, dtype=int))
    """(N + 1,) the pieces of object i are ``objects[first[i]:first[i + 1]]``."""
    outlines: list[np.ndarray] = field(default_factory=list)
    """Per object: its true footprint outline (world x, z) at its current pose."""
    local_outlines: list[np.ndarray] = field(default_factory=list)
    """Per object: ``Footprint.local_outline``."""
    boxes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    """(N,) whether each footprint is its bounding rectangle (``Footprint.shape is None``)."""
    reaches: dict[int, float] = field(default_factory=dict, repr=False)
    """:meth:`reach` of each object asked about so far (its local pieces never change)."""

    @classmethod
    def from_house(cls, house: House, *, original: House | None = None, catalog: AssetCatalog | None = None,
                   geometry: SceneGeometry | None = None) -> PlacementContext:
        """Build the context; pairs overlapping in ``original`` (default: this house) stay allowed."""
        catalog = catalog or load_catalog()
        geometry = geometry or SceneGeometry.from_house(house, catalog)
        floor = geometry.floor_objects
        ids = [f.object_id for f in floor]
        centers = np.array([f.center for f in floor], dtype=float).reshape(-1, 2)
        sizes = np.array([f.size for f in floor], dtype=float).reshape(-1, 2)
        yaws = np.array([f.yaw for f in floor], dtype=float)
        local = [f.local_pieces for f in floor]
        pieces = np.concatenate([pose_outline(lp, *f.center, f.yaw) for lp, f in zip(local, floor, strict=True)]
                                ).reshape(-1, 4, 2) if floor else np.zeros((0, 4, 2))
        owner = np.repeat(np.arange(len(floor)), [len(lp) for lp in local]).astype(int)
        room_ids = list(geometry.rooms)
        polys = [geometry.rooms[r] for r in room_ids]
        room_of = np.array([_room_index(f, geometry, room_ids) for f in floor], dtype=int)
        segs = geometry.blocking_segments()
        wall_ids = [_wall_ids_of(seg, geometry) for seg in segs]
        open_segs = [(d.p0, d.p1) for d in geometry.doors + geometry.windows]
        open_ids = [d.id for d in geometry.doors + geometry.windows]
        for w in geometry.walls:
            if w.empty:
                open_segs.append((w.p0, w.p1))
                open_ids.append(w.wall_ids[0])
        ctx = cls(geometry.grid or NormalizedGrid.for_house(house), ids, [f.object_type for f in floor],
                  np.array([f.movable for f in floor], dtype=bool), centers, sizes, yaws, local,
                  ConvexSet.build(pieces), owner, room_ids, room_of, [ConvexSet.build(room_complement(p)) for p in polys],
                  ConvexSet.build(_segments_as_polys(segs)), wall_ids,
                  ConvexSet.build(_segments_as_polys(np.array(open_segs, dtype=float).reshape(-1, 2, 2))), open_ids)
        ctx.index = {oid: k for k, oid in enumerate(ids)}
        ctx.first = np.concatenate([[0], np.cumsum([len(lp) for lp in local])]).astype(int)
        ctx.outlines = [f.outline.copy() for f in floor]
        ctx.local_outlines = [f.local_outline for f in floor]
        ctx.boxes = np.array([f.shape is None for f in floor], dtype=bool)
        base = ctx.overlap_areas()
        if original is not None:
            orig = PlacementContext.from_house(original, catalog=catalog)
            base = {}
            for (a, b), area in orig.overlap_areas().items():
                i, j = ctx.index.get(orig.ids[a]), ctx.index.get(orig.ids[b])
                if i is not None and j is not None:
                    base[(min(i, j), max(i, j))] = area
            # Overlaps that exist now but not in the original may only shrink.
            for pair, area in ctx.overlap_areas().items():
                base.setdefault(pair, area / (1.0 + PREEXISTING_GROWTH) - PREEXISTING_SLACK)
        ctx.preexisting = {pair: allowed_overlap(area) for pair, area in base.items()}
        return ctx

    def overlap_areas(self) -> dict[tuple[int, int], float]:
        """Intersection area of every pair of floor objects that overlaps (depth > OVERLAP_EPS)."""
        out = {}
        polys = [shapely.Polygon(o) for o in self.outlines]
        for i in range(len(self.ids)):
            depth = self.depth(i, self.centers[i], float(self.yaws[i]), self.objects)[0]
            for j in np.unique(self.owner[depth > OVERLAP_EPS]):
                if j > i:
                    out[(i, int(j))] = float(shapely.area(shapely.intersection(polys[i], polys[j])))
        return out

    def half(self, i: int) -> tuple[float, float]:
        return float(self.sizes[i, 0]) / 2.0, float(self.sizes[i, 1]) / 2.0

    def corners(self, i: int, center: np.ndarray, yaw: float) -> np.ndarray:
        """Corners (4, 2) of object i's bounding rectangle at a pose."""
        return footprint_corners(float(center[0]), float(center[1]), float(self.sizes[i, 0]),
                                 float(self.sizes[i, 1]), yaw)

    def outline(self, i: int, center: np.ndarray, yaw: float) -> np.ndarray:
        """Object i's true footprint outline at a pose (its corners for a box)."""
        if self.is_box(i):
            return self.corners(i, center, yaw)
        return pose_outline(self.local_outlines[i], float(center[0]), float(center[1]), yaw)

    def is_box(self, i: int) -> bool:
        """Whether object i's footprint is its bounding rectangle (no shape of its own)."""
        return bool(self.boxes[i])

    def reach(self, i: int) -> float:
        """Largest distance (m) from object i's centre to its footprint (bounds the swept box of a path)."""
        r = self.reaches.get(i)
        if r is None:
            r = self.reaches[i] = float(np.linalg.norm(self.local_pieces[i].reshape(-1, 2), axis=1).max())
        return r

    def depth(self, i: int, centers: np.ndarray, yaw: float, obstacles: ConvexSet,
              idx: np.ndarray | None = None) -> np.ndarray:
        """Penetration depth (K, C) of object i at K centres (one yaw) into convex obstacles (max over its pieces)."""
        if self.is_box(i):
            return rect_depth(centers, self.half(i), yaw, obstacles, idx)
        pieces = pose_outline(self.local_pieces[i], 0.0, 0.0, yaw)
        return np.max([poly_depth(centers, p, obstacles, idx) for p in pieces], axis=0)

    def commit(self, i: int, center: np.ndarray, yaw: float, outline: np.ndarray | None = None, *,
               relocated: bool = False) -> None:
        """Record that object i now stands at ``center`` with ``yaw`` (after an accepted edit).

        ``outline``: ``self.outline(i, center, yaw)`` when the caller already has it. ``relocated``: the edit
        was a relocation, so the object may now belong to another room (a march never leaves its room).
        """
        self.centers[i] = center
        self.yaws[i] = yaw % 360.0
        world = pose_outline(self.local_pieces[i], float(center[0]), float(center[1]), yaw)
        for k, piece in zip(range(self.first[i], self.first[i + 1]), world, strict=True):
            self.objects.update(k, piece)
        self.outlines[i] = self.outline(i, center, yaw) if outline is None else outline
        if relocated:
            self.room_of[i] = self.room_at(i, center, yaw, default=int(self.room_of[i]))

    def inside_room(self, i: int, center: np.ndarray, yaw: float, room: int) -> bool:
        """Whether object i's footprint at a pose lies inside room ``room`` (flush against a wall is fine)."""
        outside = self.room_outside[room]
        return not len(outside) or float(self.depth(i, np.asarray(center, float)[None], yaw, outside).max()) <= ROOM_EPS

    def room_at(self, i: int, center: np.ndarray, yaw: float, default: int = -1) -> int:
        """Index of the room whose polygon holds object i's footprint at a pose, else ``default``."""
        return next((r for r in range(len(self.room_ids)) if self.inside_room(i, center, yaw, r)), default)


def _room_index(fp: Footprint, geometry: SceneGeometry, room_ids: list[str]) -> int:
    """Index of the object's own room by its true footprint (the first room when it touches none)."""
    rid = footprint_room(fp, geometry.rooms)
    return room_ids.index(rid) if rid is not None else (0 if room_ids else -1)


def _wall_ids_of(seg: np.ndarray, geometry: SceneGeometry) -> tuple[str, ...]:
    a, b = seg
    for w in geometry.walls:
        p0, p1 = np.array(w.p0), np.array(w.p1)
        u = p1 - p0
        n = float(np.linalg.norm(u))
        if n < 1e-9:
            continue
        u /= n
        on_line = all(abs(u[0] * (q - p0)[1] - u[1] * (q - p0)[0]) < 1e-3 for q in (a, b))
        if on_line and all(-1e-3 <= float(np.dot(q - p0, u)) <= n + 1e-3 for q in (a, b)):
            return w.wall_ids
    return ()


@dataclass(frozen=True)
class PlacementResult:
    """Requested vs achieved change of one object; all displacements are (x, z) in meters unless named units."""

    object_id: str
    requested: tuple[float, float]
    requested_units: tuple[float, float]
    requested_yaw: float | None
    achieved: tuple[float, float]
    achieved_units: tuple[float, float]
    yaw_before: float
    yaw_after: float
    rotation_applied: bool
    stop_reason: StopReason
    """The first limit met: the translation's stop, else ``rotation_blocked``, else ``reached``."""
    blocked_by: str | None = None
    """Object id, wall id, or door/window/open-wall id that stopped the object."""
    rotation_blocked_by: str | None = None
    steps: int = 0
    """Number of delta steps actually moved."""
    message: str = ""

    @property
    def changed(self) -> bool:
        return self.rotation_applied or self.achieved != (0.0, 0.0)


def _blocked_at(ctx: PlacementContext, i: int, center: np.ndarray, yaw: float) -> tuple[str, str | None] | None:
    """Scalar predicate of the reference loop: why the pose collides, or None when it is free."""
    center = np.asarray(center, dtype=float)
    r = ctx.reach(i) + ROOM_EPS
    sweep = np.array([center[0] - r, center[1] - r, center[0] + r, center[1] + r])
    hit = _first_collision(ctx, i, center[None], yaw, sweep)
    return None if hit is None else hit[1]


def _first_collision(ctx: PlacementContext, i: int, centers: np.ndarray, yaw: float, sweep: np.ndarray | None,
                     skip: frozenset[int] = frozenset(), room: int | None = None
                     ) -> tuple[int, tuple[str, str | None]] | None:
    """The first of K poses (centres, one yaw) that collides, and why; None when all are free.

    ``sweep`` (min x, min z, max x, max z) restricts the obstacles to those whose bounding box
    meets it, and ``skip`` lists pre-existing partners proven harmless along the path (pure
    speed-ups: every pose lies inside the sweep). Objects take precedence over the room when
    both stop the same pose. ``room``: the room the poses must stay in (default: the object's own).
    """
    k_count = len(centers)
    objs, outside = ctx.objects, ctx.room_outside[ctx.room_of[i] if room is None else room]

    def near(s: ConvexSet) -> np.ndarray:
        if sweep is None:
            return np.arange(len(s))
        a = s.aabb
        return np.nonzero((a[:, 0] < sweep[2]) & (a[:, 2] > sweep[0]) & (a[:, 1] < sweep[3]) & (a[:, 3] > sweep[1]))[0]

    cand = near(objs)  # pieces; ctx.owner maps them to objects
    cand = cand[ctx.owner[cand] != i]
    is_pre = np.array([(min(i, j), max(i, j)) in ctx.preexisting for j in ctx.owner[cand]], dtype=bool)
    pre = [int(j) for j in dict.fromkeys(ctx.owner[cand[is_pre]].tolist()) if j not in skip]
    plain = cand[~is_pre] if len(cand) else cand
    k_obj, who = k_count, -1
    if len(plain):
        depth = ctx.depth(i, centers, yaw, objs, plain)
        hit = np.nonzero(depth.max(axis=1) > OVERLAP_EPS)[0]
        if len(hit):
            k_obj = int(hit[0])
            who = int(ctx.owner[plain[int(depth[k_obj].argmax())]])
    k_room = k_count
    pieces = near(outside)
    if len(pieces):
        hit = np.nonzero(ctx.depth(i, centers, yaw, outside, pieces).max(axis=1) > ROOM_EPS)[0]
        if len(hit):
            k_room = int(hit[0])
    limit = min(k_obj, k_room)
    for j in pre:
        n = min(limit + 1, k_count)
        viol = np.nonzero(_pair_area(ctx, i, j, centers[:n], yaw) > ctx.preexisting[(min(i, j), max(i, j))])[0]
        if len(viol) and (viol[0] < k_obj or (viol[0] == k_obj and who < 0)):
            k_obj, who = int(viol[0]), j
            limit = min(k_obj, k_room)
    if k_obj < k_count and k_obj <= k_room:
        return k_obj, ("blocked_by_object", ctx.ids[who])
    if k_room < k_count:
        return k_room, _room_reason(ctx, i, centers[k_room], yaw)
    return None


def _room_reason(ctx: PlacementContext, i: int, center: np.ndarray, yaw: float) -> tuple[str, str | None]:
    """Why a pose that left its room did: a wall it crosses (``blocked_by_wall``) or an opening."""
    room = ctx.room_ids[ctx.room_of[i]]
    if len(ctx.walls):
        d = ctx.depth(i, center[None], yaw, ctx.walls)[0]
        if d.max() > ROOM_EPS:
            ids = ctx.wall_ids[int(d.argmax())]
            own = [w for w in ids if w.split("|")[1:2] == [room.split("|")[1]]]
            return "blocked_by_wall", (own or list(ids) or [None])[0]
    if len(ctx.openings):
        d = ctx.depth(i, center[None], yaw, ctx.openings)[0]
        if d.max() > 0:
            return "left_room", ctx.opening_ids[int(d.argmax())]
    return "left_room", None


def _pair_area(ctx: PlacementContext, i: int, j: int, centers: np.ndarray, yaw: float) -> np.ndarray:
    offsets = ctx.outline(i, np.zeros(2), yaw)
    polys = shapely.polygons(np.asarray(centers)[:, None, :] + offsets[None])
    other = shapely.Polygon(ctx.outlines[j])
    return shapely.area(shapely.intersection(polys, other))


def _march_poses(start: np.ndarray, d: np.ndarray, step: float) -> np.ndarray:
    dist = float(np.hypot(*d))
    if dist <= 0:
        return np.zeros((0, 2))
    n = max(1, math.ceil(dist / step - 1e-9))
    s = np.minimum(np.arange(1, n + 1) * step, dist)
    return start + s[:, None] * (d / dist)


def _yaw_changes(old: float, new: float | None) -> bool:
    if new is None:
        return False
    diff = (new - old) % 360.0
    return min(diff, 360.0 - diff) > 1e-9


def _check_request(ctx: PlacementContext, object_id: str, d: np.ndarray, yaw: float | None,
                   step: float) -> str | None:
    if object_id not in ctx.index:
        return f"no floor object has the id {object_id!r}"
    if not ctx.movable[ctx.index[object_id]]:
        return f"the object {object_id!r} is not movable (fixtures and wall decor stay put)"
    if not np.all(np.isfinite(d)) or (yaw is not None and not math.isfinite(yaw)):
        return "the requested displacement or rotation is not a finite number"
    if not step > 0:
        return f"the step delta must be positive, got {step}"
    return None


def _result(ctx: PlacementContext, object_id: str, d: np.ndarray, yaw: float | None, achieved: np.ndarray,
            yaw_before: float, yaw_after: float, rotated: bool, reason: StopReason, by: str | None,
            rot_by: str | None, steps: int, message: str = "") -> PlacementResult:
    upm = ctx.grid.units_per_meter
    return PlacementResult(object_id, (float(d[0]), float(d[1])), (float(d[0] * upm), float(d[1] * upm)),
                           None if yaw is None else float(yaw) % 360.0,
                           (float(achieved[0]), float(achieved[1])),
                           (float(achieved[0] * upm), float(achieved[1] * upm)), yaw_before, yaw_after, rotated,
                           reason, by, rot_by, steps, message)


def _rotate_first(ctx: PlacementContext, object_id: str, d: np.ndarray, yaw: float | None, step: float
                  ) -> PlacementResult | tuple[int, np.ndarray, float, float, bool, str | None]:
    """Check the request and turn in place when the turned footprint is free (the paper's first stage).

    Returns the ``invalid`` result for a bad request, else (index, start, old yaw, yaw to march with,
    whether it turned, what blocked the turn).
    """
    bad = _check_request(ctx, object_id, d, yaw, step)
    if bad:
        return PlacementResult(object_id, (float(d[0]), float(d[1])), (0.0, 0.0), yaw, (0.0, 0.0), (0.0, 0.0),
                               float("nan"), float("nan"), False, "invalid", None, None, 0, bad)
    i = ctx.index[object_id]
    start = ctx.centers[i].copy()
    yaw0 = float(ctx.yaws[i])
    if not _yaw_changes(yaw0, yaw):
        return i, start, yaw0, yaw0, False, None
    why = _blocked_at(ctx, i, start, float(yaw) % 360.0)
    if why is None:
        return i, start, yaw0, float(yaw) % 360.0, True, None
    return i, start, yaw0, yaw0, False, why[1]


def place(ctx: PlacementContext, object_id: str, dx: float, dz: float, yaw: float | None = None, *,
          step: float = DEFAULT_STEP, relocate: bool = False) -> PlacementResult:
    """Collision-aware placement of one object: turn in place if free, then march along (dx, dz) m.

    Args:
        ctx: the scene's placement context (not modified; call ``ctx.commit`` to keep the result).
        object_id: a movable floor object.
        dx, dz: requested displacement in meters (world x, z).
        yaw: requested new absolute yaw in degrees, or None to keep the current one.
        step: the march step delta (m).
        relocate: set the object down at the displacement's end, in whichever room holds it,
            instead of marching (nothing moves when that pose collides or fits no room).
    """
    d = np.array([dx, dz], dtype=float)
    first = _rotate_first(ctx, object_id, d, yaw, step)
    if isinstance(first, PlacementResult):
        return first
    i, start, yaw0, cur_yaw, rotated, rot_by = first
    if relocate:
        return _relocate(ctx, object_id, i, start, d, yaw, yaw0, cur_yaw, rotated, rot_by)
    poses = _march_poses(start, d, step)
    reason, by, k_stop = "reached", None, len(poses)
    if len(poses):
        r = ctx.reach(i) + ROOM_EPS
        sweep = np.array([min(start[0], poses[-1, 0]) - r, min(start[1], poses[-1, 1]) - r,
                          max(start[0], poses[-1, 0]) + r, max(start[1], poses[-1, 1]) + r])
        hit = _first_hit(ctx, i, poses, cur_yaw, sweep)
        if hit is not None:
            k_stop, (reason, by) = hit
    achieved = poses[k_stop - 1] - start if k_stop > 0 else np.zeros(2)
    if reason == "reached" and yaw is not None and _yaw_changes(yaw0, yaw) and not rotated:
        reason, by = "rotation_blocked", rot_by
    return _result(ctx, object_id, d, yaw, achieved, yaw0, cur_yaw, rotated, reason, by, rot_by, k_stop)


def _relocate(ctx: PlacementContext, object_id: str, i: int, start: np.ndarray, d: np.ndarray, yaw: float | None,
              yaw0: float, cur_yaw: float, rotated: bool, rot_by: str | None) -> PlacementResult:
    """The relocation of :func:`place`: one pose at the displacement's end, checked in the room that holds it."""
    end = start + d
    if not np.any(d):
        reason, by, k = "reached", None, 0
    else:
        room = ctx.room_at(i, end, cur_yaw, default=int(ctx.room_of[i]))
        hit = _first_collision(ctx, i, end[None], cur_yaw, None, room=room)
        reason, by = hit[1] if hit is not None else ("reached", None)
        k = 0 if hit is not None else 1
    achieved = d if k else np.zeros(2)
    if reason == "reached" and yaw is not None and _yaw_changes(yaw0, yaw) and not rotated:
        reason, by = "rotation_blocked", rot_by
    return _result(ctx, object_id, d, yaw, achieved, yaw0, cur_yaw, rotated, reason, by, rot_by, k)


def _first_hit(ctx: PlacementContext, i: int, poses: np.ndarray, yaw: float,
               sweep: np.ndarray) -> tuple[int, tuple[str, str | None]] | None:
    """Index of the first colliding pose and why, evaluating poses in growing chunks.

    A pre-existing partner that overlaps now and whose overlap area does not grow on the first
    step can never exceed its allowance later on the straight path (the square root of the area
    is concave along a translation, on an interval of the path, when both footprints are convex),
    so it is skipped.
    """
    skip = set()
    start = ctx.centers[i][None]
    for (a, b) in ctx.preexisting:
        if i in (a, b):
            j = b if a == i else a
            area = _pair_area(ctx, i, j, np.concatenate([start, poses[:1]]), yaw)
            convex = len(ctx.local_pieces[i]) == 1 and len(ctx.local_pieces[j]) == 1
            if convex and 0.0 < area[0] <= ctx.preexisting[(a, b)] and area[1] <= area[0]:
                skip.add(j)
    skip = frozenset(skip)
    lo, chunk = 0, 32
    while lo < len(poses):
        hi = min(len(poses), lo + chunk)
        hit = _first_collision(ctx, i, poses[lo:hi], yaw, sweep, skip)
        if hit is not None:
            return lo + hit[0], hit[1]
        lo, chunk = hi, chunk * 4
    return None


def reference_place(ctx: PlacementContext, object_id: str, dx: float, dz: float, yaw: float | None = None, *,
                    step: float = DEFAULT_STEP) -> PlacementResult:
    """The paper's march as a plain loop, one pose at a time against every obstacle (for tests)."""
    d = np.array([dx, dz], dtype=float)
    first = _rotate_first(ctx, object_id, d, yaw, step)
    if isinstance(first, PlacementResult):
        return first
    i, start, yaw0, cur_yaw, rotated, rot_by = first
    dist = float(np.hypot(*d))
    reason, by, pos, k = "reached", None, start.copy(), 0
    while dist > 0:
        s = min((k + 1) * step, dist)
        cand = start + s * (d / dist)
        why = _blocked_at(ctx, i, cand, cur_yaw)
        if why is not None:
            reason, by = why
            break
        pos, k = cand, k + 1
        if s >= dist:
            break
    if reason == "reached" and yaw is not None and _yaw_changes(yaw0, yaw) and not rotated:
        reason, by = "rotation_blocked", rot_by
    return _result(ctx, object_id, d, yaw, pos - start, yaw0, cur_yaw, rotated, reason, by, rot_by, k)


def place_units(ctx: PlacementContext, object_id: str, dx_units: float, dy_units: float,
                rotation: float | None = None, *, step: float = DEFAULT_STEP, relocate: bool = False) -> PlacementResult:
    """:func:`place` with the paper's grid units: +dx right (world +x), +dy up (world +z)."""
    m = 1.0 / ctx.grid.units_per_meter
    return place(ctx, object_id, dx_units * m, dy_units * m, rotation, step=step, relocate=relocate)
