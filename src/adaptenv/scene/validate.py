"""Semantic validation of a house: a pure function that returns every problem, never raising.

:func:`validate_house` checks what the pydantic model cannot: id formats, references between
rooms, walls, doors and windows, polygons, asset ids, objects placed inside the house and the
agent's start pose. :func:`validate_house_file` also turns unreadable, non-JSON and structurally
invalid files into problems, so ``adaptenv validate`` can list everything wrong with a file.

Example:
    >>> from adaptenv.scene.validate import validate_house_file
    >>> for problem in validate_house_file("house.json"):  # doctest: +SKIP
    ...     print(problem)
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import Point, Polygon

from adaptenv.errors import HouseError, Problem
from adaptenv.scene.assets import (
    ROOM_TYPES,
    TABLE_HINT,
    AssetCatalog,
    load_catalog,
    skipping_unknown_assets,
)
from adaptenv.scene.geometry import object_footprint, wall_floor_segment
from adaptenv.scene.model import (
    House,
    HouseObject,
    Opening,
    json_path,
    number_problems,
    parse_house,
    read_house_document,
)

#: How far (m) a floor object may stick out of the rooms before it counts as outside.
PLACEMENT_TOLERANCE = 0.01
#: How far (m) a child's centre may lie outside its parent's footprint.
CHILD_TOLERANCE = 0.1
#: How far (m) a door or window hole may run past either end of its wall.
HOLE_TOLERANCE = 0.01

ROOM_ID = re.compile(r"^room\|\d+$")
_NUM = r"-?\d+(?:\.\d+)?"
WALL_ID = re.compile(rf"^wall\|(?:\d+|exterior)\|{_NUM}\|{_NUM}\|{_NUM}\|{_NUM}$")


def validate_house(house: House, file: str | None = None, catalog: AssetCatalog | None = None, *,
                   skip_unknown: bool = False) -> list[Problem]:
    """Every semantic problem of a parsed house, grouped by check (empty when the house is valid); a
    house larger than any real one gets only those problems.

    Args:
        house: a house that passed structural parsing (:func:`~adaptenv.scene.house.parse_house`).
        file: the file name to put in each problem, if any.
        catalog: the asset catalog (default: the shipped ProcTHOR catalog).
        skip_unknown: the house's unknown child objects were left out (:func:`drop_unknown_children`), so
            an unknown top-level object is reported as one that cannot be left out.
    """
    catalog = catalog or load_catalog()
    if out := number_problems(house, file):  # a house edited in code may hold coordinates no file may
        return out

    def add(loc: tuple, message: str) -> None:
        out.append(Problem(json_path(loc), message, file))

    room_polys = _check_rooms(house, add)
    wall_ids = _check_walls(house, add)
    room_ids = {r.id for r in house.rooms}
    for kind, openings in (("doors", house.doors), ("windows", house.windows)):
        for i, op in enumerate(openings):
            _check_opening(house, op, (kind, i), wall_ids, room_ids, catalog, add)
    floor = shapely.union_all(list(room_polys.values())) if room_polys else None
    _check_objects(house, floor, catalog, add, skip_unknown)
    _check_agent(house, floor, add)
    return out


def drop_unknown_children(house: House, catalog: AssetCatalog | None = None) -> list[tuple[str, str]]:
    """Leave out, in place, every child object whose asset the catalog does not know (a small object
    resting on another: the agent never collides with it); returns (object id, asset id) of each."""
    catalog = catalog or load_catalog()
    dropped = []
    for obj in house.objects:
        unknown = [c for c in obj.children if c.assetId not in catalog.assets]
        if unknown:
            dropped += [(c.id, c.assetId) for c in unknown]
            obj.children = [c for c in obj.children if c.assetId in catalog.assets]
    return dropped


def dropped_children_line(houses: list[House], of: int | None = None) -> str | None:
    """One line counting the child objects of unknown assets left out of ``houses`` (None when none were);
    ``of`` is the number of houses read, when it is a set (some may have failed to load)."""
    dropped = [d for h in houses for d in h.dropped_children]
    if not dropped:
        return None
    where = "" if of is None else f" in {sum(bool(h.dropped_children) for h in houses)} of {of} houses"
    ids = len({a for _, a in dropped})
    return (f"left out {len(dropped)} object{'s' if len(dropped) != 1 else ''} resting on others{where}, of "
            f"{ids} unknown asset id{'s' if ids != 1 else ''} (--skip-unknown-assets; the agent never collides "
            "with them, and targets are floor objects)")


def validate_read_house(house: House, file: str | None = None, catalog: AssetCatalog | None = None, *,
                        skip_unknown: bool | None = None, validate: bool = True) -> list[Problem]:
    """The problems of a house just read (none when not ``validate``), after leaving out its child objects
    of unknown assets when ``skip_unknown`` (default: :func:`~adaptenv.scene.assets.skipping_unknown_assets`);
    the house records them in ``House.dropped_children``."""
    skip = skipping_unknown_assets() if skip_unknown is None else skip_unknown
    if skip:
        house._dropped_children = [*house.dropped_children, *drop_unknown_children(house, catalog)]
    return validate_house(house, file=file, catalog=catalog, skip_unknown=skip) if validate else []


def validate_house_file(path: str | Path) -> list[Problem]:
    """Every problem of a house file, including unreadable, non-JSON and structurally invalid ones."""
    return read_and_validate(path)[1]


def read_and_validate(path: str | Path) -> tuple[House | None, list[Problem]]:
    """A house file as read (None when it cannot be parsed; its ``dropped_children`` say what
    ``--skip-unknown-assets`` left out) and every problem of it (:func:`validate_house_file`)."""
    try:
        doc = read_house_document(path)
        house = parse_house(doc, str(path))
    except HouseError as err:
        return None, list(err.problems)
    return house, validate_read_house(house, file=str(path))


def _distinct_vertices(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Vertices with consecutive repeats and a repeated closing vertex dropped."""
    out: list[tuple[float, float]] = []
    for p in points:
        if not out or p != out[-1]:
            out.append(p)
    if len(out) > 1 and out[0] == out[-1]:
        out.pop()
    return out


def _check_rooms(house: House, add) -> dict[str, Polygon]:
    """Room ids, types and floor polygons; returns the valid polygons by room id."""
    if not house.rooms:
        add(("rooms",), "the house has no rooms; add at least one room with a floor polygon")
    seen: dict[str, int] = {}
    polys: dict[str, Polygon] = {}
    for i, room in enumerate(house.rooms):
        if not ROOM_ID.match(room.id):
            add(("rooms", i, "id"), f"the room id {room.id!r} is not of the form 'room|N'; rename it, e.g. 'room|2'")
        if room.id in seen:
            add(("rooms", i, "id"), f"the room id {room.id!r} is already used by rooms[{seen[room.id]}]; "
                "give every room a unique id")
        seen.setdefault(room.id, i)
        if room.roomType not in ROOM_TYPES:
            add(("rooms", i, "roomType"), f"the room type {room.roomType!r} is unknown; use one of {', '.join(ROOM_TYPES)}")
        pts = _distinct_vertices([(p.x, p.z) for p in room.floorPolygon])
        loc = ("rooms", i, "floorPolygon")
        if len(set(pts)) < 3:
            add(loc, f"the floor polygon has {len(set(pts))} distinct vertices and cannot enclose a floor; "
                "list at least 3 distinct (x, z) corners in order")
            continue
        poly = Polygon(pts)
        if poly.convex_hull.area <= 1e-9:
            add(loc, "the floor polygon is degenerate (zero area: its vertices are collinear); "
                "list the room's corners in order around the floor")
        elif not poly.is_valid or poly.area <= 1e-9:
            reason = shapely.is_valid_reason(poly)
            add(loc, f"the floor polygon is not simple ({reason}); order its corners so the edges do not cross")
        else:
            polys[room.id] = poly
    return polys


def _check_walls(house: House, add) -> set[str]:
    """Wall ids, rooms and polygons; returns the set of wall ids."""
    room_ids = {r.id for r in house.rooms}
    seen: dict[str, int] = {}
    for i, wall in enumerate(house.walls):
        if not WALL_ID.match(wall.id):
            add(("walls", i, "id"), f"the wall id {wall.id!r} does not parse as 'wall|room|minX|minZ|maxX|maxZ'; "
                "rename it, e.g. 'wall|2|0.00|0.00|4.00|0.00'")
        if wall.id in seen:
            add(("walls", i, "id"), f"the wall id {wall.id!r} is already used by walls[{seen[wall.id]}]; "
                "give every wall a unique id")
        seen.setdefault(wall.id, i)
        if wall.roomId != "exterior" and wall.roomId not in room_ids:
            add(("walls", i, "roomId"), f"the wall's room {wall.roomId!r} does not exist; "
                "use the id of an existing room or 'exterior'")
        if len(wall.polygon) != 4:
            add(("walls", i, "polygon"), f"the wall polygon has {len(wall.polygon)} vertices, not 4; "
                "list the two floor corners and the same two at ceiling height")
    return set(seen)


def _check_opening(house: House, op: Opening, loc: tuple, wall_ids: set[str], room_ids: set[str],
                   catalog: AssetCatalog, add) -> None:
    """References, asset id and hole of one door or window."""
    what = "door" if loc[0] == "doors" else "window"
    for key in ("wall0", "wall1"):
        wid = getattr(op, key)
        if wid not in wall_ids:
            add((*loc, key), f"the {what} names the wall {wid!r}, which does not exist; "
                "use the id of one of the house's walls")
    for key in ("room0", "room1"):
        rid = getattr(op, key)
        if rid not in room_ids:
            add((*loc, key), f"the {what} names the room {rid!r}, which does not exist; "
                "use the id of one of the house's rooms")
    if op.assetId not in catalog.assets:
        add((*loc, "assetId"), f"the assetId {op.assetId!r} is not a ProcTHOR asset; use an id from the asset catalog")
    hole = op.holePolygon
    if len(hole) != 2:
        add((*loc, "holePolygon"), f"the hole polygon has {len(hole)} points, not 2; "
            "give its [min, max] corners in wall0-local coordinates")
        return
    lo, hi = min(hole[0].x, hole[1].x), max(hole[0].x, hole[1].x)
    if hi - lo <= 1e-6:
        add((*loc, "holePolygon"), "the hole has zero width; give min and max corners with different x")
        return
    wall = next((w for w in house.walls if w.id == op.wall0), None)
    if wall is None or len(wall.polygon) < 2:
        return
    p0, p1 = wall_floor_segment(wall)
    length = float(np.linalg.norm(p1 - p0))
    if lo < -HOLE_TOLERANCE or hi > length + HOLE_TOLERANCE:
        add((*loc, "holePolygon"), f"the hole spans {lo:.2f}..{hi:.2f} m along wall0, outside the wall's "
            f"length 0..{length:.2f} m; move the hole onto the wall")


def _check_objects(house: House, floor, catalog: AssetCatalog, add, skip_unknown: bool = False) -> None:
    """Asset ids, unique ids and placement of top-level objects and their children."""
    seen: dict[str, str] = {}
    tops: list[tuple[int, str, np.ndarray]] = []  # (index, role, true footprint outline)
    kids: list[tuple[int, int, np.ndarray | None]] = []  # (parent index, child index, parent outline)
    unknown: dict[str, tuple] = {}  # unknown asset id -> location of its first use
    for i, obj in enumerate(house.objects):
        found = _check_object(obj, ("objects", i), seen, catalog, add, unknown, is_child=False)
        if found is not None:
            tops.append((i, *found))
        for j, child in enumerate(obj.children):
            if _check_object(child, ("objects", i, "children", j), seen, catalog, add, unknown,
                             is_child=True) is not None:
                kids.append((i, j, found[1] if found is not None else None))
    tops_unknown = [(i, o) for i, o in enumerate(house.objects) if o.assetId in unknown]
    if skip_unknown and tops_unknown:
        _unknown_top_level(tops_unknown, add)
    elif unknown:
        first = ", ".join(repr(a) for a in list(unknown)[:3])
        add((*next(iter(unknown.values())), "assetId"),
            f"{len(unknown)} assetId{'s are' if len(unknown) > 1 else ' is'} in neither the ProcTHOR catalog nor an "
            f"--assets table (first: {first}); pass --assets FILE with a table of your assets (asset id -> "
            f"object type and bounding box, see docs/scene.md); {TABLE_HINT}")
    if floor is None:
        return
    floor_tol = floor.buffer(PLACEMENT_TOLERANCE)
    shapely.prepare(floor_tol)
    bbox = Polygon.from_bounds(*floor.bounds).buffer(PLACEMENT_TOLERANCE)
    objs = house.objects
    inside = shapely.covers(floor_tol, [Polygon(c) for _, _, c in tops])
    centers = np.array([(objs[i].position.x, objs[i].position.z) for i, _, _ in tops]).reshape(-1, 2)
    in_bbox = shapely.covers(bbox, shapely.points(centers))
    for (i, role, _), ok, ok_bbox in zip(tops, inside, in_bbox, strict=True):
        o = objs[i]
        if role == "floor" and not ok:
            add(("objects", i, "position"), f"the footprint of {o.id!r} ({o.assetId}) at (x={o.position.x:.2f}, "
                f"z={o.position.z:.2f}) is not inside any room; move it inside a room's floor polygon")
        elif role != "floor" and not ok_bbox:
            add(("objects", i, "position"), f"the object {o.id!r} ({o.assetId}) at (x={o.position.x:.2f}, z={o.position.z:.2f}) "
                "is outside the house; move it onto one of the house's walls")
    if not kids:
        return
    pts = shapely.points([(objs[i].children[j].position.x, objs[i].children[j].position.z) for i, j, _ in kids])
    in_room = shapely.covers(floor_tol, pts)
    for (i, j, corners), pt, ok in zip(kids, pts, in_room, strict=True):
        if ok or (corners is not None and Polygon(corners).distance(pt) <= CHILD_TOLERANCE):
            continue
        c = objs[i].children[j]
        add(("objects", i, "children", j, "position"), f"the object {c.id!r} ({c.assetId}) at (x={c.position.x:.2f}, "
            f"z={c.position.z:.2f}) is neither on its parent {objs[i].id!r} nor inside a room; move it onto its parent")


def _unknown_top_level(tops: list[tuple[int, HouseObject]], add) -> None:
    """One problem naming the top-level objects (index, object) of unknown assets, which --skip-unknown-assets
    cannot leave out."""
    objs = [o for _, o in tops]
    first = ", ".join(f"{o.id!r} (assetId {o.assetId!r})" for o in objs[:3])
    add(("objects", tops[0][0], "assetId"),
        f"{len(objs)} top-level object{'s have assets' if len(objs) > 1 else ' has an asset'} in neither the "
        f"ProcTHOR catalog nor an --assets table ({'first: ' if len(objs) > 3 else ''}{first}); "
        "--skip-unknown-assets leaves out only objects resting on others, since an object of unknown size "
        "standing in the house would block the agent unseen; build a table with `adaptenv assets from-objathor "
        "ANNOTATIONS -o TABLE` and pass --assets TABLE")


def _check_object(obj: HouseObject, loc: tuple, seen: dict[str, str], catalog: AssetCatalog,
                  add, unknown: dict[str, tuple], *, is_child: bool) -> tuple[str, np.ndarray] | None:
    """Unique id and known asset of one object (unknown ids are collected in ``unknown``); returns
    (role, true footprint outline) when the asset is known."""
    if obj.id in seen:
        add((*loc, "id"), f"the object id {obj.id!r} is already used by {seen[obj.id]}; give every object a unique id")
    else:
        seen[obj.id] = json_path(loc)
    asset = catalog.assets.get(obj.assetId)
    if asset is None:
        unknown.setdefault(obj.assetId, loc)
        return None
    if is_child:
        return "small", np.empty((0, 2))
    fp = object_footprint(obj, catalog)
    return fp.role, fp.outline


def _check_agent(house: House, floor, add) -> None:
    """The start pose(s) in metadata must stand inside a room."""
    if floor is None:
        return
    floor_tol = floor.buffer(PLACEMENT_TOLERANCE)
    poses = []
    if house.metadata.agent is not None:
        poses.append((("metadata", "agent", "position"), house.metadata.agent))
    for kind, pose in (house.metadata.agentPoses or {}).items():
        poses.append((("metadata", "agentPoses", kind, "position"), pose))
    for loc, pose in poses:
        if not floor_tol.covers(Point(pose.position.x, pose.position.z)):
            add(loc, f"the agent start (x={pose.position.x:.2f}, z={pose.position.z:.2f}) is outside every room; "
                "move it inside a room (e.g. with House.set_agent_pose)")
