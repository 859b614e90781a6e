"""Houses with numbers no real house has, and a trajectory from another house: one line, exit 1, no traceback."""

from __future__ import annotations

import json
import re

import pytest
from typer.testing import CliRunner

from adaptenv.cli import app
from adaptenv.errors import ConfigError, HouseError
from adaptenv.scene.house import save_house
from adaptenv.sim.trajectory import Pose, Step, Trajectory

runner = CliRunner()


def _scale_world(doc: dict, factor: float) -> None:
    """Multiply every world x and z (rooms, walls, objects, agent starts) by ``factor``."""
    points = [p for r in doc["rooms"] for p in r["floorPolygon"]] + [p for w in doc["walls"] for p in w["polygon"]]
    points += [o["position"] for o in doc["objects"]] + [c["position"] for o in doc["objects"] for c in o.get("children", [])]
    points += [doc["metadata"]["agent"]["position"]] + [p["position"] for p in doc["metadata"]["agentPoses"].values()]
    for p in points:
        p["x"], p["z"] = p["x"] * factor, p["z"] * factor


def _set(path: tuple, value: float):
    def edit(doc: dict) -> None:
        node = doc
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
    return edit


# (case, edit of the real house, JSON path the message names, text the message holds)
CASES = [
    ("nan-object-x", _set(("objects", 0, "position", "x"), float("nan")), "objects[0].position.x", "not a finite number"),
    ("inf-room-corner", _set(("rooms", 2, "floorPolygon", 1, "x"), float("inf")), "rooms[2].floorPolygon[1].x",
     "not a finite number"),
    ("nan-rotation", _set(("objects", 3, "rotation", "y"), float("nan")), "objects[3].rotation.y", "not a finite number"),
    ("scaled-1e6", lambda doc: _scale_world(doc, 1e6), "rooms[0].floorPolygon[2].x",
     "makes the house 1.58e+07 m across along x, more than any real house"),
    ("1e308", _set(("objects", 0, "position", "x"), 1e308), "objects[0].position.x", "the value 1e+308 makes the house"),
]


@pytest.fixture(params=CASES, ids=[c[0] for c in CASES])
def bad_house(request, real_house_path, tmp_path):
    _, edit, where, text = request.param
    doc = json.loads(real_house_path.read_text())
    edit(doc)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(doc))
    return path, where, text


def _assert_one_short_line(message: str) -> None:
    assert "\n" not in message and "Traceback" not in message
    assert not re.search(r"\d{20}", message), message


def test_validate_names_the_file_and_field(bad_house):
    path, where, text = bad_house
    result = runner.invoke(app, ["validate", str(path)])
    assert result.exit_code == 1, result.output
    first = result.output.splitlines()[0]
    assert first.startswith(f"{path}: at {where}, ") and text in first
    _assert_one_short_line(first)


@pytest.mark.parametrize("command", [["render", "-o", "{tmp}/map.png"], ["rollout", "-o", "{tmp}/traj.json"]])
def test_render_and_rollout_refuse_with_one_line(bad_house, command, tmp_path):
    path, where, text = bad_house
    args = [command[0], str(path), *(a.format(tmp=tmp_path) for a in command[1:])]
    result = runner.invoke(app, args)
    assert result.exit_code == 1 and isinstance(result.exception, HouseError), result.output
    message = str(result.exception)
    assert message.startswith(f"{path}: at {where}, ") and text in message
    _assert_one_short_line(message)
    assert not (tmp_path / "map.png").exists() and not (tmp_path / "traj.json").exists()


def test_render_refuses_a_trajectory_from_another_house(real_house_path, tmp_path):
    from tests.sim import helpers as H

    fridge = {"target_ids": ["Fridge|2|1"], "target_positions": [(15.403, 2.205)]}  # the real house's fridge
    start = Pose(x=10.0, z=2.5, yaw=0.0)
    traj = Trajectory(house=str(real_house_path), target_type="Fridge", start=start, steps=[Step(pose=start, action="end")],
                      **fridge).save(tmp_path / "traj.json")
    other = save_house(H.one_room(), tmp_path / "other.json")
    result = runner.invoke(app, ["render", str(other), "-t", str(traj), "-o", str(tmp_path / "map.png")])
    assert result.exit_code == 1 and isinstance(result.exception, ConfigError), result.output
    message = str(result.exception)
    assert message.startswith(f"{traj}: recorded in house ") and str(other) in message and "\n" not in message
    assert not (tmp_path / "map.png").exists()
    ok = runner.invoke(app, ["render", str(real_house_path), "-t", str(traj), "-o", str(tmp_path / "map.png")])
    assert ok.exit_code == 0, ok.output
