"""Small synthetic houses for simulator tests, built from the House/Room/Wall/Opening/HouseObject models.

Rooms are axis-aligned rectangles ``(min_x, min_z, max_x, max_z)``. Walls follow ProcTHOR's
conventions (one wall per room side, ids ``wall|N|minX|minZ|maxX|maxZ``, an ``exterior`` twin for
outer sides), doors join two rooms through a shared wall, and objects are placed by asset id with
their bottom on the floor. Every builder returns a House that passes ``validate_house``.

Import it from a test file as ``from tests.sim import helpers as H`` (pytest's importlib mode
resolves ``tests`` as a namespace package from the rootdir).
"""

from __future__ import annotations

from dataclasses import dataclass

from adaptenv.scene.assets import load_catalog
from adaptenv.scene.house import House, HouseObject, Opening, Room, Vec3, Wall

WALL_HEIGHT = 2.5
#: Assets the tests use (sizes from the ProcTHOR catalog: x width, y height, z depth).
LOW_TARGET = "bin_1"               # GarbageCan, 0.50 x 0.50 x 0.34, below the occluder height
TALL_TARGET = "Fridge_1"           # Fridge, 1.01 x 1.97 x 0.72, occludes
LOW_FURNITURE = "Coffee_Table_207_1"  # CoffeeTable, 1.41 x 0.47 x 0.67: does not block sight
TALL_FURNITURE = "Desk_308_1_1"    # Desk, 1.39 x 2.08 x 0.69: blocks sight
DOOR_ASSET = "Doorway_1"

Rect = tuple[float, float, float, float]


@dataclass(frozen=True)
class Obj:
    """An object to place: asset id, centre (x, z) and yaw (degrees)."""

    asset_id: str
    x: float
    z: float
    yaw: float = 0.0


@dataclass(frozen=True)
class Door:
    """A door between two rooms on their shared wall, centred at ``center`` along that wall."""

    room_a: int
    room_b: int
    center: float
    """Position of the door centre along the shared wall, as the world x (horizontal wall) or z."""
    width: float = 1.0


def _fmt(v: float) -> str:
    return f"{v:.2f}"


def _room_sides(k: int, rect: Rect) -> list[tuple[str, tuple[float, float], tuple[float, float]]]:
    x0, z0, x1, z1 = rect
    sides = [((x0, z0), (x1, z0)), ((x1, z0), (x1, z1)), ((x0, z1), (x1, z1)), ((x0, z0), (x0, z1))]
    return [(_wall_id(str(k), a, b), a, b) for a, b in sides]


def _wall_id(room: str, a: tuple[float, float], b: tuple[float, float]) -> str:
    lo, hi = min(a, b), max(a, b)
    return f"wall|{room}|{_fmt(lo[0])}|{_fmt(lo[1])}|{_fmt(hi[0])}|{_fmt(hi[1])}"


def _wall(wall_id: str, room_id: str, a: tuple[float, float], b: tuple[float, float]) -> Wall:
    pts = [Vec3(x=a[0], y=0.0, z=a[1]), Vec3(x=b[0], y=0.0, z=b[1]),
           Vec3(x=a[0], y=WALL_HEIGHT, z=a[1]), Vec3(x=b[0], y=WALL_HEIGHT, z=b[1])]
    return Wall(id=wall_id, roomId=room_id, polygon=pts)


def _shared_side(ra: Rect, rb: Rect) -> tuple[tuple[float, float], tuple[float, float]]:
    """The overlap of two touching rectangles' sides, as a segment (lo, hi)."""
    ax0, az0, ax1, az1 = ra
    bx0, bz0, bx1, bz1 = rb
    for xa, xb in ((ax1, bx0), (ax0, bx1)):
        if abs(xa - xb) < 1e-9:
            return (xa, max(az0, bz0)), (xa, min(az1, bz1))
    for za, zb in ((az1, bz0), (az0, bz1)):
        if abs(za - zb) < 1e-9:
            return (max(ax0, bx0), za), (min(ax1, bx1), za)
    raise ValueError(f"rooms {ra} and {rb} do not share a side")


def make_house(rooms: list[Rect], *, doors: tuple[Door, ...] | list[Door] = (), objects: list[Obj] | tuple = (),
               agent: tuple[float, float, float] | None = None, room_types: list[str] | None = None) -> House:
    """A house of rectangular rooms joined by doors, with objects placed on the floor.

    Rooms that touch share one wall segment (each room lists it, as ProcTHOR does); a wall side
    is split where it meets another room so that the shared part has its own id.
    """
    catalog = load_catalog()
    room_models = []
    walls: list[Wall] = []
    shared: dict[tuple[int, int], tuple] = {}
    for i in range(len(rooms)):
        for j in range(i + 1, len(rooms)):
            try:
                shared[(i, j)] = _shared_side(rooms[i], rooms[j])
            except ValueError:
                continue
    for k, rect in enumerate(rooms):
        x0, z0, x1, z1 = rect
        rtype = room_types[k] if room_types else "LivingRoom"
        room_models.append(Room(id=f"room|{k}", roomType=rtype, floorPolygon=[
            Vec3(x=x0, z=z0), Vec3(x=x0, z=z1), Vec3(x=x1, z=z1), Vec3(x=x1, z=z0)]))
        for _, a, b in _room_sides(k, rect):
            for piece_a, piece_b, other in _split_side(k, a, b, shared):
                walls.append(_wall(_wall_id(str(k), piece_a, piece_b), f"room|{k}", piece_a, piece_b))
                if other is None:
                    walls.append(_wall(_wall_id("exterior", piece_a, piece_b), "exterior", piece_a, piece_b))
    door_models = []
    for n, d in enumerate(doors):
        lo, hi = shared[(min(d.room_a, d.room_b), max(d.room_a, d.room_b))]
        horizontal = abs(lo[1] - hi[1]) < 1e-9
        start = lo[0] if horizontal else lo[1]
        a, b = d.center - d.width / 2 - start, d.center + d.width / 2 - start
        door_models.append(Opening(
            id=f"door|{d.room_a}|{d.room_b}|{n}", assetId=DOOR_ASSET, room0=f"room|{d.room_a}",
            room1=f"room|{d.room_b}", wall0=_wall_id(str(d.room_a), lo, hi), wall1=_wall_id(str(d.room_b), lo, hi),
            holePolygon=[Vec3(x=a, y=0.0, z=0.0), Vec3(x=b, y=2.1, z=0.0)], openable=False, openness=1.0))
    objs = []
    for n, o in enumerate(objects):
        asset = catalog.asset(o.asset_id)
        objs.append(HouseObject(id=f"{asset.object_type}|{n}", assetId=o.asset_id,
                                position=Vec3(x=o.x, y=asset.size[1] / 2.0, z=o.z), rotation=Vec3(y=o.yaw),
                                kinematic=True))
    house = House(rooms=room_models, walls=walls, doors=door_models, objects=objs)
    if agent is not None:
        house.set_agent_pose(*agent)
    return house


def _split_side(k: int, a, b, shared: dict) -> list[tuple]:
    """Pieces of room k's side a-b: the parts shared with another room and the rest (other=None)."""
    horizontal = abs(a[1] - b[1]) < 1e-9
    axis = 0 if horizontal else 1
    cuts = []
    for (i, j), (lo, hi) in shared.items():
        if k not in (i, j):
            continue
        on_line = abs(lo[1 - axis] - a[1 - axis]) < 1e-9 and abs(hi[1 - axis] - a[1 - axis]) < 1e-9
        if on_line and hi[axis] - lo[axis] > 1e-9:
            cuts.append((lo[axis], hi[axis], j if i == k else i))
    pieces, pos = [], a[axis]
    for lo, hi, other in sorted(cuts):
        if lo > pos + 1e-9:
            pieces.append((pos, lo, None))
        pieces.append((lo, hi, other))
        pos = hi
    if pos < b[axis] - 1e-9:
        pieces.append((pos, b[axis], None))

    def point(t: float) -> tuple[float, float]:
        return (t, a[1]) if horizontal else (a[0], t)

    return [(point(lo), point(hi), other) for lo, hi, other in pieces]


def one_room(size: tuple[float, float] = (4.0, 4.0), objects: list[Obj] | tuple = (),
             agent: tuple[float, float, float] | None = None) -> House:
    """One empty-walled room from (0, 0) to ``size`` with the given objects."""
    return make_house([(0.0, 0.0, size[0], size[1])], objects=objects, agent=agent)


def two_rooms(door_width: float | None = 1.0, *, size: float = 4.0, objects: list[Obj] | tuple = (),
              agent: tuple[float, float, float] | None = None, door_center: float | None = None) -> House:
    """Rooms (0..size, 0..size) and (size..2 size, 0..size) side by side; a door on the shared wall.

    ``door_width=None`` seals the wall (no door), making the second room unreachable from the first.
    """
    rooms = [(0.0, 0.0, size, size), (size, 0.0, 2 * size, size)]
    doors = [] if door_width is None else [Door(0, 1, size / 2 if door_center is None else door_center, door_width)]
    return make_house(rooms, doors=doors, objects=objects, agent=agent)


def target_behind_wall() -> House:
    """Two sealed rooms: the agent's room (left) and a garbage can 1 m behind the shared wall."""
    return two_rooms(None, objects=[Obj(LOW_TARGET, 5.0, 2.0)], agent=(3.0, 2.0, 90.0))


def corridor_house() -> House:
    """Three rooms in an L: a target far from the start so paths turn through two doors."""
    rooms = [(0.0, 0.0, 4.0, 3.0), (4.0, 0.0, 8.0, 3.0), (4.0, 3.0, 8.0, 7.0)]
    doors = [Door(0, 1, 1.5, 0.9), Door(1, 2, 6.0, 0.9)]
    objs = [Obj(LOW_TARGET, 7.5, 6.6), Obj(TALL_FURNITURE, 2.0, 1.5, 90.0), Obj(LOW_FURNITURE, 6.0, 1.2)]
    return make_house(rooms, doors=doors, objects=objs, agent=(1.0, 0.5, 0.0))


def sealed_target_house() -> House:
    """A 5 x 4 m room with the start and a 2 x 4 m sealed room (no door) holding the only garbage can."""
    rooms = [(0.0, 0.0, 5.0, 4.0), (5.0, 0.0, 7.0, 4.0)]
    return make_house(rooms, objects=[Obj(LOW_TARGET, 6.0, 2.0), Obj(TALL_TARGET, 1.0, 3.5)], agent=(2.0, 2.0, 90.0))

