"""Door and window stages: connect every room, one closed front door, windows on exterior walls.

Rooms are connected along a spanning tree of the room adjacency graph, cheapest links first
(living room to anything, bedroom to bathroom, ...), plus a few extra links between public rooms.
Kitchen-living (and living-living) links are sometimes open (``empty`` walls) or leafless
doorframes, as in ProcTHOR. Holes are written in wall0-local coordinates: x runs along wall0 from
its polygon[0], y is the height.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from adaptenv.scene.assets import AssetCatalog, AssetInfo
from adaptenv.scene.geometry import wall_floor_segment
from adaptenv.scene.house import House, Opening, Vec3, Wall
from adaptenv.scene.procedural.config import GenerationConfig, StageFailed

PUBLIC_ROOMS = frozenset({"Kitchen", "LivingRoom"})
#: Cost of linking two room types by a door (lower is preferred in the spanning tree).
_PAIR_COST = {
    ("LivingRoom", "LivingRoom"): 0.2, ("Kitchen", "LivingRoom"): 0.0, ("Bedroom", "LivingRoom"): 0.3,
    ("Bathroom", "LivingRoom"): 0.8, ("Bathroom", "Bedroom"): 0.6, ("Bedroom", "Kitchen"): 1.2,
    ("Bedroom", "Bedroom"): 1.4, ("Kitchen", "Kitchen"): 1.0, ("Bathroom", "Kitchen"): 2.0,
    ("Bathroom", "Bathroom"): 3.0,
}
#: Wall length (m) kept solid at each end of a wall beside a hole.
END_MARGIN = 0.2


@dataclass
class SharedWall:
    """A wall segment between two rooms: the wall as each room lists it."""

    wall_a: Wall
    wall_b: Wall

    @property
    def length(self) -> float:
        p0, p1 = wall_floor_segment(self.wall_a)
        return float(np.linalg.norm(p1 - p0))


def wall_length(wall: Wall) -> float:
    """Length (m) of a wall's floor edge."""
    p0, p1 = wall_floor_segment(wall)
    return float(np.linalg.norm(p1 - p0))


def _key(wall: Wall) -> tuple:
    p0, p1 = wall_floor_segment(wall)
    a, b = tuple(np.round(p0, 3)), tuple(np.round(p1, 3))
    return (a, b) if a <= b else (b, a)


def shared_walls(house: House) -> dict[tuple[str, str], list[SharedWall]]:
    """Wall segments shared by two rooms, keyed by the room-id pair (in the order rooms are listed)."""
    order = {r.id: i for i, r in enumerate(house.rooms)}
    by_key: dict[tuple, list[Wall]] = {}
    for w in house.walls:
        if w.roomId in order:
            by_key.setdefault(_key(w), []).append(w)
    out: dict[tuple[str, str], list[SharedWall]] = {}
    for walls in by_key.values():
        if len(walls) == 2:
            a, b = sorted(walls, key=lambda w: order[w.roomId])
            out.setdefault((a.roomId, b.roomId), []).append(SharedWall(a, b))
    return dict(sorted(out.items(), key=lambda kv: (order[kv[0][0]], order[kv[0][1]])))


def exterior_walls(house: House) -> dict[str, list[Wall]]:
    """Each room's walls on the house boundary (those with an ``exterior`` copy)."""
    ext = {_key(w) for w in house.walls if w.roomId == "exterior"}
    out: dict[str, list[Wall]] = {r.id: [] for r in house.rooms}
    for w in house.walls:
        if w.roomId in out and _key(w) in ext:
            out[w.roomId].append(w)
    return out


def exterior_id(wall: Wall) -> str:
    """Id of the exterior copy of a room's boundary wall."""
    parts = wall.id.split("|")
    return "|".join([parts[0], "exterior", *parts[2:]])


def split_assets(catalog: AssetCatalog, object_type: str, split: str) -> list[AssetInfo]:
    """Assets of a type in this split, plus the split-less ones every split shares (sorted by id)."""
    return [a for a in catalog.assets_of_type(object_type) if a.split in (split, None)]


def _door_asset(rng: np.random.Generator, catalog: AssetCatalog, cfg: GenerationConfig, kind: str,
                double: bool) -> AssetInfo:
    pool = [a for a in split_assets(catalog, kind, cfg.split) if ("Double" in a.asset_id) == double]
    pool = pool or [a for a in catalog.assets_of_type(kind) if ("Double" in a.asset_id) == double]
    return pool[int(rng.integers(len(pool)))]


def _hole_start(rng: np.random.Generator, length: float, width: float, taken: list[tuple[float, float]]) -> float | None:
    """Start (m along the wall) of a hole of this width clear of the wall ends and of taken intervals."""
    lo, hi = END_MARGIN, length - END_MARGIN - width
    if hi < lo:
        return None
    for _ in range(12):
        t = float(rng.uniform(lo, hi))
        if all(t + width + END_MARGIN <= a or t >= b + END_MARGIN for a, b in taken):
            return t
    return None


def _opening(op_id: str, asset: AssetInfo, room0: str, room1: str, wall0: str, wall1: str, t: float,
             width: float, y0: float, height: float, **extra) -> Opening:
    return Opening(id=op_id, assetId=asset.asset_id, room0=room0, room1=room1, wall0=wall0, wall1=wall1,
                   holePolygon=[Vec3(x=round(t, 4), y=round(y0, 4), z=0.0),
                                Vec3(x=round(t + width, 4), y=round(y0 + height, 4), z=0.0)],
                   assetPosition=Vec3(x=round(t + width / 2, 4), y=round(y0 + height / 2, 4), z=0.0), **extra)


def _num(room_id: str) -> int:
    return int(room_id.split("|")[1])


def _spanning_links(rng: np.random.Generator, house: House, usable: dict[tuple[str, str], list[SharedWall]],
                    cfg: GenerationConfig) -> list[tuple[str, str]]:
    """Room pairs to connect: a cheapest spanning tree (Kruskal) plus some extra public links."""
    types = {r.id: r.roomType for r in house.rooms}
    parent = {r.id: r.id for r in house.rooms}

    def find(a: str) -> str:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    costed = sorted((_PAIR_COST[tuple(sorted((types[a], types[b])))] + float(rng.uniform(0, 0.6)), a, b)
                    for a, b in usable)
    links, rest = [], []
    for _, a, b in costed:
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
            links.append((a, b))
        else:
            rest.append((a, b))
    if len({find(r.id) for r in house.rooms}) > 1:
        raise StageFailed("the rooms cannot all be connected by doors")
    for a, b in rest:
        if types[a] in PUBLIC_ROOMS and types[b] in PUBLIC_ROOMS and rng.random() < cfg.extra_door_prob:
            links.append((a, b))
    return links


def stage_doors(house: House, *, rng: np.random.Generator, catalog: AssetCatalog, cfg: GenerationConfig) -> None:
    """Doors, doorframes and open walls making every room reachable (with ``closed_door_prob``, some interior doors
    are then shut), plus one closed exterior door."""
    types = {r.id: r.roomType for r in house.rooms}
    min_len = 1.0 + 2 * END_MARGIN + 0.1
    usable = {pair: [s for s in segs if s.length >= min_len] for pair, segs in shared_walls(house).items()}
    usable = {pair: segs for pair, segs in usable.items() if segs}
    doors: list[Opening] = []
    for a, b in _spanning_links(rng, house, usable, cfg):
        segs = sorted(usable[(a, b)], key=lambda s: (-round(s.length, 3), s.wall_a.id))
        seg = segs[0] if len(segs) == 1 or rng.random() < 0.7 else segs[int(rng.integers(len(segs)))]
        public = types[a] in PUBLIC_ROOMS and types[b] in PUBLIC_ROOMS
        r = rng.random()
        if public and r < cfg.open_kitchen_prob:
            seg.wall_a.empty = True
            seg.wall_b.empty = True
            continue
        kind = "Doorframe" if public and r < cfg.open_kitchen_prob + cfg.doorframe_prob else "Doorway"
        double = public and seg.length >= 2.0 + 2 * END_MARGIN + 0.1 and rng.random() < 0.5
        asset = _door_asset(rng, catalog, cfg, kind, double)
        width, height = asset.size[0], asset.size[1]
        flip = rng.random() < 0.5
        w0, w1 = (seg.wall_b, seg.wall_a) if flip else (seg.wall_a, seg.wall_b)
        t = _hole_start(rng, seg.length, width, [])
        if t is None:
            raise StageFailed(f"no room for a door on {w0.id}")
        closed = kind == "Doorway" and cfg.closed_door_prob > 0 and rng.random() < cfg.closed_door_prob
        extra = {"openable": True, "openness": 0 if closed else 1} if kind == "Doorway" else {}
        lo, hi = sorted((_num(a), _num(b)))
        doors.append(_opening(f"door|{lo}|{hi}", asset, w0.roomId, w1.roomId, w0.id, w1.id, t, width, 0.0, height,
                              **extra))
    house.doors = doors + _front_door(rng, house, catalog, cfg)


def _front_door(rng: np.random.Generator, house: House, catalog: AssetCatalog, cfg: GenerationConfig) -> list[Opening]:
    """One closed exterior door, in the living room or kitchen when they touch the outside."""
    preference = {"LivingRoom": 0, "Kitchen": 1, "Bedroom": 2, "Bathroom": 3}
    asset = _door_asset(rng, catalog, cfg, "Doorway", False)
    width, height = asset.size[0], asset.size[1]
    ext = exterior_walls(house)
    rooms = sorted(house.rooms, key=lambda r: (preference[r.roomType], rng.random()))
    for room in rooms:
        walls = [w for w in ext[room.id] if wall_length(w) >= width + 2 * END_MARGIN + 0.1]
        if not walls:
            continue
        wall = walls[int(rng.integers(len(walls)))]
        t = _hole_start(rng, wall_length(wall), width, [])
        if t is None:
            continue
        return [_opening(f"door|1|{_num(room.id)}", asset, room.id, room.id, wall.id, exterior_id(wall), t, width,
                         0.0, height, openable=True, openness=0)]
    return []


def stage_windows(house: House, *, rng: np.random.Generator, catalog: AssetCatalog, cfg: GenerationConfig) -> None:
    """Windows on exterior walls (never bay windows), clear of the front door; at most two per room."""
    pool = [a for a in split_assets(catalog, "Window", cfg.split)
            if a.asset_id in catalog.wall_holes and "Bay" not in a.asset_id]
    taken: dict[str, list[tuple[float, float]]] = {}
    for d in house.doors:
        xs = sorted(v.x for v in d.holePolygon)
        taken.setdefault(d.wall0, []).append((xs[0], xs[-1]))
    height = max((v.y for v in house.walls[0].polygon), default=2.6) if house.walls else 2.6
    windows: list[Opening] = []
    ext = exterior_walls(house)
    for room in house.rooms:
        k = 0
        limit = 1 if room.roomType == "Bathroom" else 2
        walls = ext[room.id]
        for i in rng.permutation(len(walls)):
            wall = walls[int(i)]
            if k >= limit or rng.random() >= cfg.window_prob:
                continue
            length = wall_length(wall)
            fits = [a for a in pool if catalog.wall_holes[a.asset_id].width + 2 * END_MARGIN <= length]
            if not fits:
                continue
            asset = fits[int(rng.integers(len(fits)))]
            hole = catalog.wall_holes[asset.asset_id]
            top = min(height - 0.3, float(rng.uniform(1.75, 2.1)))
            y0 = top - hole.height
            if y0 < 0.3:
                continue
            t = _hole_start(rng, length, hole.width, taken.get(wall.id, []))
            if t is None:
                continue
            taken.setdefault(wall.id, []).append((t, t + hole.width))
            windows.append(_opening(f"window|{_num(room.id)}|{k}", asset, room.id, room.id, wall.id, exterior_id(wall),
                                    t, hole.width, y0, hole.height))
            k += 1
    house.windows = windows
