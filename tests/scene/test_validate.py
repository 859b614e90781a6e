"""validate_house / validate_house_file: one test per malformed case, every problem listed."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from adaptenv.errors import HouseError
from adaptenv.scene.house import load_house, parse_house
from adaptenv.scene.validate import validate_house, validate_house_file


@pytest.fixture
def doc(real_house_path) -> dict:
    return json.loads(real_house_path.read_text())


def _write(tmp_path: Path, doc, name: str = "broken.json") -> Path:
    p = tmp_path / name
    p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return p


def _paths(problems) -> list[str]:
    return [p.path for p in problems]


def _one_problem(tmp_path: Path, doc, path: str, *words: str):
    """Validate the document as a file; exactly one problem, at ``path``, naming the file and words."""
    f = _write(tmp_path, doc)
    problems = validate_house_file(f)
    assert _paths(problems) == [path], [str(p) for p in problems]
    text = str(problems[0])
    assert text.startswith(f"{f}: at {path}, ")
    for w in words:
        assert w in problems[0].message
    return problems[0]


def _square_room_house(polygon: list[tuple[float, float]]) -> dict:
    """A one-room house without walls or objects, with the given floor polygon."""
    return {"rooms": [{"id": "room|2", "roomType": "Bedroom",
                       "floorPolygon": [{"x": x, "y": 0, "z": z} for x, z in polygon]}],
            "walls": [], "doors": [], "windows": [], "objects": [], "metadata": {}}


def test_real_house_has_no_problems(real_house_path, real_house):
    assert validate_house_file(real_house_path) == []
    assert validate_house(real_house) == []


def test_not_json(tmp_path):
    _one_problem(tmp_path, "{not json", "$", "not valid JSON")


def test_not_an_object(tmp_path):
    _one_problem(tmp_path, "[1, 2]", "$", "not an object")


def test_missing_file(tmp_path):
    problems = validate_house_file(tmp_path / "nope.json")
    assert len(problems) == 1 and "nope.json" in str(problems[0]) and "does not exist" in problems[0].message


def test_missing_rooms(tmp_path, doc):
    del doc["rooms"]
    _one_problem(tmp_path, doc, "$", "'rooms'", "missing")


def test_wrong_field_type(tmp_path, doc):
    doc["objects"][3]["position"]["x"] = "left"
    problems = validate_house_file(_write(tmp_path, doc))
    assert _paths(problems) == ["objects[3].position.x"]


def test_wall_id_does_not_parse(tmp_path, doc):
    doc["walls"][3]["id"] = "wall-2-east"
    _one_problem(tmp_path, doc, "walls[3].id", "'wall-2-east'", "wall|room|minX|minZ|maxX|maxZ")


def test_wall_polygon_needs_four_vertices(tmp_path, doc):
    doc["walls"][3]["polygon"] = doc["walls"][3]["polygon"][:3]
    _one_problem(tmp_path, doc, "walls[3].polygon", "3 vertices")


def test_door_names_a_missing_wall(tmp_path, doc):
    doc["doors"][2]["wall0"] = "wall|99|0.00|0.00|1.00|0.00"
    _one_problem(tmp_path, doc, "doors[2].wall0", "'wall|99|0.00|0.00|1.00|0.00'", "does not exist")


def test_window_names_a_missing_room(tmp_path, doc):
    doc["windows"][1]["room1"] = "room|42"
    _one_problem(tmp_path, doc, "windows[1].room1", "'room|42'")


def test_hole_outside_the_wall(tmp_path, doc):
    doc["doors"][0]["holePolygon"][1]["x"] = 40.0
    _one_problem(tmp_path, doc, "doors[0].holePolygon", "outside the wall")


def test_hole_needs_two_points(tmp_path, doc):
    doc["windows"][0]["holePolygon"] = doc["windows"][0]["holePolygon"][:1]
    _one_problem(tmp_path, doc, "windows[0].holePolygon", "1 points, not 2")


@pytest.mark.parametrize("where", [("objects", 5), ("children", 0, 2), ("doors", 1), ("windows", 2)])
def test_unknown_asset_id(tmp_path, doc, where):
    if where[0] == "children":
        target, path = doc["objects"][where[1]]["children"][where[2]], f"objects[{where[1]}].children[{where[2]}].assetId"
    else:
        target, path = doc[where[0]][where[1]], f"{where[0]}[{where[1]}].assetId"
    target["assetId"] = "Sofa_999_NoSuch"
    fix = "not a ProcTHOR asset" if where[0] in ("doors", "windows") else "pass --assets FILE"
    _one_problem(tmp_path, doc, path, "'Sofa_999_NoSuch'", fix)


def test_room_id_and_type(tmp_path, doc):
    doc["rooms"][9]["roomType"] = "Garage"
    _one_problem(tmp_path, doc, "rooms[9].roomType", "'Garage'", "Kitchen")


@pytest.mark.parametrize(("polygon", "words"), [
    ([(0, 0), (4, 0)], "2 distinct vertices"),                    # cannot close
    ([(0, 0), (4, 0), (0, 0), (4, 0)], "2 distinct vertices"),    # repeats do not count
    ([(0, 0), (2, 0), (4, 0)], "zero area"),                       # collinear: degenerate
    ([(0, 0), (4, 4), (4, 0), (0, 4)], "not simple"),              # bow tie: self-intersecting
])
def test_bad_floor_polygon(tmp_path, polygon, words):
    _one_problem(tmp_path, _square_room_house(polygon), "rooms[0].floorPolygon", words)


def test_repeated_closing_vertex_and_collinear_vertices_are_fine(tmp_path):
    doc = _square_room_house([(0, 0), (2, 0), (4, 0), (4, 4), (0, 4), (0, 0)])
    assert validate_house_file(_write(tmp_path, doc)) == []


def test_object_outside_every_room(tmp_path, doc):
    i = next(k for k, o in enumerate(doc["objects"]) if o["id"] == "HousePlant|2|2|0")
    doc["objects"][i]["position"]["x"] = -3.0
    _one_problem(tmp_path, doc, f"objects[{i}].position", "HousePlant", "not inside any room")


def test_object_sticking_through_a_wall(tmp_path, doc):
    # The fridge (0.85 m wide, back to the wall x = 15.78) pushed 0.2 m through it.
    i = next(k for k, o in enumerate(doc["objects"]) if o["id"] == "Fridge|2|1")
    for c in [doc["objects"][i], *doc["objects"][i]["children"]]:
        c["position"]["x"] += 0.2
    _one_problem(tmp_path, doc, f"objects[{i}].position", "not inside any room")


def test_wall_object_and_child_outside(tmp_path, doc):
    i = next(k for k, o in enumerate(doc["objects"]) if o["id"] == "Painting|5|4")
    doc["objects"][i]["position"]["x"] = -2.0
    doc["objects"][0]["children"][3]["position"]["z"] = -1.5
    problems = validate_house_file(_write(tmp_path, doc))
    assert _paths(problems) == [f"objects[{i}].position", "objects[0].children[3].position"]
    assert "outside the house" in problems[0].message and "neither on its parent" in problems[1].message


def test_duplicate_object_id(tmp_path, doc):
    doc["objects"][7]["id"] = doc["objects"][6]["id"]
    _one_problem(tmp_path, doc, "objects[7].id", "already used by objects[6]")


def test_agent_start_outside(tmp_path, doc):
    doc["metadata"]["agentPoses"]["default"]["position"]["x"] = 40.0
    _one_problem(tmp_path, doc, "metadata.agentPoses.default.position", "outside every room")


def test_several_problems_are_all_listed(tmp_path, doc):
    doc["walls"][3]["id"] = "bad"
    doc["doors"][2]["wall0"] = "wall|99|0.00|0.00|1.00|0.00"
    doc["objects"][5]["assetId"] = "Nope"
    doc["rooms"][1]["roomType"] = "Attic"
    doc["metadata"]["agent"]["position"]["z"] = -10.0
    f = _write(tmp_path, doc)
    problems = validate_house_file(f)
    assert sorted(_paths(problems)) == sorted(["walls[3].id", "doors[2].wall0", "objects[5].assetId",
                                              "rooms[1].roomType", "metadata.agent.position"])
    assert all(p.file == str(f) for p in problems)
    with pytest.raises(HouseError) as err:
        load_house(f)
    assert len(err.value.problems) == 5 and "4 more problems" in str(err.value)


def test_validate_house_is_pure_and_file_optional(doc):
    doc["objects"][5]["assetId"] = "Nope"
    house = parse_house(doc)
    first = validate_house(house)
    assert first == validate_house(house)
    assert str(first[0]) == "at objects[5].assetId, " + first[0].message
