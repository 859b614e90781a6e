"""The paper's scene graph e = (O, A, R): objects, their attributes and pairwise relations.

Objects ``O`` are the house's objects (top-level and children), each an :class:`ObjectNode` whose
fields are the attributes ``A`` (type, asset, position, yaw, size, role, movability, room, grid
position). Relations ``R`` are :class:`Relation` triples ``(kind, subject, object)``:

- ``in_room``: object -> room id (the room containing the object).
- ``on``: child -> parent (a small object resting on furniture).
- ``next_to``: floor object <-> floor object whose footprints are within :data:`NEXT_TO_DISTANCE`
  with no wall between them. Symmetric; stored once per pair.

Footprints are the true floor outlines (:attr:`adaptenv.scene.geometry.Footprint.polygon`, the
shape the simulator uses): an object standing in the floor an L counter wraps around is ``next_to``
it only when it comes within :data:`NEXT_TO_DISTANCE` of an arm, and ``faces`` rays hit the arms.
- ``against_wall``: object -> wall id (the side in the object's room); its footprint's back edge
  runs alongside a blocking wall within :data:`AGAINST_WALL_DISTANCE` and its front points away
  from that wall (within :data:`AGAINST_WALL_ANGLE`).
- ``faces``: object -> object; the ray from the middle of A's front edge along its heading hits
  B's footprint within :data:`FACES_RANGE` before any wall (a sofa faces a TV, a chair its table;
  every object along the ray counts, so chairs across a table face each other too).

Example:
    >>> from adaptenv.scene.graph import build_scene_graph
    >>> g = build_scene_graph(house)  # doctest: +SKIP
    >>> [r.object for r in g.relations_of("faces") if r.subject == "Sofa|3|3"]  # doctest: +SKIP
    ['TVStand|3|1|0']
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

import numpy as np
import shapely

from adaptenv.scene.assets import AssetCatalog, ObjectRole, load_catalog
from adaptenv.scene.geometry import (
    Footprint,
    SceneGeometry,
    WallSegment,
    footprint_room,
    heading,
    object_footprint,
)
from adaptenv.scene.house import House

RelationKind = Literal["in_room", "on", "next_to", "against_wall", "faces"]
RELATION_KINDS: tuple[str, ...] = ("in_room", "on", "next_to", "against_wall", "faces")
SYMMETRIC_KINDS = frozenset({"next_to"})

#: Floor footprints at most this far apart (m) are ``next_to`` each other.
NEXT_TO_DISTANCE = 0.5
#: A back edge at most this far (m) from a wall is ``against_wall``.
AGAINST_WALL_DISTANCE = 0.15
#: The front must point within this angle (degrees) of the wall's inward normal.
AGAINST_WALL_ANGLE = 30.0
#: The back edge must run alongside the wall for at least this length (m).
MIN_WALL_OVERLAP = 0.05
#: How far (m) in front of an object's front edge ``faces`` looks.
FACES_RANGE = 3.0


@dataclass(frozen=True)
class Relation:
    """One edge of the scene graph: ``subject`` is ``kind`` ``object`` (e.g. a cup is ``on`` a table)."""

    kind: RelationKind
    subject: str
    object: str


@dataclass(frozen=True)
class ObjectNode:
    """One object and its attributes (world meters; ``grid`` is the paper's 0..100 map position)."""

    id: str
    type: str
    asset_id: str
    position: tuple[float, float, float]
    yaw: float
    size: tuple[float, float, float]
    """Full bounding-box extents (x, y, z) in the object's local frame, m."""
    role: ObjectRole
    movable: bool
    room: str | None
    grid: tuple[float, float]
    parent: str | None = None


@dataclass
class SceneGraph:
    """Objects (by id), rooms (id -> type) and the relations between them."""

    nodes: dict[str, ObjectNode]
    rooms: dict[str, str]
    relations: list[Relation] = field(default_factory=list)

    def relations_of(self, kind: RelationKind) -> list[Relation]:
        """All relations of one kind, in construction order."""
        return [r for r in self.relations if r.kind == kind]

    def has(self, kind: RelationKind, subject: str, obj: str) -> bool:
        """Whether the relation holds (either order for symmetric kinds such as ``next_to``)."""
        for r in self.relations:
            if r.kind == kind and ((r.subject, r.object) == (subject, obj)
                                   or (kind in SYMMETRIC_KINDS and (r.subject, r.object) == (obj, subject))):
                return True
        return False

    def neighbors(self, object_id: str, kind: RelationKind | None = None) -> list[str]:
        """Ids (objects, rooms or walls) related to ``object_id`` in either direction, sorted."""
        out = set()
        for r in self.relations:
            if kind is not None and r.kind != kind:
                continue
            if r.subject == object_id:
                out.add(r.object)
            elif r.object == object_id:
                out.add(r.subject)
        return sorted(out)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form: ``{"rooms": {...}, "nodes": {id: attributes}, "relations": [...]}``."""
        return {"rooms": dict(self.rooms), "nodes": {k: asdict(v) for k, v in self.nodes.items()},
                "relations": [asdict(r) for r in self.relations]}


def build_scene_graph(house: House, geometry: SceneGeometry | None = None,
                      catalog: AssetCatalog | None = None, kinds: tuple[str, ...] = RELATION_KINDS) -> SceneGraph:
    """Build the scene graph of a (valid) house; pass ``geometry`` if you already have it.

    ``kinds`` limits the relations computed (all nodes are always built): scoring loops that read
    one relation skip the cost of the others.
    """
    unknown = set(kinds) - set(RELATION_KINDS)
    if unknown:
        raise ValueError(f"build_scene_graph: unknown relation kinds {sorted(unknown)}; use {RELATION_KINDS}")
    catalog = catalog or load_catalog()
    geometry = geometry or SceneGeometry.from_house(house, catalog)
    grid = geometry.grid
    blocking = shapely.linestrings(geometry.blocking_segments())
    blocking_tree = shapely.STRtree(blocking)
    tops = {f.object_id: f for f in geometry.footprints}
    items = []
    for obj, parent in house.iter_objects():
        fp = tops.get(obj.id) if parent is None else None
        items.append((obj, parent, fp or object_footprint(obj, catalog, is_child=parent is not None)))
    rooms = _rooms_of([fp for _, _, fp in items], geometry)

    nodes: dict[str, ObjectNode] = {}
    relations: list[Relation] = []
    for (obj, parent, fp), room in zip(items, rooms, strict=True):
        if room is None and parent is not None:
            room = nodes[parent.id].room
        gx, gy = grid.point(obj.position.x, obj.position.z)
        nodes[obj.id] = ObjectNode(obj.id, fp.object_type, obj.assetId,
                                   (obj.position.x, obj.position.y, obj.position.z), fp.yaw,
                                   catalog.asset(obj.assetId).size, fp.role, fp.movable, room, (gx, gy),
                                   parent.id if parent is not None else None)
        if room is not None and "in_room" in kinds:
            relations.append(Relation("in_room", obj.id, room))
        if parent is not None and "on" in kinds:
            relations.append(Relation("on", obj.id, parent.id))

    placed = [f for f in geometry.footprints if f.role in ("floor", "wall")]
    if "next_to" in kinds:
        relations += _next_to(geometry.floor_objects, blocking_tree, blocking)
    if "against_wall" in kinds:
        relations += _against_wall(placed, nodes, geometry.walls, blocking)
    if "faces" in kinds:
        relations += _faces(placed, blocking_tree, blocking)
    return SceneGraph(nodes, dict(geometry.room_types), relations)


def _rooms_of(footprints: list[Footprint], geometry: SceneGeometry) -> list[str | None]:
    """Room of each object: the room covering its centre nudged 5 cm forward (so wall decor lands in
    the room it faces), else its centre, else the room its footprint overlaps most; objects with a
    shape of their own (L and C counters) by :func:`~adaptenv.scene.geometry.footprint_room`."""
    centres = np.array([fp.center for fp in footprints], dtype=float).reshape(-1, 2)
    fronts = np.array([heading(fp.yaw) for fp in footprints], dtype=float).reshape(-1, 2)
    out: list[str | None] = [None] * len(footprints)
    for pts in (shapely.points(centres + 0.05 * fronts), shapely.points(centres)):
        for rid, poly in geometry.rooms.items():
            for k in np.flatnonzero(shapely.covers(poly, pts)):
                if out[k] is None:
                    out[k] = rid
    for k, fp in enumerate(footprints):
        if out[k] is None or fp.shape is not None:  # an L counter's centre may lie off its outline
            out[k] = footprint_room(fp, geometry.rooms)
    return out


def _next_to(floor: list[Footprint], tree: shapely.STRtree, blocking: np.ndarray) -> list[Relation]:
    """Pairs of floor footprints within NEXT_TO_DISTANCE whose shortest link crosses no wall."""
    polys = np.array([f.polygon for f in floor], dtype=object)
    if len(polys) < 2:
        return []
    a_idx, b_idx = shapely.STRtree(polys).query(polys, predicate="dwithin", distance=NEXT_TO_DISTANCE)
    out = []
    for a, b in zip(a_idx, b_idx, strict=True):
        if a >= b:
            continue
        link = shapely.shortest_line(polys[a], polys[b])
        if link.length > 1e-9 and len(tree.query(link, predicate="crosses")):
            continue
        out.append(Relation("next_to", floor[a].object_id, floor[b].object_id))
    return out


def _wall_id(wall: WallSegment, room: str | None) -> str:
    """The id of the wall's side that belongs to ``room`` (any side when unknown)."""
    if room is not None:
        number = room.split("|")[-1]
        for wid in wall.wall_ids:
            if wid.split("|")[1] == number:
                return wid
    return wall.wall_ids[0]


def backs_onto(fp: Footprint, p0: np.ndarray, p1: np.ndarray, min_cos: float) -> bool:
    """Whether the footprint's front faces away from the wall p0-p1 (within ``acos(min_cos)``) and its back edge
    overlaps the wall by MIN_WALL_OVERLAP or more (distance is the caller's test).

    Computed in Python floats; :func:`_backs_onto_arrays`, its definition, decides whenever a value lies within
    1e-9 of its limit, where the two roundings could disagree.
    """
    x0, z0, x1, z1 = float(p0[0]), float(p0[1]), float(p1[0]), float(p1[1])
    length = max(math.sqrt((x1 - x0) * (x1 - x0) + (z1 - z0) * (z1 - z0)), 1e-12)  # np.linalg.norm's arithmetic
    ux, uz = (x1 - x0) / length, (z1 - z0) / length
    nx, nz = -uz, ux
    side = nx * (fp.center[0] - x0) + nz * (fp.center[1] - z0)
    if side < 0:
        nx, nz = -nx, -nz
    a, b = sorted((cx - x0) * ux + (cz - z0) * uz for cx, cz in fp.corners[:2].tolist())
    yaw = math.radians(fp.yaw)  # heading(fp.yaw) is (sin, cos) of it
    facing = math.sin(yaw) * nx + math.cos(yaw) * nz - min_cos
    overlap = min(b, length) - max(a, 0.0) - MIN_WALL_OVERLAP
    if min(abs(side), abs(facing), abs(overlap)) <= 1e-9:
        return _backs_onto_arrays(fp, p0, p1, min_cos)
    return facing >= 0 and overlap >= 0


def _backs_onto_arrays(fp: Footprint, p0: np.ndarray, p1: np.ndarray, min_cos: float) -> bool:
    """:func:`backs_onto` as numpy arrays (its definition)."""
    length = max(float(np.linalg.norm(p1 - p0)), 1e-12)
    u = (p1 - p0) / length
    normal = np.array([-u[1], u[0]])
    if np.dot(normal, np.array(fp.center) - p0) < 0:
        normal = -normal
    t = sorted(float(np.dot(c - p0, u)) for c in fp.corners[:2])
    return float(np.dot(heading(fp.yaw), normal)) >= min_cos and min(t[1], length) - max(t[0], 0.0) >= MIN_WALL_OVERLAP


def _against_wall(placed: list[Footprint], nodes: dict[str, ObjectNode], walls: list[WallSegment],
                  blocking: np.ndarray) -> list[Relation]:
    """Objects whose back edge runs within AGAINST_WALL_DISTANCE of a blocking wall they face away from."""
    solid = [w for w in walls if not w.empty]
    if not solid or not len(blocking) or not placed:
        return []
    lines = shapely.linestrings([[w.p0, w.p1] for w in solid])
    backs = shapely.linestrings(np.array([fp.corners[:2] for fp in placed]))
    near_blocking = shapely.distance(backs, shapely.multilinestrings(list(blocking))) <= AGAINST_WALL_DISTANCE
    near = shapely.distance(backs[:, None], lines[None, :]) <= AGAINST_WALL_DISTANCE
    min_cos = math.cos(math.radians(AGAINST_WALL_ANGLE))
    out = []
    for i, k in zip(*np.nonzero(near & near_blocking[:, None]), strict=True):
        fp = placed[i]
        if backs_onto(fp, np.array(solid[k].p0), np.array(solid[k].p1), min_cos):
            out.append(Relation("against_wall", fp.object_id, _wall_id(solid[k], nodes[fp.object_id].room)))
    return out


def _faces(placed: list[Footprint], tree: shapely.STRtree, blocking: np.ndarray) -> list[Relation]:
    """A faces B when A's front ray (from its front edge, FACES_RANGE long, cut at walls) hits B."""
    if len(placed) < 2:
        return []
    fronts = np.array([heading(fp.yaw) for fp in placed])
    starts = np.array([fp.center for fp in placed]) + fronts * np.array([fp.size[1] / 2.0 for fp in placed])[:, None]
    reach = np.full(len(placed), FACES_RANGE)
    rays = shapely.linestrings(np.stack([starts, starts + fronts * FACES_RANGE], axis=1))
    ray_idx, wall_idx = tree.query(rays, predicate="intersects")
    if len(ray_idx):
        hits = shapely.intersection(rays[ray_idx], blocking[wall_idx])
        dist = shapely.distance(shapely.points(starts[ray_idx]), hits)
        np.minimum.at(reach, ray_idx, dist)
    rays = shapely.linestrings(np.stack([starts, starts + fronts * reach[:, None]], axis=1))
    polys = np.array([fp.polygon for fp in placed], dtype=object)
    ray_idx, target_idx = shapely.STRtree(polys).query(rays, predicate="intersects")
    order = np.lexsort((target_idx, ray_idx))
    return [Relation("faces", placed[i].object_id, placed[j].object_id)
            for i, j in zip(ray_idx[order], target_idx[order], strict=True) if i != j and reach[i] > 1e-6]
