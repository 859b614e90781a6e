"""The scene graph of a hand-built room: sofa facing a TV against a wall, chair at a table, bowl on it."""

from __future__ import annotations

import json

import pytest

from adaptenv.scene.graph import NEXT_TO_DISTANCE, build_scene_graph
from adaptenv.scene.house import House, HouseObject, Room, Vec3, Wall
from adaptenv.scene.validate import validate_house

TV_WALL = "wall|2|0.00|5.00|6.00|5.00"


def _wall(room: str, a: tuple[float, float], b: tuple[float, float]) -> Wall:
    number = room.split("|")[-1] if room != "exterior" else "exterior"
    (x0, z0), (x1, z1) = a, b
    wid = f"wall|{number}|{min(x0, x1):.2f}|{min(z0, z1):.2f}|{max(x0, x1):.2f}|{max(z0, z1):.2f}"
    return Wall(id=wid, roomId=room, polygon=[Vec3(x=x0, z=z0), Vec3(x=x1, z=z1),
                                              Vec3(x=x0, y=2.5, z=z0), Vec3(x=x1, y=2.5, z=z1)])


def _obj(oid: str, asset: str, x: float, y: float, z: float, yaw: float, children=()) -> HouseObject:
    return HouseObject(id=oid, assetId=asset, position=Vec3(x=x, y=y, z=z), rotation=Vec3(y=yaw),
                       children=list(children))


def living_room(sofa_yaw: float = 0.0, chair_x: float = 1.2) -> House:
    """A 6 m x 5 m room (x 0..6, z 0..5).

    - TV (0.82 x 0.14 m) on the floor, back to the north wall z = 5, facing -z, at x = 4.5.
    - Sofa (1.55 x 0.95 m) in the middle at (4.5, 2.0), facing +z: its front edge (z = 2.47) is
      2.4 m from the TV.
    - Dining table (1.47 x 1.49 m) at (1.2, 1.2); a chair (0.47 x 0.50 m) at (chair_x, 2.3)
      facing -z, 0.11 m from the table; a bowl on the table.
    """
    corners = [(0.0, 0.0), (6.0, 0.0), (6.0, 5.0), (0.0, 5.0)]
    walls = []
    for a, b in zip(corners, corners[1:] + corners[:1], strict=True):
        walls += [_wall("room|2", a, b), _wall("exterior", a, b)]
    objects = [
        _obj("Television|1", "RoboTHOR_television_props_america_1_v", 4.5, 0.2603, 5.0 - 0.071, 180.0),
        _obj("Sofa|1", "RoboTHOR_sofa_alrid", 4.5, 0.4086, 2.0, sofa_yaw),
        _obj("DiningTable|1", "Dining_Table_16_1", 1.2, 0.4125, 1.2, 0.0,
             [_obj("Bowl|1", "Bowl_1", 1.2, 0.869, 1.2, 0.0)]),
        _obj("Chair|1", "Chair_002_1", chair_x, 0.4828, 2.3, 180.0),
    ]
    house = House(rooms=[Room(id="room|2", roomType="LivingRoom", floorPolygon=[Vec3(x=x, z=z) for x, z in corners])],
                  walls=walls, objects=objects)
    house.set_agent_pose(3.0, 3.5, 0.0)
    return house


@pytest.fixture
def graph():
    house = living_room()
    assert validate_house(house) == []
    return build_scene_graph(house)


def _pairs(graph, kind) -> set[tuple[str, str]]:
    return {(r.subject, r.object) for r in graph.relations_of(kind)}


def test_nodes_and_attributes(graph):
    assert set(graph.nodes) == {"Television|1", "Sofa|1", "DiningTable|1", "Bowl|1", "Chair|1"}
    assert graph.rooms == {"room|2": "LivingRoom"}
    sofa = graph.nodes["Sofa|1"]
    assert (sofa.type, sofa.role, sofa.movable, sofa.room, sofa.parent) == ("Sofa", "floor", True, "room|2", None)
    assert sofa.position == (4.5, 0.4086, 2.0) and sofa.yaw == 0.0
    assert sofa.size == pytest.approx((1.5486, 0.8171, 0.947))
    assert sofa.grid == pytest.approx((75.0, 100.0 * 2.0 / 6.0))  # the 6 m side spans 0..100
    bowl = graph.nodes["Bowl|1"]
    assert (bowl.role, bowl.movable, bowl.parent) == ("small", False, "DiningTable|1")


def test_in_room_and_on(graph):
    assert _pairs(graph, "in_room") == {(k, "room|2") for k in graph.nodes}
    assert _pairs(graph, "on") == {("Bowl|1", "DiningTable|1")}


def test_next_to(graph):
    assert _pairs(graph, "next_to") == {("DiningTable|1", "Chair|1")}
    assert graph.has("next_to", "Chair|1", "DiningTable|1")  # symmetric
    far = build_scene_graph(living_room(chair_x=1.2 + 0.735 + 0.235 + NEXT_TO_DISTANCE + 0.1))
    assert not far.relations_of("next_to")


def test_against_wall(graph):
    assert _pairs(graph, "against_wall") == {("Television|1", TV_WALL)}


def test_faces(graph):
    assert _pairs(graph, "faces") == {("Sofa|1", "Television|1"), ("Television|1", "Sofa|1"),
                                      ("Chair|1", "DiningTable|1"),
                                      # The table's local front (+z) points at the chair 0.11 m away.
                                      ("DiningTable|1", "Chair|1")}
    turned = build_scene_graph(living_room(sofa_yaw=90.0))  # now faces the east wall
    assert not turned.has("faces", "Sofa|1", "Television|1")


def test_sofa_with_its_back_to_a_wall():
    house = living_room()
    house.objects[1].position.z = 0.947 / 2 + 0.05  # back 5 cm from the south wall
    g = build_scene_graph(house)
    assert g.has("against_wall", "Sofa|1", "wall|2|0.00|0.00|6.00|0.00")
    assert not g.has("faces", "Sofa|1", "Television|1")  # 3.9 m away: out of range
    house.objects[1].rotation.y = 180.0  # facing the wall: not "against" it
    assert not build_scene_graph(house).has("against_wall", "Sofa|1", "wall|2|0.00|0.00|6.00|0.00")


def test_neighbors_and_json(graph):
    assert graph.neighbors("DiningTable|1") == ["Bowl|1", "Chair|1", "room|2"]
    assert graph.neighbors("Sofa|1", kind="faces") == ["Television|1"]
    doc = json.loads(json.dumps(graph.to_dict()))
    assert doc["nodes"]["Sofa|1"]["type"] == "Sofa"
    assert {"kind": "on", "subject": "Bowl|1", "object": "DiningTable|1"} in doc["relations"]


def test_real_house_graph(real_house):
    g = build_scene_graph(real_house)
    assert len(g.nodes) == 68 + 109
    assert len(g.relations_of("in_room")) == len(g.nodes)
    assert len(g.relations_of("on")) == 109
    assert g.has("faces", "Sofa|3|3", "TVStand|3|1|0")
    assert g.has("against_wall", "Sofa|3|3", "wall|3|8.77|5.26|15.78|5.26")
    assert g.has("next_to", "Chair|3|0|1", "DiningTable|3|0|0")
    assert g.nodes["Painting|4|4"].room == "room|4"


def test_a_subset_of_relation_kinds_gives_the_same_relations(real_house):
    full = build_scene_graph(real_house)
    part = build_scene_graph(real_house, kinds=("against_wall", "on"))
    assert part.nodes == full.nodes
    assert part.relations == [r for r in full.relations if r.kind in ("against_wall", "on")]
    assert part.relations_of("against_wall") and not part.relations_of("next_to")
    with pytest.raises(ValueError, match="unknown relation kinds"):
        build_scene_graph(real_house, kinds=("beside",))
