"""Property-based fuzzing of the house parser, the validator and the trajectory loader.

Random and mutated documents (NaN, infinity, huge, negative, wrong types, missing and extra keys)
never raise anything but adaptenv's own errors, whose messages are one short line, and every house
that parses round-trips (parse -> write -> parse gives the same house).

The default run (hypothesis profile ``ci``, tests/conftest.py) is 100 examples per property, deterministic.
The long run is 10,000 random examples per property::

    ADAPTENV_FUZZ_PROFILE=long pytest -q -p no:cacheprovider tests/scene/test_fuzz.py tests/test_fuzz_readers.py
"""

from __future__ import annotations

import functools
import json
import math
import re
from pathlib import Path
from typing import Any

import hypothesis.strategies as st
import pytest
from hypothesis import HealthCheck, given, settings

from adaptenv.errors import AdaptenvError, HouseError
from adaptenv.scene.house import House, load_house, parse_house
from adaptenv.scene.procedural.presets import generate_preset
from adaptenv.scene.validate import validate_house, validate_house_file
from adaptenv.sim.trajectory import EpisodeMetrics, Pose, Step, Trajectory

REAL_HOUSE = Path(__file__).parents[1] / "data" / "procthor-10k-train-1.json"
FUZZ = settings(suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
"""The profile's example count and determinism (tests/conftest.py)."""

ODD_NUMBERS = [math.nan, math.inf, -math.inf, 1e308, -1e308, 1e6, -1e6, -1.0, 0.0, 5e-324, 10**30, -(10**30)]
"""Numbers a user may type by mistake: not finite, huge, tiny, negative."""
JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=6),
                    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3),
                    max_leaves=8)
"""Any JSON value, NaN and infinity included."""
ODD_VALUE = st.sampled_from(ODD_NUMBERS) | st.floats() | JSON


@functools.cache
def seed_documents() -> tuple[dict[str, Any], ...]:
    """The real ProcTHOR house and the small preset houses, as JSON documents."""
    presets = tuple(house.to_dict() for _, house in generate_preset("tiny"))
    return (json.loads(REAL_HOUSE.read_text()), *presets)


def _pick_container(data: st.DataObject, doc: dict | list) -> dict | list:
    """A dict or list inside ``doc``, found by a random walk down from the top."""
    node = doc
    while True:
        inner = [v for v in (node.values() if isinstance(node, dict) else node) if isinstance(v, dict | list)]
        if not inner or data.draw(st.integers(0, 4), label="stop?") == 0:
            return node
        node = data.draw(st.sampled_from(inner), label="into")


def _scale(doc: Any, factor: float) -> Any:
    """Every x and z in the document times ``factor`` (a house in the wrong units)."""
    if isinstance(doc, dict):
        return {k: v * factor if k in ("x", "z") and isinstance(v, int | float) and not isinstance(v, bool)
                else _scale(v, factor) for k, v in doc.items()}
    if isinstance(doc, list):
        return [_scale(v, factor) for v in doc]
    return doc


def mutate(data: st.DataObject, doc: Any, max_mutations: int = 3) -> Any:
    """``doc`` with 1..max_mutations random edits: values replaced, keys and items removed or added."""
    doc = json.loads(json.dumps(doc))  # a deep copy, faster than copy.deepcopy
    if data.draw(st.integers(0, 9), label="scale?") == 0:
        doc = _scale(doc, data.draw(st.sampled_from([1e6, -1e3, 1e-9, 1e300]), label="factor"))
    for _ in range(data.draw(st.integers(1, max_mutations), label="mutations")):
        if not isinstance(doc, dict | list):
            return data.draw(ODD_VALUE, label="document")
        parent = _pick_container(data, doc)
        keys = list(parent) if isinstance(parent, dict) else list(range(len(parent)))
        op = data.draw(st.sampled_from(["replace", "number", "delete", "add"]), label="op")
        if op == "add" or not keys:
            if isinstance(parent, dict):
                parent[data.draw(st.text(max_size=8), label="key")] = data.draw(ODD_VALUE, label="value")
            else:
                parent.append(json.loads(json.dumps(parent[0])) if parent else data.draw(ODD_VALUE, label="value"))
            continue
        key = data.draw(st.sampled_from(keys), label="key")
        if op == "delete":
            del parent[key]
        elif op == "number":
            parent[key] = data.draw(st.sampled_from(ODD_NUMBERS), label="number")
        else:
            parent[key] = data.draw(ODD_VALUE, label="value")
    return doc


def assert_one_short_line(message: str) -> None:
    """A message a user can read: one line, no runaway numbers."""
    assert "\n" not in message and "Traceback" not in message, message
    assert not re.search(r"\d{25}", message), message


@pytest.fixture(scope="module")
def scratch(tmp_path_factory) -> Path:
    """One folder for the files every example writes (and overwrites)."""
    return tmp_path_factory.mktemp("fuzz")


def write(doc: Any, path: Path) -> Path:
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


@FUZZ
@given(data=st.data())
def test_mutated_houses_raise_only_house_errors(data):
    doc = mutate(data, data.draw(st.sampled_from(seed_documents()), label="seed"))
    try:
        house = parse_house(doc, "house.json")
    except HouseError as err:
        assert all(p.file == "house.json" for p in err.problems)
        assert_one_short_line(str(err))
        return
    for problem in validate_house(house, file="house.json"):
        assert_one_short_line(str(problem))


def test_a_huge_integer_inside_a_value_of_the_wrong_type_is_not_printed():
    """Found by the fuzz: the message quoted the whole value, 25 digits included."""
    with pytest.raises(HouseError, match=r"^house.json: at doors, the value \{\.\.\.\} is invalid"):
        parse_house({"rooms": [], "doors": {"": 10**24}}, "house.json")


@FUZZ
@given(doc=JSON)
def test_random_documents_raise_only_house_errors(doc):
    try:
        house = parse_house(doc, "random.json")
    except HouseError as err:
        assert_one_short_line(str(err))
        return
    for problem in validate_house(house):
        assert_one_short_line(str(problem))


@FUZZ
@given(data=st.data())
def test_houses_that_parse_round_trip(data):
    doc = mutate(data, data.draw(st.sampled_from(seed_documents()), label="seed"))
    try:
        house = parse_house(doc)
    except HouseError:
        return
    again = parse_house(json.loads(json.dumps(house.to_dict())))  # what save_house writes, read back
    assert json.dumps(again.to_dict(), sort_keys=True) == json.dumps(house.to_dict(), sort_keys=True)


@FUZZ
@given(data=st.data(), value=st.sampled_from(ODD_NUMBERS) | st.floats())
def test_validator_never_raises_on_a_house_edited_in_code(data, value):
    house = House.model_validate(data.draw(st.sampled_from(seed_documents()), label="seed"))
    vectors = [r.floorPolygon[0] for r in house.rooms] + [o.position for o, _ in house.iter_objects()]
    vectors += [o.rotation for o, _ in house.iter_objects()]
    target = data.draw(st.sampled_from(vectors), label="vector")
    object.__setattr__(target, data.draw(st.sampled_from("xyz"), label="axis"), value)  # unvalidated, as code may
    for problem in validate_house(house, file="edited.json"):
        assert_one_short_line(str(problem))


def trajectory_document() -> dict[str, Any]:
    """A short episode in the real house's kitchen as a JSON document."""
    steps = [Step(pose=Pose(x=10.0 + i, z=2.5, yaw=0.0), action="m", moved=i != 2, visible=["Fridge|2|1"],
                  clearance=0.3, geodesic=4.0 - i) for i in range(4)]
    metrics = EpisodeMetrics(success=True, spl=0.8, sel=0.7, episode_length=4, path_length=4.0, final_geodesic=0.0,
                             collisions=1, min_clearance=0.3, rooms_visited=1, first_sight_step=0,
                             optimal_path_length=3.2)
    traj = Trajectory(house="kitchen", target_type="Fridge", target_ids=["Fridge|2|1"],
                      target_positions=[(15.403, 2.205)], start=Pose(x=10.0, z=2.5, yaw=0.0), steps=steps,
                      final_pose=Pose(x=14.0, z=2.5, yaw=0.0), policy="expert", seed=0, metrics=metrics)
    return json.loads(traj.model_dump_json())


@FUZZ
@given(data=st.data())
def test_trajectory_loader_raises_only_adaptenv_errors(data, scratch):
    doc = (mutate(data, trajectory_document()) if data.draw(st.booleans(), label="mutated?")
           else data.draw(JSON, label="document"))
    path = write(doc, scratch / "traj.json")
    try:
        Trajectory.load(path)
    except AdaptenvError as err:
        assert str(path) in str(err)
        assert_one_short_line(str(err))


@FUZZ
@given(text=st.text(max_size=40) | st.sampled_from(["[" * 100_000, "1" * 5000, "{\"rooms\": NaN}", "\ud800"]))
def test_unreadable_text_is_an_adaptenv_error(text, scratch):
    path = scratch / "file.json"
    path.write_bytes(text.encode("utf-8", "surrogatepass"))
    assert validate_house_file(path)
    for load in (load_house, Trajectory.load):
        try:
            load(path)
        except AdaptenvError as err:
            assert_one_short_line(str(err))
