"""House documents round-trip losslessly; agent poses and rigid moves edit them correctly."""

from __future__ import annotations

import copy
import json

import pytest

from adaptenv.scene.house import SCHEMA_VERSION, load_house, move_object, parse_house, save_house


def test_real_house_round_trips(real_house_path, tmp_path):
    out = save_house(load_house(real_house_path), tmp_path / "sub" / "copy.json")
    assert json.loads(out.read_text()) == json.loads(real_house_path.read_text())


def test_unknown_keys_survive_at_every_level(real_house_path):
    doc = json.loads(real_house_path.read_text())
    doc["myTopKey"] = {"a": [1, 2]}
    doc["rooms"][0]["myRoomKey"] = "r"
    doc["rooms"][0]["floorPolygon"][0]["w"] = 7
    doc["walls"][0]["myWallKey"] = 1.5
    doc["doors"][0]["myDoorKey"] = None
    doc["windows"][0]["myWindowKey"] = [1]
    doc["objects"][0]["myObjectKey"] = True
    doc["objects"][0]["position"]["extra"] = 3
    doc["objects"][0]["children"][0]["myChildKey"] = {"deep": {"deeper": 1}}
    doc["metadata"]["myMetaKey"] = "m"
    doc["metadata"]["agent"]["myAgentKey"] = 2
    doc["metadata"]["agentPoses"]["default"]["myPoseKey"] = 3
    doc["proceduralParameters"]["myParam"] = {"x": 1}
    assert parse_house(copy.deepcopy(doc)).to_dict() == doc


def test_set_agent_pose_writes_both_places(real_house_path, tmp_path):
    doc = json.loads(real_house_path.read_text())
    doc["metadata"] = {}  # no schema, no poses
    house = parse_house(doc)
    house.set_agent_pose(3.0, 4.5, 450.0)
    out = json.loads(save_house(house, tmp_path / "h.json").read_text())["metadata"]
    assert out["schema"] == SCHEMA_VERSION == "1.0.0"
    assert out["agent"]["position"] == {"x": 3.0, "y": 0.95, "z": 4.5}
    assert out["agent"]["rotation"]["y"] == 90.0
    assert set(out["agentPoses"]) == {"default", "arm", "locobot", "stretch"}
    for pose in out["agentPoses"].values():
        assert (pose["position"]["x"], pose["position"]["z"], pose["rotation"]["y"]) == (3.0, 4.5, 90.0)
    assert load_house(tmp_path / "h.json", validate=False).agent_pose() == (3.0, 4.5, 90.0)


def test_move_object_turns_children_rigidly(real_house):
    table = real_house.objects[0]
    table.position.x, table.position.z, table.rotation.y = 1.0, 1.0, 0.0
    a, b = table.children[0], table.children[1]
    a.position.x, a.position.z, a.rotation.y = 2.0, 1.0, 0.0  # 1 m along the table's local +x
    b.position.x, b.position.z, b.rotation.y = 1.0, 2.0, 300.0  # 1 m along its local +z (its front)
    y_before = a.position.y
    move_object(table, 0.5, 0.0, 90.0)
    # A 90 degree turn maps local x to (cos 90, -sin 90) = (0, -1) and local z to (sin 90, cos 90) = (1, 0);
    # then everything shifts by (0.5, 0).
    assert (table.position.x, table.position.z, table.rotation.y) == pytest.approx((1.5, 1.0, 90.0))
    assert (a.position.x, a.position.z) == pytest.approx((1.5, 0.0))
    assert (b.position.x, b.position.z) == pytest.approx((2.5, 1.0))
    assert (a.rotation.y, b.rotation.y) == pytest.approx((90.0, 30.0))
    assert a.position.y == y_before


def test_move_object_translation_only_keeps_yaw(real_house):
    obj = real_house.objects[1]
    x, z, yaw = obj.position.x, obj.position.z, obj.rotation.y
    kids = [(c.position.x, c.position.z, c.rotation.y) for c in obj.children]
    move_object(obj, -0.25, 0.75)
    assert (obj.position.x, obj.position.z, obj.rotation.y) == pytest.approx((x - 0.25, z + 0.75, yaw))
    for c, (cx, cz, cyaw) in zip(obj.children, kids, strict=True):
        assert (c.position.x, c.position.z, c.rotation.y) == pytest.approx((cx - 0.25, cz + 0.75, cyaw))
