"""Rasterized floor plans: the real house is one navigable region; doorway width decides connectivity."""

from __future__ import annotations

import numpy as np
import pytest

from adaptenv.scene.geometry import SceneGeometry
from adaptenv.scene.house import House, Opening, Room, Vec3, Wall
from adaptenv.scene.occupancy import LABEL_OBJECT0, LABEL_OUTSIDE, LABEL_WALL, rasterize
from adaptenv.scene.validate import validate_house
from adaptenv.sim.spec import AGENT_RADIUS

WALL_HEIGHT = 2.5


def _wall(room: str, a: tuple[float, float], b: tuple[float, float]) -> Wall:
    """A wall side from a to b (a is polygon[0], so hole x is measured from a)."""
    number = room.split("|")[-1] if room != "exterior" else "exterior"
    (x0, z0), (x1, z1) = a, b
    wid = f"wall|{number}|{min(x0, x1):.2f}|{min(z0, z1):.2f}|{max(x0, x1):.2f}|{max(z0, z1):.2f}"
    poly = [Vec3(x=x0, z=z0), Vec3(x=x1, z=z1), Vec3(x=x0, y=WALL_HEIGHT, z=z0), Vec3(x=x1, y=WALL_HEIGHT, z=z1)]
    return Wall(id=wid, roomId=room, polygon=poly)


def two_room_house(door_width: float | None) -> House:
    """Two 3 m x 3 m bedrooms side by side (x 0..3 and 3..6), joined by a doorway centred on x = 3."""
    rects = {"room|2": (0.0, 0.0, 3.0, 3.0), "room|3": (3.0, 0.0, 6.0, 3.0)}
    rooms, walls = [], []
    for rid, (x0, z0, x1, z1) in rects.items():
        rooms.append(Room(id=rid, roomType="Bedroom",
                          floorPolygon=[Vec3(x=x0, z=z0), Vec3(x=x0, z=z1), Vec3(x=x1, z=z1), Vec3(x=x1, z=z0)]))
        for a, b in (((x0, z0), (x1, z0)), ((x1, z0), (x1, z1)), ((x0, z1), (x1, z1)), ((x0, z0), (x0, z1))):
            walls.append(_wall(rid, a, b))
            if a[0] != 3.0 or b[0] != 3.0:  # every side but the shared one is on the boundary
                walls.append(_wall("exterior", a, b))
    doors = []
    if door_width is not None:
        lo, hi = 1.5 - door_width / 2, 1.5 + door_width / 2
        doors.append(Opening(id="door|2|3", assetId="Doorframe_1", room0="room|2", room1="room|3",
                             wall0="wall|2|3.00|0.00|3.00|3.00", wall1="wall|3|3.00|0.00|3.00|3.00",
                             holePolygon=[Vec3(x=lo), Vec3(x=hi, y=2.1)]))
    house = House(rooms=rooms, walls=walls, doors=doors)
    house.set_agent_pose(1.5, 1.5, 90.0)
    return house


def test_synthetic_house_is_valid():
    house = two_room_house(0.9)
    assert validate_house(house) == []
    assert len(SceneGeometry.from_house(house).walls) == 7  # the shared wall is merged


@pytest.mark.parametrize(("width", "regions"), [(0.9, 1), (0.3, 2), (None, 2)])
def test_doorway_width_decides_connectivity(width, regions):
    grid = rasterize(SceneGeometry.from_house(two_room_house(width)))
    labels, n = grid.components(AGENT_RADIUS)
    assert n == regions
    left, right = grid.to_cell(1.5, 1.5), grid.to_cell(4.5, 1.5)
    assert labels[left] > 0 and labels[right] > 0
    assert bool(labels[left] == labels[right]) == (regions == 1)


def test_real_house_rasterizes(real_house):
    geometry = SceneGeometry.from_house(real_house)
    grid = rasterize(geometry)
    h, w = grid.shape
    assert (h, w) == grid.blocked.shape == grid.clearance.shape == grid.room.shape
    assert grid.label[0, 0] == LABEL_OUTSIDE and grid.blocked[0, 0]
    assert (grid.label == LABEL_WALL).any()
    assert set(np.unique(grid.label[grid.label >= LABEL_OBJECT0]) - LABEL_OBJECT0) == set(range(49))
    assert grid.room_at(12.5, 2.5) == "room|2" and grid.room_at(-1.0, -1.0) is None
    assert (grid.clearance[grid.blocked] == 0).all() and (grid.clearance[~grid.blocked] > 0).all()


def test_real_house_navigable_space_is_one_large_region(real_house):
    grid = rasterize(SceneGeometry.from_house(real_house))
    labels, n = grid.components(AGENT_RADIUS)
    sizes = np.bincount(labels.ravel())[1:]
    x, z, _ = real_house.agent_pose()
    start = labels[grid.to_cell(x, z)]
    assert start == 1 + int(np.argmax(sizes))
    assert sizes[start - 1] >= 0.95 * sizes.sum()
    # Every room has navigable cells in the start's region.
    assert set(np.unique(grid.room[labels == start])) >= set(range(len(grid.room_ids)))
