"""Structure stages: room types, a grid floor plan grown room by room, walls, materials and lights.

The floor plan is a small grid of cells (1.6-2.2 m each). Every room starts as one seed cell and
grows as a rectangle one row or column at a time; leftover cells are then handed to neighbouring
rooms one at a time, keeping every room a simple rectilinear polygon. Room polygons list a vertex
wherever the room on the other side of the boundary changes, so that each wall segment (one per
neighbour run) appears identically in both rooms, as ProcTHOR writes them.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import Polygon

from adaptenv.scene.assets import AssetCatalog
from adaptenv.scene.house import House, Room, Vec3, Wall
from adaptenv.scene.procedural.config import GenerationConfig, StageFailed

#: Target size of each room type in grid cells (inclusive range).
ROOM_CELLS = {"Kitchen": (4, 6), "LivingRoom": (4, 8), "Bedroom": (4, 6), "Bathroom": (1, 2)}
#: A house with a single room gets a bigger one (a one-room bathroom stays small).
SINGLE_ROOM_CELLS = {"Kitchen": (4, 7), "LivingRoom": (4, 7), "Bedroom": (4, 7), "Bathroom": (2, 3)}

_FLOOR_MATERIALS = {
    "Kitchen": ("KitchenFloor", "SmallTiles", "HexTiles", "DarkTiles", "CeramicTiles1", "WhiteMarble",
                "TexturesCom_Marble Floor Tiles 1_diffuse_S", "GreyFloor"),
    "LivingRoom": ("WoodGrain_Brown", "WoodGrains", "WoodFloorsCross", "DarkWoodFloors", "GreyFloor 3",
                   "TexturesCom_WoodFine0050_1_seamless_S", "WoodFineDarkFloorsRedNRM1", "Carpet2"),
    "Bedroom": ("BedroomFloor1", "WoodGrain_Tan", "LightWoodCounters4", "Carpet1", "CarpetWhite", "HotelCarpet",
                "TexturesCom_WoodFineWhite", "MediumWoodSmooth"),
    "Bathroom": ("bathroomTilesGrey", "bathroomTilesTan", "SmallTiles", "HexTiles", "CeramicTiles2",
                 "WhiteMarble2", "SubwayTilesAO", "DarkTiles 1"),
}
_WALL_MATERIALS = {
    "Kitchen": ("KitchenWalls", "SubwayTiles2", "WallDrywallWhite", "EggshellDrywall", "DrywallBeige", "PureWhite"),
    "LivingRoom": ("WallDrywallGrey", "DrywallBeige", "EggshellDrywall", "YellowDrywall", "PureWhite",
                   "DrywallGreen", "WallDrywallWhite2"),
    "Bedroom": ("DrywallEggshell", "PinkConcrete_Bedroom1", "DrywallOrange", "WallDrywallWhite3", "PureWhite",
                "YellowPlaster", "OrangeDrywall"),
    "Bathroom": ("bathroomTilesBlue", "bathroomTilesGreen1", "bathroomTilesTan2", "SubwayTilesRough",
                 "WhiteBrick", "PureWhite"),
}
_EXTERIOR_MATERIALS = ("BrownDrywall", "RedBrick", "WhiteBrick", "Drywall", "YellowDrywall", "RedBricks")
_CEILING_MATERIALS = ("PureWhite", "WallDrywallWhite", "EggshellDrywall", "Drywall")


_NAMES: dict[int, tuple[AssetCatalog, frozenset[str]]] = {}


def _material_names(catalog: AssetCatalog) -> frozenset[str]:
    """The catalog's material names, computed once per catalog object."""
    entry = _NAMES.get(id(catalog))
    if entry is None or entry[0] is not catalog:
        entry = _NAMES[id(catalog)] = (catalog, catalog.material_names)
    return entry[1]


def pick_name(rng: np.random.Generator, wanted: tuple[str, ...], catalog: AssetCatalog, fallback: str = "Wall") -> str:
    """A random name from ``wanted`` that the catalog knows (else from the catalog's ``fallback`` group)."""
    known = _material_names(catalog)
    names = [n for n in wanted if n in known] or sorted(catalog.materials.get(fallback, ())) or sorted(known)
    return names[int(rng.integers(len(names)))]


# ----------------------------------------------------------------------------------------- room types


def draw_room_types(rng: np.random.Generator, cfg: GenerationConfig) -> tuple[str, ...]:
    """The house's room types: ``cfg.room_types`` if set, else a plausible mix for the room count.

    Houses with 3+ rooms have a kitchen and a living room; the rest are bedrooms and bathrooms
    (about one bathroom per two bedrooms), and big houses sometimes get a second living room.
    """
    if cfg.room_types is not None:
        return tuple(cfg.room_types)
    n = cfg.n_rooms if cfg.n_rooms is not None else int(rng.integers(cfg.room_range[0], cfg.room_range[1] + 1))
    if n == 1:
        return (("LivingRoom", "Bedroom", "Kitchen", "Bathroom")[int(rng.choice(4, p=[0.35, 0.3, 0.2, 0.15]))],)
    if n == 2:
        pairs = (("Kitchen", "LivingRoom"), ("LivingRoom", "Bedroom"), ("Bedroom", "Bathroom"), ("Kitchen", "Bedroom"))
        return pairs[int(rng.choice(4, p=[0.35, 0.25, 0.25, 0.15]))]
    types = ["Kitchen", "LivingRoom"]
    rest = n - 2
    if rest >= 5 and rng.random() < 0.5:
        types.append("LivingRoom")
        rest -= 1
    bathrooms = max(1, int(round(rest / 3 + rng.uniform(-0.3, 0.3)))) if rest >= 2 else int(rng.random() < 0.3)
    types += ["Bedroom"] * (rest - bathrooms) + ["Bathroom"] * bathrooms
    return tuple(types)


# ------------------------------------------------------------------------------------------ floor plan


def _target_cells(rng: np.random.Generator, types: tuple[str, ...]) -> list[int]:
    if len(types) == 1:
        lo, hi = SINGLE_ROOM_CELLS.get(types[0], ROOM_CELLS[types[0]])
        return [int(rng.integers(lo, hi + 1))]
    return [int(rng.integers(ROOM_CELLS[t][0], ROOM_CELLS[t][1] + 1)) for t in types]


def _house_mask(rng: np.random.Generator, total: int) -> np.ndarray:
    """A hole-free house outline of about ``total`` cells: a rectangle, maybe minus part of an end row."""
    lo = max(1, math.ceil(math.sqrt(total / 2.0)))
    hi = max(lo, math.floor(math.sqrt(total * 2.0)))
    width = int(rng.integers(lo, hi + 1))
    height = math.ceil(total / width)
    mask = np.ones((height, width), dtype=bool)
    extra = width * height - total
    if extra > 0 and height > 1:
        row = 0 if rng.random() < 0.5 else height - 1
        cols = slice(0, extra) if rng.random() < 0.5 else slice(width - extra, width)
        mask[row, cols] = False
    return mask


def _boundary_edges(cells: np.ndarray, k: int) -> list[tuple[tuple[int, int], tuple[int, int], int]]:
    """Directed unit edges (clockwise in x-z) around room ``k``, with the label across each edge.

    Vertices are (col, row) grid points; the label is the neighbouring room index or -1 outside.
    """
    h, w = cells.shape

    def other(r: int, c: int) -> int:
        return int(cells[r, c]) if 0 <= r < h and 0 <= c < w else -1

    out = []
    for r, c in zip(*np.nonzero(cells == k), strict=True):
        r, c = int(r), int(c)
        for (a, b), (nr, nc) in ((((c, r), (c, r + 1)), (r, c - 1)), (((c, r + 1), (c + 1, r + 1)), (r + 1, c)),
                                 (((c + 1, r + 1), (c + 1, r)), (r, c + 1)), (((c + 1, r), (c, r)), (r - 1, c))):
            o = other(nr, nc)
            if o != k:
                out.append((a, b, o))
    return out


def trace_room(cells: np.ndarray, k: int) -> list[tuple[tuple[int, int], tuple[int, int], int]] | None:
    """Boundary runs of room ``k`` as (start, end, neighbour) in clockwise order, or None when the
    room is not a simple polygon (a hole, a pinch point or several pieces)."""
    edges = _boundary_edges(cells, k)
    if not edges:
        return None
    by_start: dict[tuple[int, int], tuple[tuple[int, int], tuple[int, int], int]] = {}
    for e in edges:
        if e[0] in by_start:
            return None  # two boundary edges leave one vertex: the room touches itself at a corner
        by_start[e[0]] = e
    start = min(by_start)
    chain, v = [], start
    while True:
        e = by_start[v]
        chain.append(e)
        v = e[1]
        if v == start:
            break
    if len(chain) != len(edges):
        return None  # more than one boundary loop: a hole or a second piece
    runs: list[list] = []
    for a, b, o in chain:
        d = (b[0] - a[0], b[1] - a[1])
        if runs and runs[-1][3] == d and runs[-1][2] == o:
            runs[-1][1] = b
        else:
            runs.append([a, b, o, d])
    if len(runs) > 1 and runs[0][3] == runs[-1][3] and runs[0][2] == runs[-1][2]:
        runs[0][0] = runs[-1][0]
        runs.pop()
    # Start at the lowest vertex (min x, then min z), as ProcTHOR does.
    first = min(range(len(runs)), key=lambda i: runs[i][0])
    runs = runs[first:] + runs[:first]
    return [(tuple(a), tuple(b), o) for a, b, o, _ in runs]


def _aspect(h: int, w: int) -> float:
    return max(h, w) / min(h, w)


def grow_floor_plan(rng: np.random.Generator, targets: list[int]) -> np.ndarray | None:
    """Room index of every cell (-1 outside the house), or None when growth got stuck."""
    n = len(targets)
    mask = _house_mask(rng, sum(targets))
    h, w = mask.shape
    cells = np.full((h, w), -1, dtype=np.int64)
    # Seeds: a 2x2 block for every room but bathrooms (1x1), big ones first, each drawn with a weight
    # growing with its distance to the seeds already placed, so rooms spread over the plan.
    rects: list[list[int]] = [[]] * n
    centers: list[tuple[float, float]] = []
    for k in sorted(range(n), key=lambda k: (-min(targets[k], 4), k)):
        size = 2 if targets[k] >= 3 else 1
        free = mask & (cells == -1)
        ok = np.ones((h - size + 1, w - size + 1), dtype=bool) if h >= size and w >= size else np.zeros((0, 0), bool)
        for dr in range(size):
            for dc in range(size):
                ok &= free[dr:dr + h - size + 1, dc:dc + w - size + 1]
        spots = np.argwhere(ok)
        if len(spots) == 0:
            return None
        if centers:
            d = np.abs(spots[:, None, :] + size / 2 - np.array(centers)[None]).sum(axis=2).min(axis=1)
            weight = d**3
        else:
            weight = np.ones(len(spots))
        r, c = (int(v) for v in spots[int(rng.choice(len(spots), p=weight / weight.sum()))])
        cells[r:r + size, c:c + size] = k
        rects[k] = [r, c, r + size, c + size]  # r0, c0, r1, c1 (exclusive)
        centers.append((r + size / 2, c + size / 2))

    def strip(rect: list[int], side: int) -> tuple[slice, slice] | None:
        r0, c0, r1, c1 = rect
        if side == 0 and r0 > 0:
            return slice(r0 - 1, r0), slice(c0, c1)
        if side == 1 and r1 < h:
            return slice(r1, r1 + 1), slice(c0, c1)
        if side == 2 and c0 > 0:
            return slice(r0, r1), slice(c0 - 1, c0)
        if side == 3 and c1 < w:
            return slice(r0, r1), slice(c1, c1 + 1)
        return None

    # Phase 1: rectangular growth, the room furthest below its target first.
    active = set(range(n))
    while active:
        order = sorted(active, key=lambda k: (((rects[k][2] - rects[k][0]) * (rects[k][3] - rects[k][1])) / targets[k],
                                              rng.random()))
        grown = False
        for k in order:
            area = (rects[k][2] - rects[k][0]) * (rects[k][3] - rects[k][1])
            if area >= targets[k]:
                active.discard(k)
                continue
            r0, c0, r1, c1 = rects[k]
            # Prefer the growth that keeps the room closest to a square.
            sides = sorted(range(4), key=lambda sd: (_aspect(r1 - r0 + (sd < 2), c1 - c0 + (sd >= 2)), rng.random()))
            for side in sides:
                s = strip(rects[k], int(side))
                if s is None or not (mask[s].all() and (cells[s] == -1).all()):
                    continue
                if area + cells[s].size > targets[k] + 2:
                    continue
                cells[s] = k
                r0, c0, r1, c1 = rects[k]
                rects[k] = [[r0 - 1, c0, r1, c1], [r0, c0, r1 + 1, c1], [r0, c0 - 1, r1, c1], [r0, c0, r1, c1 + 1]][int(side)]
                grown = True
                break
            else:
                active.discard(k)
            if grown:
                break
    # Phase 2: hand leftover cells one by one to a neighbouring room that stays a simple polygon.
    while True:
        left = [tuple(map(int, p)) for p in zip(*np.nonzero(mask & (cells == -1)), strict=True)]
        if not left:
            break
        sizes = np.bincount(cells[cells >= 0], minlength=n)
        options = []
        for r, c in left:
            for nr, nc in ((r - 1, c), (r + 1, c), (r, c - 1), (r, c + 1)):
                if 0 <= nr < h and 0 <= nc < w and cells[nr, nc] >= 0:
                    k = int(cells[nr, nc])
                    options.append((sizes[k] / targets[k], rng.random(), r, c, k))
        placed = False
        for _, _, r, c, k in sorted(set(options)):
            cells[r, c] = k
            if trace_room(cells, k) is not None:
                placed = True
                break
            cells[r, c] = -1
        if not placed:
            return None
    if any(trace_room(cells, k) is None for k in range(n)):
        return None
    return cells


def _livable(cells: np.ndarray, types: tuple[str, ...]) -> bool:
    """Whether every room is big enough for its furniture: bathrooms any size, other rooms at least
    three cells and two cells across in both directions (no corridor-like bedrooms)."""
    for k, rtype in enumerate(types):
        if rtype == "Bathroom":
            continue
        rows, cols = np.nonzero(cells == k)
        if len(rows) < min(3, ROOM_CELLS[rtype][0]) or np.ptp(rows) < 1 or np.ptp(cols) < 1:
            return False
    return True


# -------------------------------------------------------------------------------------------- stages


def _vec(x: float, z: float, y: float = 0.0) -> Vec3:
    return Vec3(x=round(x, 4), y=round(y, 4), z=round(z, 4))


def stage_structure(house: House, *, rng: np.random.Generator, catalog: AssetCatalog, cfg: GenerationConfig) -> None:
    """Rooms: types, a grown grid floor plan scaled to meters, floor materials."""
    types = draw_room_types(rng, cfg)
    for _ in range(80):
        cells = grow_floor_plan(rng, _target_cells(rng, types))
        if cells is not None and _livable(cells, types):
            break
    else:
        raise StageFailed("the floor plan could not be grown")
    cell = round(float(rng.uniform(*cfg.cell_size)), 3)
    house.rooms = []
    for k, rtype in enumerate(types):
        runs = trace_room(cells, k)
        assert runs is not None
        poly = [Vec3(x=round(a[0] * cell, 3), y=0.0, z=round(a[1] * cell, 3)) for a, _, _ in runs]
        house.rooms.append(Room(id=f"room|{k + 2}", roomType=rtype, floorPolygon=poly,
                                floorMaterial={"name": pick_name(rng, _FLOOR_MATERIALS[rtype], catalog, "Wood")},
                                ceilings=[], children=[]))


def _wall_id(room: str, a: tuple[float, float], b: tuple[float, float]) -> str:
    x0, x1 = sorted((a[0], b[0]))
    z0, z1 = sorted((a[1], b[1]))
    return f"wall|{room}|{x0:.2f}|{z0:.2f}|{x1:.2f}|{z1:.2f}"


def stage_walls(house: House, *, rng: np.random.Generator, catalog: AssetCatalog, cfg: GenerationConfig) -> None:
    """Walls: every room edge once per room (clockwise), plus an ``exterior`` copy of boundary edges.

    Relies on room polygons listing a vertex wherever the neighbour changes (as the structure
    stage writes them), so an interior wall is the same segment in both rooms.
    """
    height = round(float(rng.uniform(*cfg.wall_height)), 4)
    edges: dict[tuple, list[str]] = {}
    for room in house.rooms:
        pts = [(p.x, p.z) for p in room.floorPolygon]
        for i, a in enumerate(pts):
            b = pts[(i + 1) % len(pts)]
            edges.setdefault(tuple(sorted((a, b))), []).append(room.id)
    exterior_material = pick_name(rng, _EXTERIOR_MATERIALS, catalog)
    walls, exterior = [], []
    for room in house.rooms:
        material = {"name": pick_name(rng, _WALL_MATERIALS[room.roomType], catalog)}
        num = room.id.split("|")[1]
        pts = [(p.x, p.z) for p in room.floorPolygon]
        for i, a in enumerate(pts):
            b = pts[(i + 1) % len(pts)]
            walls.append(Wall(id=_wall_id(num, a, b), roomId=room.id,
                              polygon=[_vec(*a), _vec(*b), _vec(*a, y=height), _vec(*b, y=height)],
                              material=dict(material)))
            if len(edges[tuple(sorted((a, b)))]) == 1:
                exterior.append(Wall(id=_wall_id("exterior", a, b), roomId="exterior",
                                     polygon=[_vec(*b, y=height), _vec(*a, y=height), _vec(*b), _vec(*a)],
                                     material={"name": exterior_material}))
    house.walls = walls + exterior


def room_polygon(room: Room) -> Polygon:
    """The room's floor polygon in (x, z)."""
    return Polygon([(p.x, p.z) for p in room.floorPolygon])


def stage_lights(house: House, *, rng: np.random.Generator, catalog: AssetCatalog, cfg: GenerationConfig) -> None:
    """proceduralParameters: a sun, one ceiling light per room, ceiling material and skybox."""
    height = max(v.y for v in house.walls[0].polygon) if house.walls else 2.6
    shadow = {"type": "Soft", "strength": 1, "normalBias": 0, "bias": 0.05, "nearPlane": 0.2,
              "resolution": "FromQualitySettings"}
    lights = [{"id": "DirectionalLight", "indirectMultiplier": 1.0, "intensity": 1,
               "position": {"x": 0.84, "y": 0.1855, "z": -1.09}, "rgb": {"r": 1.0, "g": 1.0, "b": 1.0},
               "rotation": {"x": 66, "y": 75, "z": 0}, "shadow": {**shadow, "bias": 0}, "type": "directional"}]
    for room in house.rooms:
        p = shapely.point_on_surface(room_polygon(room))
        lights.append({"id": f"light_{room.id.split('|')[1]}", "intensity": 0.45,
                       "position": {"x": round(p.x, 4), "y": round(height - 0.2, 4), "z": round(p.y, 4)},
                       "range": 15, "rgb": {"r": 1.0, "g": 0.855, "b": 0.722}, "shadow": dict(shadow),
                       "type": "point"})
    skyboxes = sorted(catalog.skyboxes)
    house.proceduralParameters = {
        "ceilingMaterial": {"name": pick_name(rng, _CEILING_MATERIALS, catalog)},
        "floorColliderThickness": 1.0,
        "lights": lights,
        "receptacleHeight": 0.7,
        "reflections": [],
        "skyboxId": skyboxes[int(rng.integers(len(skyboxes)))] if skyboxes else "SkyOakland",
    }
