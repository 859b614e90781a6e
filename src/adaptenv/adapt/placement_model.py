"""The placement model: where objects of each type stand in homes, learned from houses.

A person judges a moved object by a few things they read at a glance. Per floor object (:func:`object_features`):

- ``wall_distance``: m from its footprint to the nearest blocking wall (walls minus passable doorways and open
  connections);
- ``wall_angle``: degrees between its heading and the normal of that wall pointing into the room (0: back to the
  wall, facing the room; 90: side to it; 180: facing it), the smallest over the walls within 0.15 m of the nearest;
  not read for a small, nearly square object (:func:`looks_symmetric`: a bin or a plant looks the same turned);
- ``anchor_distance``: m between its footprint and the nearest footprint of its group's anchor type in its room
  (:func:`anchors`: chairs to a dining table or desk, nightstands to a bed, ...);
- ``anchor_facing``: the share of its width that faces that anchor's footprint (straight ahead within
  :data:`FACING_REACH` m of its front edge, or under it), by footprint, not centre to centre: 1 for a chair square
  at a table's edge, 0 for one at the corner facing along the table;
- ``member_gap``: m to the nearest other object of its type at the same anchor (a chair to the next chair);
- ``isolation``: m to the nearest wall or other floor object (how far into open floor it stands);
- ``door_distance``: m to the nearest passable doorway or open connection between rooms (the opening's line);
- ``route_distance``: m to the room's walking routes: the shortest paths, in the empty room kept
  :data:`ROUTE_CLEARANCE` m from its walls, between every two of its doorways and open connections.

:class:`PlacementModel` holds, per object type, the 1st, 50th and 99th percentile of each feature over a reference
set of houses (:func:`fit`), by default houses of adaptenv's procedural generator (shipped as
``adapt/data/placement_reference.json``, rebuilt by ``python tools/build_placement_reference.py``). A value is
unlike the reference when it lies outside the central 98% (below the 1st or above the 99th percentile) on the side
a person reads (:data:`TAILS`: too far from the wall, too close to a doorway) by more than :data:`TOLERANCE`. A type
with fewer than :data:`MIN_SAMPLES` values of a feature falls back to its placement class (ProcTHOR's annotations:
``edge`` for types placed only along walls or in corners, ``middle`` for types also placed in the middle of a room),
then to all objects.
"""

from __future__ import annotations

import gzip
import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Literal

import numpy as np
import shapely
import shapely.ops
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import shortest_path

from adaptenv.errors import ConfigError
from adaptenv.scene.assets import AssetCatalog, load_catalog
from adaptenv.scene.geometry import (
    Footprint,
    SceneGeometry,
    footprint_corners,
    heading,
    pose_outline,
    yaw_axes,
)
from adaptenv.scene.graph import AGAINST_WALL_DISTANCE
from adaptenv.scene.house import House

FEATURES = ("wall_distance", "wall_angle", "anchor_distance", "anchor_facing", "member_gap", "isolation",
            "door_distance", "route_distance")
#: Which side of the reference's central 98% a person finds wrong.
TAILS: dict[str, Literal["low", "high"]] = {
    "wall_distance": "high", "wall_angle": "high", "anchor_distance": "high", "anchor_facing": "low",
    "member_gap": "low", "isolation": "high", "door_distance": "low", "route_distance": "low"}
#: Units of each feature, for messages.
UNITS = {f: {"wall_angle": "degrees", "anchor_facing": "of its width"}.get(f, "m") for f in FEATURES}
#: How far past the reference's percentile (and past where it stood) a value must lie to count (m, degrees, share):
#: 0.15 m for the distances to the walls and to the nearest object (the scene graph's ``against_wall`` distance: a
#: person sees an object that close to a wall as standing against it), 0.05 m for the other distances.
TOLERANCE = {f: {"wall_angle": 10.0, "anchor_facing": 0.1, "wall_distance": AGAINST_WALL_DISTANCE,
                 "isolation": AGAINST_WALL_DISTANCE}.get(f, 0.05) for f in FEATURES}
#: How far ahead of its front edge (m) an object faces its anchor.
FACING_REACH = 1.0
#: Percentiles bounding the central 98%.
LOW_Q, HIGH_Q = 0.01, 0.99
#: A type with fewer values of a feature than this falls back to its placement class, then to all objects.
MIN_SAMPLES = 30
#: The walking routes keep this far (m) from the walls (an agent's radius plus a margin).
ROUTE_CLEARANCE = 0.3
#: Walls within this much (m) of the nearest one also count for ``wall_angle`` (an object in a corner).
WALL_TIE = AGAINST_WALL_DISTANCE
#: ``wall_angle`` is not read for an object this small (m^2 footprint) and this nearly square (longer side over
#: shorter): a bin, a plant, a lamp or a box looks the same turned.
SYMMETRIC_AREA, SYMMETRIC_RATIO = 0.35, 1.25
#: Anchors beyond ProcTHOR's floor asset groups: nightstands to their bed.
EXTRA_ANCHORS: dict[str, tuple[str, ...]] = {"SideTable": ("Bed",)}
#: Where the shipped reference lives (package data).
REFERENCE_RESOURCE = "data/placement_reference.json"


@cache
def group_pairs() -> tuple[tuple[str, str, str], ...]:
    """(anchor type, member type, group name) of ProcTHOR's floor asset groups (members placed ``nextTo``)."""
    doc = json.loads(resources.files("adaptenv.scene").joinpath("data/asset_groups.json").read_text("utf-8"))
    out: dict[tuple[str, str], str] = {}
    for p in doc["pairs"]:
        if p["relation"] == "nextTo":
            out.setdefault((p["anchor"], p["member"]), p["group"].rstrip("-0123456789"))
    return tuple((a, m, g) for (a, m), g in out.items())


@cache
def anchors() -> dict[str, tuple[str, ...]]:
    """Member type -> the types it stands with: ProcTHOR's floor asset groups plus EXTRA_ANCHORS."""
    out: dict[str, tuple[str, ...]] = dict(EXTRA_ANCHORS)
    for a, m, _ in group_pairs():
        out[m] = (*out.get(m, ()), a)
    return out


def anchor_types(object_type: str) -> tuple[str, ...]:
    """The types a member of this type stands with (empty for types that are no group member)."""
    return anchors().get(object_type, ())


def placement_class(catalog: AssetCatalog, object_type: str) -> str:
    """``edge`` for a type ProcTHOR places only along walls or in corners, ``middle`` for one it also places in the
    middle of a room."""
    return "middle" if catalog.type_info(object_type).in_middle else "edge"


@dataclass(frozen=True)
class HouseLayout:
    """What the features read from a house's structure (walls, doorways, routes); built once per house."""

    rooms: dict[str, shapely.Polygon]
    walls: np.ndarray
    """(N, 2, 2) blocking wall segments."""
    wall_lines: np.ndarray
    wall_union: shapely.Geometry
    doorways: shapely.Geometry
    """Passable doorways and open connections between rooms, as lines (empty when none)."""
    routes: dict[str, shapely.Geometry]
    """Room id -> its walking routes (lines; empty geometry for a room with fewer than two doorways)."""
    _room_of: dict[tuple[float, float], str | None] = field(default_factory=dict, compare=False, repr=False)

    @classmethod
    def of(cls, geometry: SceneGeometry) -> HouseLayout:
        seg = geometry.blocking_segments().reshape(-1, 2, 2)
        lines = shapely.linestrings(seg) if len(seg) else np.array([], dtype=object)
        ways = [((d.p0, d.p1), d.rooms) for d in geometry.doors if d.passable]
        ways += [((w.p0, w.p1), w.rooms) for w in geometry.walls if w.empty and len(set(w.rooms)) == 2]
        door_lines = [shapely.LineString(p) for p, _ in ways]
        routes = {rid: walking_routes(poly, [shapely.LineString(p) for p, rooms in ways if rid in rooms])
                  for rid, poly in geometry.rooms.items()}
        return cls(dict(geometry.rooms), seg, lines,
                   shapely.multilinestrings(list(lines)) if len(seg) else shapely.GeometryCollection(),
                   shapely.multilinestrings(door_lines) if door_lines else shapely.GeometryCollection(), routes)

    def room_at(self, x: float, z: float) -> str | None:
        """The room holding the point (None outside every room)."""
        key = (float(x), float(z))
        if key not in self._room_of:
            pt = shapely.Point(key)
            self._room_of[key] = next((rid for rid, p in self.rooms.items() if p.covers(pt)), None)
        return self._room_of[key]

    def room_of(self, fp: Footprint) -> str | None:
        """The room holding the footprint's centre."""
        return self.room_at(*fp.center)


def walking_routes(room: shapely.Polygon, doorways: list[shapely.LineString]) -> shapely.Geometry:
    """The shortest paths between every two doorways of a room, kept ROUTE_CLEARANCE m from its walls (a visibility
    graph over the shrunk room's corners); an empty geometry with fewer than two doorways."""
    free = room.buffer(-ROUTE_CLEARANCE, join_style="mitre")
    if len(doorways) < 2 or free.is_empty:
        return shapely.GeometryCollection()
    ends = [shapely.ops.nearest_points(free, d.interpolate(0.5, normalized=True))[0] for d in doorways]
    corners = [shapely.Point(c) for part in getattr(free, "geoms", [free]) for c in part.exterior.coords[:-1]]
    nodes = ends + corners
    pts = np.array([[p.x, p.y] for p in nodes])
    inside = free.buffer(1e-6)
    n = len(nodes)
    w = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1, n):
            if inside.covers(shapely.LineString([pts[i], pts[j]])):
                w[i, j] = w[j, i] = max(float(np.linalg.norm(pts[i] - pts[j])), 1e-9)
    dist, pred = shortest_path(csr_matrix(w), directed=False, indices=list(range(len(ends))),
                               return_predecessors=True)
    paths = []
    for a in range(len(ends)):
        for b in range(a + 1, len(ends)):
            if not math.isfinite(dist[a, b]):
                continue
            chain, k = [b], b
            while k != a:
                k = int(pred[a, k])
                chain.append(k)
            paths.append(shapely.LineString(pts[chain[::-1]]) if len(chain) > 1 else shapely.Point(pts[a]))
    return shapely.union_all(paths) if paths else shapely.GeometryCollection()


def _distance(fp: Footprint, geom: shapely.Geometry) -> float:
    return math.nan if geom.is_empty else float(shapely.distance(fp.polygon, geom))


def _wall_angle(layout: HouseLayout, fp: Footprint, nearest: float) -> float:
    """Degrees between the heading and the room-side normal of the nearest wall (the least over near ties)."""
    d = shapely.distance(fp.polygon, layout.wall_lines)
    h = heading(fp.yaw)
    c = np.asarray(fp.center, dtype=float)
    best = math.nan
    for k in np.flatnonzero(d <= nearest + WALL_TIE):
        p0, p1 = layout.walls[k]
        u = (p1 - p0) / max(float(np.linalg.norm(p1 - p0)), 1e-12)
        n = np.array([-u[1], u[0]])
        if float(np.dot(c - p0, n)) < 0.0:
            n = -n
        a = math.degrees(math.acos(max(-1.0, min(1.0, float(np.dot(h, n))))))
        best = a if math.isnan(best) else min(best, a)
    return best


def looks_symmetric(fp: Footprint) -> bool:
    """Whether the footprint is small and nearly square (its heading is not read; SYMMETRIC_AREA, SYMMETRIC_RATIO)."""
    w, d = fp.size
    return w * d <= SYMMETRIC_AREA and max(w, d) <= SYMMETRIC_RATIO * max(min(w, d), 1e-9)


def facing_share(fp: Footprint, target: Footprint) -> float:
    """The share (0-1) of ``fp``'s width whose straight line ahead meets ``target``'s footprint within FACING_REACH m
    of its front edge (or under it): 1 for a chair square at a table's edge, 0 for one beside it facing along it."""
    w, d = fp.size
    ahead = footprint_corners(0.0, FACING_REACH / 2.0, w, d + FACING_REACH, 0.0)  # local, heading +z
    strip = shapely.Polygon(pose_outline(ahead, fp.center[0], fp.center[1], fp.yaw))
    meet = strip.intersection(target.polygon)
    if meet.is_empty or w <= 0.0:
        return 0.0
    ux, _ = yaw_axes(fp.yaw)
    pts = shapely.get_coordinates(meet) - np.asarray(fp.center, dtype=float)
    side = np.clip(pts @ ux, -w / 2.0, w / 2.0)
    return float((side.max() - side.min()) / w)


def object_features(layout: HouseLayout, fp: Footprint, others: Mapping[str, Footprint]) -> dict[str, float]:
    """The features of ``fp`` with every other floor object where ``others`` has it (NaN where undefined: no wall,
    no anchor in the room, no other member, fewer than two doorways)."""
    room = layout.room_of(fp)
    wall = _distance(fp, layout.wall_union)
    out = dict.fromkeys(FEATURES, math.nan)
    out["wall_distance"] = wall
    out["wall_angle"] = _wall_angle(layout, fp, wall) if math.isfinite(wall) and not looks_symmetric(fp) else math.nan
    rest = [o for o in others.values() if o.object_id != fp.object_id and o.role == "floor"]
    near = min((float(shapely.distance(fp.polygon, o.polygon)) for o in rest
                if not _apart(fp.bounds, o.bounds, wall if math.isfinite(wall) else math.inf)), default=math.inf)
    out["isolation"] = min(wall, near) if math.isfinite(min(wall, near)) else math.nan
    out["door_distance"] = _distance(fp, layout.doorways)
    out["route_distance"] = _distance(fp, layout.routes.get(room, shapely.GeometryCollection()))
    kinds = anchor_types(fp.object_type)
    if kinds and room is not None:
        anchors = [o for o in rest if o.object_type in kinds and layout.room_of(o) == room]
        if anchors:
            dist = [float(shapely.distance(fp.polygon, a.polygon)) for a in anchors]
            k = int(np.argmin(dist))
            anchor = anchors[k]
            out["anchor_distance"] = dist[k]
            out["anchor_facing"] = facing_share(fp, anchor)
            mates = [o for o in rest if o.object_type == fp.object_type and layout.room_of(o) == room
                     and _nearest(o, anchors) is anchor]
            if mates:
                out["member_gap"] = min(float(shapely.distance(fp.polygon, o.polygon)) for o in mates)
    return out


def _nearest(fp: Footprint, anchors: list[Footprint]) -> Footprint:
    return min(anchors, key=lambda a: float(shapely.distance(fp.polygon, a.polygon)))


def _apart(a: tuple[float, ...], b: tuple[float, ...], gap: float) -> bool:
    """Whether two (min x, min z, max x, max z) boxes lie more than ``gap`` m apart along x or z."""
    return a[0] - b[2] > gap or b[0] - a[2] > gap or a[1] - b[3] > gap or b[1] - a[3] > gap


def house_features(house: House, catalog: AssetCatalog | None = None) -> list[tuple[str, dict[str, float]]]:
    """(object type, features) of every movable floor object of a house, as it stands."""
    geometry = SceneGeometry.from_house(house, catalog or load_catalog())
    layout = HouseLayout.of(geometry)
    floor = {f.object_id: f for f in geometry.floor_objects}
    return [(f.object_type, object_features(layout, f, floor)) for f in floor.values() if f.movable]


@dataclass(frozen=True)
class Range:
    """One feature's reference percentiles for one key (an object type, a placement class or all objects)."""

    key: str
    n: int
    low: float
    median: float
    high: float


@dataclass(frozen=True)
class PlacementModel:
    """Per key (object type, ``class:edge`` / ``class:middle``, ``all``) and feature: the reference's count and
    1st, 50th and 99th percentiles."""

    stats: dict[str, dict[str, tuple[int, float, float, float]]]
    source: str = ""
    """What it was fitted on (e.g. ``procedural: 300 houses, seed 0``)."""
    houses: int = 0

    def range(self, object_type: str, cls: str, feature: str) -> Range | None:
        """The reference range of a feature for a type: the type's own when it has MIN_SAMPLES values, else its
        placement class's, else all objects' (None when even those are fewer)."""
        for key in (object_type, f"class:{cls}", "all"):
            s = self.stats.get(key, {}).get(feature)
            if s is not None and s[0] >= MIN_SAMPLES:
                return Range(key, *s)
        return None

    def to_json(self) -> dict:
        return {"source": self.source, "houses": self.houses, "quantiles": [LOW_Q, 0.5, HIGH_Q],
                "min_samples": MIN_SAMPLES, "features": list(FEATURES),
                "stats": {k: {f: [n, round(a, 4), round(b, 4), round(c, 4)] for f, (n, a, b, c) in v.items()}
                          for k, v in sorted(self.stats.items())}}

    @classmethod
    def from_json(cls, doc: dict, what: str = "placement reference") -> PlacementModel:
        try:
            stats = {k: {f: (int(s[0]), float(s[1]), float(s[2]), float(s[3])) for f, s in v.items()}
                     for k, v in doc["stats"].items()}
        except (KeyError, TypeError, ValueError, IndexError, AttributeError):
            raise ConfigError(f"{what}: not a placement reference (no 'stats' of [count, p1, p50, p99] per type and "
                              "feature); write one with tools/build_placement_reference.py") from None
        return cls(stats, str(doc.get("source", "")), int(doc.get("houses", 0)))

    def save(self, path: Path) -> Path:
        Path(path).write_text(json.dumps(self.to_json(), indent=1) + "\n", encoding="utf-8")
        return Path(path)


def fit(rows: Iterable[tuple[str, dict[str, float]]], catalog: AssetCatalog | None = None, *, source: str = "",
        houses: int = 0) -> PlacementModel:
    """The model of (object type, features) rows: percentiles per type, per placement class and over all."""
    catalog = catalog or load_catalog()
    values: dict[str, dict[str, list[float]]] = {}
    for object_type, feats in rows:
        for key in (object_type, f"class:{placement_class(catalog, object_type)}", "all"):
            for f, x in feats.items():
                if math.isfinite(x):
                    values.setdefault(key, {}).setdefault(f, []).append(x)
    stats = {k: {f: (len(xs), *(float(q) for q in np.quantile(np.array(xs), [LOW_Q, 0.5, HIGH_Q])))
                 for f, xs in v.items()} for k, v in values.items()}
    return PlacementModel(stats, source, houses)


def fit_houses(houses: Iterable[House], catalog: AssetCatalog | None = None, *, source: str = "") -> PlacementModel:
    """The model of every movable floor object of the houses, as they stand."""
    catalog = catalog or load_catalog()
    rows, n = [], 0
    for h in houses:
        rows += house_features(h, catalog)
        n += 1
    return fit(rows, catalog, source=source, houses=n)


def procedural_reference(n: int = 300, seed: int = 0, catalog: AssetCatalog | None = None) -> PlacementModel:
    """The model of ``n`` procedural houses (:func:`~adaptenv.scene.procedural.generate.generate_houses`, default
    config): the shipped reference."""
    # the generator is only needed to rebuild the reference
    from adaptenv.scene.procedural.generate import generate_houses

    catalog = catalog or load_catalog()
    return fit_houses(generate_houses(n, seed, catalog=catalog), catalog,
                      source=f"procedural: generate_houses({n}, seed={seed}), default config")


@cache
def default_model() -> PlacementModel:
    """The shipped reference (houses of adaptenv's procedural generator)."""
    doc = json.loads(resources.files("adaptenv.adapt").joinpath(REFERENCE_RESOURCE).read_text("utf-8"))
    return PlacementModel.from_json(doc)


def load_model(path: Path, catalog: AssetCatalog | None = None) -> PlacementModel:
    """A reference from a file: a model JSON (``.json``) or houses to fit on, one per line (``.jsonl``/``.jsonl.gz``).

    Raises:
        ConfigError: the file is missing, not a model, or holds no valid house.
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"--reference {path}: no such file; pass a placement reference JSON or houses "
                          "(FILE.jsonl.gz)")
    if path.name.endswith((".jsonl", ".jsonl.gz")):
        from adaptenv.scene.dataset import dataset_houses, parse_dataset_spec

        ds = parse_dataset_spec(path)
        houses = [h for _, h in dataset_houses(ds, catalog=catalog) if isinstance(h, House)] if ds else []
        if not houses:
            raise ConfigError(f"--reference {path}: no valid house in it; pass houses one JSON object a line")
        return fit_houses(houses, catalog, source=f"houses of {path.name}")
    opener = gzip.open if path.suffix == ".gz" else open
    try:
        with opener(path, "rt", encoding="utf-8") as fh:
            doc = json.load(fh)
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"--reference {path}: not readable JSON ({exc}); pass a placement reference JSON or "
                          "houses (FILE.jsonl.gz)") from None
    return PlacementModel.from_json(doc, f"--reference {path}")


@dataclass(frozen=True)
class Unlike:
    """One feature of a moved object outside the reference's central 98%."""

    feature: str
    value: float
    before: float
    range: Range

    def message(self, object_id: str, object_type: str) -> str:
        unit = UNITS[self.feature]
        side = "above" if TAILS[self.feature] == "high" else "below"
        was = "" if math.isnan(self.before) else f"; it stood at {self.before:.2f}"
        return (f"{object_id} ({object_type}) {self.feature} {self.value:.2f} {unit}, {side} the reference's central "
                f"98% for {self.range.key} ({self.range.low:.2f}-{self.range.high:.2f} {unit}, "
                f"{self.range.n} objects){was}")


def unlike(model: PlacementModel, cls: str, object_type: str, now: Mapping[str, float],
           before: Mapping[str, float] | None) -> list[Unlike]:
    """The features of ``now`` outside the reference's central 98% by more than TOLERANCE, on the side TAILS names,
    and further out than ``before`` (where the object stood in the house before editing) by more than TOLERANCE."""
    out = []
    for f in FEATURES:
        x = now.get(f, math.nan)
        if not math.isfinite(x):
            continue
        r = model.range(object_type, cls, f)
        if r is None:
            continue
        b = (before or {}).get(f, math.nan)
        tol = TOLERANCE[f]
        if TAILS[f] == "high":
            bad = x > r.high + tol and (not math.isfinite(b) or x > b + tol)
        else:
            bad = x < r.low - tol and (not math.isfinite(b) or x < b - tol)
        if bad:
            out.append(Unlike(f, x, b, r))
    return out
