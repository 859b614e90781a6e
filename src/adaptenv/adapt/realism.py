"""A realism score per scene in [0, 1] (higher = more like a ProcTHOR-furnished home), with its terms.

Built from the ProcTHOR placement annotations (``AssetCatalog.type_info``) and the scene graph
(:mod:`adaptenv.scene.graph`). Terms, each in [0, 1] (None when nothing in the scene is concerned):

- ``wall_anchored``: objects whose type ProcTHOR places on an edge and never in the middle
  (``on_edge and not in_middle``, minus :data:`FREE_STANDING` types such as tables and lamps), or
  that stood against a wall in ``original``, still stand with
  their back against a wall, facing the room (the graph's ``against_wall`` relation);
- ``room_fit``: floor objects in a room type where their type occurs (``weight_in(room) > 0``);
- ``groups``: seats near a table or desk of their room, a television facing a sofa or armchair of
  its room, side tables near a bed in bedrooms (groups are formed in ``original`` when given, so
  a chair carried out of its dining room still counts against its table; distances mapped
  linearly from 1 at
  :data:`GROUP_NEAR` to 0 at :data:`GROUP_FAR`; facing = cosine of the angle);
- ``door_zones``: the approach zone (:data:`DOOR_ZONE` m deep on both sides) of every passable
  doorway is free of floor furniture: 1 when free, 0 once furniture there covers
  :data:`~adaptenv.adapt.doorways.MAX_APPROACH_COVER` of the door's width (see :mod:`adaptenv.adapt.doorways`);
- ``angles``: objects of wall-anchored types keep a yaw within :data:`ANGLE_TOLERANCE` of a multiple of 90.

``total`` is the weighted mean of the terms that apply (weights in :data:`WEIGHTS`). Generators
can use it as a regularizer; the benchmark compares built-in and random edits with it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely

from adaptenv.adapt.doorways import (
    APPROACH_DEPTH,
    MAX_APPROACH_COVER,
    approach_zones,
    covered_width,
)
from adaptenv.scene.assets import AssetCatalog, load_catalog
from adaptenv.scene.geometry import Footprint, SceneGeometry, heading
from adaptenv.scene.graph import build_scene_graph
from adaptenv.scene.house import House

#: Seats and what they gather around.
SEATS = frozenset({"Chair"})
TABLES = frozenset({"DiningTable", "Desk", "CoffeeTable", "CounterTop"})
LOUNGE = frozenset({"Sofa", "ArmChair"})
#: Group distances (m) between footprints: full score up to GROUP_NEAR, none from GROUP_FAR.
GROUP_NEAR, GROUP_FAR = 0.3, 1.3
#: Depth (m) of the zone in front of (and behind) a doorway that furniture should leave free.
DOOR_ZONE = APPROACH_DEPTH
#: Degrees a wall-anchored object's yaw may deviate from a multiple of 90.
ANGLE_TOLERANCE = 3.0
#: Edge-annotated types that ProcTHOR data shows standing free or turned (tables, small or round things).
FREE_STANDING = frozenset({"DiningTable", "CoffeeTable", "Stool", "Ottoman", "FloorLamp", "GarbageCan", "Box",
                           "Boots", "BaseballBat", "Plunger", "RoomDecor", "VacuumCleaner", "LaundryHamper",
                           "HousePlant", "Chair"})
WEIGHTS = {"wall_anchored": 1.0, "room_fit": 1.0, "groups": 1.0, "door_zones": 1.0, "angles": 1.0}


@dataclass(frozen=True)
class RealismReport:
    """Each realism term (None when it does not apply) and their weighted mean ``total``."""

    wall_anchored: float | None
    room_fit: float | None
    groups: float | None
    door_zones: float | None
    angles: float | None
    total: float
    offenders: dict[str, list[str]] = field(default_factory=dict)
    """Per term, the object or door ids that lowered it."""

    def terms(self) -> dict[str, float | None]:
        return {k: getattr(self, k) for k in WEIGHTS}


def _closeness(d: float) -> float:
    return float(np.clip((GROUP_FAR - d) / (GROUP_FAR - GROUP_NEAR), 0.0, 1.0))


def _mean(xs: list[float]) -> float | None:
    return float(np.mean(xs)) if xs else None


@dataclass(frozen=True)
class RealismReference:
    """What :func:`realism` reads from the scene before editing: the objects against a wall and the groups.

    A generator scores many candidates against one original; building this once saves a scene graph per candidate.
    """

    anchored: frozenset[str]
    groups: tuple[tuple[str, str, tuple[str, ...]], ...]

    @classmethod
    def of(cls, original: House, catalog: AssetCatalog | None = None) -> RealismReference:
        catalog = catalog or load_catalog()
        geometry = SceneGeometry.from_house(original, catalog)
        graph = build_scene_graph(original, geometry, catalog, kinds=("against_wall",))
        pairs = _group_pairs(geometry, {n.id: n.room for n in graph.nodes.values()})
        return cls(frozenset(r.subject for r in graph.relations_of("against_wall")),
                   tuple((m, kind, tuple(ps)) for m, kind, ps in pairs))


def realism(house: House, *, original: House | RealismReference | None = None, catalog: AssetCatalog | None = None,
            geometry: SceneGeometry | None = None) -> RealismReport:
    """Score a scene's realism; ``original`` (the house before editing, or its :class:`RealismReference`) adds the
    objects that stood against a wall before editing and keeps the groups it had."""
    catalog = catalog or load_catalog()
    geometry = geometry or SceneGeometry.from_house(house, catalog)
    graph = build_scene_graph(house, geometry, catalog, kinds=("against_wall",))
    floor = [f for f in geometry.floor_objects]
    room_of = {f.object_id: graph.nodes[f.object_id].room for f in geometry.footprints}
    against = {r.subject for r in graph.relations_of("against_wall")}
    offenders: dict[str, list[str]] = {k: [] for k in WEIGHTS}

    if isinstance(original, House):
        original = RealismReference.of(original, catalog)
    anchored_before = original.anchored if original is not None else frozenset()
    anchored = [f for f in floor if f.movable and (_edge_type(catalog, f.object_type) or f.object_id in anchored_before)]

    wall_scores, angle_scores = [], []
    for f in anchored:
        ok = f.object_id in against
        wall_scores.append(float(ok))
        if not ok:
            offenders["wall_anchored"].append(f.object_id)
        if _edge_type(catalog, f.object_type):
            off = abs(((f.yaw + 45.0) % 90.0) - 45.0)
            angle_scores.append(float(off <= ANGLE_TOLERANCE))
            if off > ANGLE_TOLERANCE:
                offenders["angles"].append(f.object_id)

    fit_scores = []
    for f in floor:
        info = catalog.type_info(f.object_type)
        room = room_of.get(f.object_id)
        if room is None or not any(info.room_weights.values()):
            continue
        ok = info.weight_in(geometry.room_types[room]) > 0
        fit_scores.append(float(ok))
        if not ok:
            offenders["room_fit"].append(f.object_id)

    pairs = list(original.groups) if original is not None else _group_pairs(geometry, room_of)
    group_scores = _group_scores(geometry, pairs, offenders["groups"])
    door_scores = _door_scores(geometry, floor, offenders["door_zones"])

    terms = {"wall_anchored": _mean(wall_scores), "room_fit": _mean(fit_scores), "groups": _mean(group_scores),
             "door_zones": _mean(door_scores), "angles": _mean(angle_scores)}
    used = {k: v for k, v in terms.items() if v is not None}
    total = sum(WEIGHTS[k] * v for k, v in used.items()) / sum(WEIGHTS[k] for k in used) if used else 1.0
    return RealismReport(**terms, total=float(total), offenders={k: v for k, v in offenders.items() if v})


def _edge_type(catalog: AssetCatalog, object_type: str) -> bool:
    info = catalog.type_info(object_type)
    return info.on_edge and not info.in_middle and object_type not in FREE_STANDING


def _nearest(f: Footprint, others: list[Footprint]) -> tuple[Footprint | None, float]:
    if not others:
        return None, float("inf")
    d = shapely.distance(f.polygon, [o.polygon for o in others])
    k = int(np.argmin(d))
    return others[k], float(d[k])


def _group_pairs(geometry: SceneGeometry, room_of: dict[str, str | None]) -> list[tuple[str, str, list[str]]]:
    """(member id, kind, partner ids): seats and tables, televisions and lounge seats, side tables and beds."""
    by_room: dict[str | None, list[Footprint]] = {}
    for f in geometry.footprints:
        by_room.setdefault(room_of.get(f.object_id), []).append(f)
    out = []
    for room, items in by_room.items():
        if room is None:
            continue
        rtype = geometry.room_types.get(room)
        tables = [f.object_id for f in items if f.object_type in TABLES]
        lounge = [f.object_id for f in items if f.object_type in LOUNGE]
        beds = [f.object_id for f in items if f.object_type == "Bed"]
        for f in items:
            if f.object_type in SEATS and tables:
                out.append((f.object_id, "near", tables))
            elif f.object_type == "Television" and lounge:
                out.append((f.object_id, "faces", lounge))
            elif f.object_type == "SideTable" and rtype == "Bedroom" and beds:
                out.append((f.object_id, "near", beds))
    return out


def _group_scores(geometry: SceneGeometry, pairs: list[tuple[str, str, Sequence[str]]],
                  offenders: list[str]) -> list[float]:
    """Score each group member against its partners (from the original scene when there is one)."""
    fps = {f.object_id: f for f in geometry.footprints}
    scores = []
    for member, kind, partners in pairs:
        f = fps.get(member)
        others = [fps[p] for p in partners if p in fps]
        if f is None or not others:
            continue
        if kind == "near":
            score = _closeness(_nearest(f, others)[1])
        else:
            best = 0.0
            for o in others:
                v = np.array(o.center) - np.array(f.center)
                n = float(np.linalg.norm(v))
                if n > 1e-9:
                    best = max(best, float(np.dot(heading(f.yaw), v / n)))
            score = best
        scores.append(score)
        if score < 0.5:
            offenders.append(member)
    return scores


def _door_scores(geometry: SceneGeometry, floor: list[Footprint], offenders: list[str]) -> list[float]:
    """Per passable doorway: 1 when its approach zone is free, falling linearly to 0 when furniture covers
    :data:`~adaptenv.adapt.doorways.MAX_APPROACH_COVER` of the door's width there (what validation rejects)."""
    polys = [f.polygon for f in floor]
    scores = []
    for z in approach_zones(geometry, DOOR_ZONE):
        share = covered_width(z, polys) / z.width
        score = float(np.clip(1.0 - share / MAX_APPROACH_COVER, 0.0, 1.0))
        scores.append(score)
        if score < 1.0:
            offenders.append(z.door_id)
    return scores
