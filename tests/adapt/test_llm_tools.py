"""The generator's tools: the paper's propose_move_instruction schema, validation/clamping, verify_move."""

from __future__ import annotations

import math

import pytest

from adaptenv.adapt.llm import (
    ModelAnswerError,
    MoveInstruction,
    MoveInstructionError,
    move_tool,
    parse_move_instruction,
    parse_verification,
    verify_tool,
)

IDS = ["Sofa|1", "Chair|2", "Bed|3"]
GOOD = {"object_id": "Chair|2", "x_direction": "right", "x_units": 10, "y_direction": "down", "y_units": 4.5,
        "rotation": 45}

# The paper's appendix schema, transcribed literally (allowed_object_ids = IDS).
PAPER_TOOL = {
    "type": "function",
    "name": "propose_move_instruction",
    "description": (
        "Propose the change in position for exactly one object. "
        "Movement must be expressed in a normalized 100x100 apartment grid as left/right and up/down units."),
    "parameters": {
        "type": "object",
        "properties": {
            "object_id": {"type": "string", "enum": IDS},
            "x_direction": {"type": "string", "enum": ["left", "right"]},
            "x_units": {"type": "number", "minimum": 0, "maximum": 100},
            "y_direction": {"type": "string", "enum": ["up", "down"]},
            "y_units": {"type": "number", "minimum": 0, "maximum": 100},
            "rotation": {"type": "number", "minimum": 0, "maximum": 360}},
        "required": ["object_id", "x_direction", "x_units", "y_direction", "y_units", "rotation"],
        "additionalProperties": False,
    }}


def test_move_tool_matches_the_paper_field_for_field():
    spec = move_tool(IDS).as_dict()
    assert spec.pop("strict") is True
    assert spec == PAPER_TOOL
    assert list(spec["parameters"]["properties"]) == list(PAPER_TOOL["parameters"]["properties"])


def test_move_tool_dedupes_ids_and_rejects_empty():
    assert move_tool(["a", "b", "a"]).parameters["properties"]["object_id"]["enum"] == ["a", "b"]
    with pytest.raises(ValueError, match="at least one"):
        move_tool([])


def test_valid_arguments_parse():
    move = parse_move_instruction(GOOD, IDS)
    assert move == MoveInstruction(object_id="Chair|2", x_direction="right", x_units=10.0, y_direction="down",
                                   y_units=4.5, rotation=45.0)
    assert move.signed_displacement() == (10.0, -4.5)
    assert move.to_arguments() == {**GOOD, "x_units": 10.0, "rotation": 45.0}


@pytest.mark.parametrize(("xd", "yd", "expected"), [("right", "up", (3.0, 2.0)), ("left", "up", (-3.0, 2.0)),
                                                    ("right", "down", (3.0, -2.0)), ("left", "down", (-3.0, -2.0))])
def test_signed_displacement_right_and_up_positive(xd, yd, expected):
    move = parse_move_instruction({**GOOD, "x_direction": xd, "x_units": 3, "y_direction": yd, "y_units": 2}, IDS)
    assert move.signed_displacement() == expected


@pytest.mark.parametrize(("field", "value", "expected"), [
    ("x_units", 150, 100.0), ("x_units", -3, 0.0), ("y_units", 100.0001, 100.0), ("y_units", 0, 0.0),
    ("rotation", 360, 0.0), ("rotation", 370, 10.0), ("rotation", -90, 270.0), ("rotation", 359.5, 359.5),
    ("rotation", 720, 0.0), ("rotation", -1e-20, 0.0),
])
def test_clamping(field, value, expected):
    move = parse_move_instruction({**GOOD, field: value}, IDS)
    assert getattr(move, field) == expected
    assert 0.0 <= move.rotation < 360.0


@pytest.mark.parametrize(("args", "needle"), [
    ({**GOOD, "object_id": "Lamp|9"}, "object_id 'Lamp|9' is not allowed; use one of 'Sofa|1', 'Chair|2', 'Bed|3'"),
    ({**GOOD, "object_id": 7}, "object_id must be a string"),
    ({**GOOD, "x_units": "10"}, 'x_units must be a number, got "10"'),
    ({**GOOD, "y_units": True}, "y_units must be a number, got true"),
    ({**GOOD, "rotation": None}, "rotation must be a number, got null"),
    ({**GOOD, "x_units": math.nan}, "x_units must be a finite number"),
    ({**GOOD, "rotation": math.inf}, "rotation must be a finite number"),
    ({**GOOD, "x_direction": "up"}, "x_direction 'up' is not allowed; use one of 'left', 'right'"),
    ({**GOOD, "y_direction": "Down"}, "y_direction 'Down' is not allowed; use one of 'up', 'down'"),
    ({k: v for k, v in GOOD.items() if k != "rotation"}, "missing field(s): rotation"),
    ({**GOOD, "z_units": 1}, "unexpected field(s): z_units"),
    ([GOOD], "the arguments must be a JSON object, got list"),
])
def test_every_validation_error_path(args, needle):
    with pytest.raises(MoveInstructionError) as info:
        parse_move_instruction(args, IDS)
    exc = info.value
    assert isinstance(exc, ModelAnswerError)
    assert needle in exc.feedback and needle in str(exc)
    assert exc.feedback.endswith("Call propose_move_instruction again with valid arguments.")


def test_all_problems_are_reported_at_once():
    bad = {"object_id": "Nope", "x_direction": "sideways", "x_units": "far", "extra": 1}
    with pytest.raises(MoveInstructionError) as info:
        parse_move_instruction(bad, IDS)
    text = info.value.feedback
    for needle in ("missing field(s): y_direction, y_units, rotation", "unexpected field(s): extra",
                   "object_id 'Nope'", "x_direction 'sideways'", "x_units must be a number"):
        assert needle in text
    assert '"extra": 1' in info.value.raw


def test_long_id_lists_are_truncated_in_feedback():
    ids = [f"Obj|{i}" for i in range(100)]
    with pytest.raises(MoveInstructionError, match=r"and 70 more"):
        parse_move_instruction({**GOOD, "object_id": "Nope"}, ids)


def test_verify_tool_schema():
    plain = verify_tool()
    assert plain.name == "verify_move"
    assert plain.parameters["required"] == ["matches_intent", "reason"]
    assert plain.parameters["properties"]["matches_intent"]["type"] == "boolean"
    assert plain.parameters["additionalProperties"] is False
    with_revision = verify_tool(IDS).parameters
    assert with_revision["required"] == ["matches_intent", "reason", "revised_move"]
    move_schema, null = with_revision["properties"]["revised_move"]["anyOf"]
    assert move_schema == PAPER_TOOL["parameters"] and null == {"type": "null"}


def test_parse_verification():
    yes = parse_verification({"matches_intent": True, "reason": "the gap is narrower"})
    assert yes.matches_intent and yes.revised_move is None
    revised = parse_verification({"matches_intent": False, "reason": "moved the wrong way",
                                  "revised_move": {**GOOD, "x_units": 250}}, IDS)
    assert not revised.matches_intent and revised.revised_move.x_units == 100.0
    ignored = parse_verification({"matches_intent": True, "reason": "ok", "revised_move": GOOD}, IDS)
    assert ignored.revised_move is None
    none = parse_verification({"matches_intent": False, "reason": "r", "revised_move": None}, IDS)
    assert none.revised_move is None


@pytest.mark.parametrize(("args", "allowed", "needle"), [
    ({"matches_intent": "yes", "reason": "r"}, None, "matches_intent must be true or false"),
    ({"matches_intent": True, "reason": 3}, None, "reason must be a string"),
    ({"matches_intent": True}, None, "missing field(s): reason"),
    ({"matches_intent": True, "reason": "r", "revised_move": None}, None, "unexpected field(s): revised_move"),
    ({"matches_intent": False, "reason": "r", "revised_move": {**GOOD, "object_id": "X"}}, IDS,
     "revised_move.object_id 'X' is not allowed"),
    ({"matches_intent": False, "reason": "r", "revised_move": "left"}, IDS, "revised_move must be a JSON object"),
])
def test_verification_errors(args, allowed, needle):
    with pytest.raises(MoveInstructionError) as info:
        parse_verification(args, allowed)
    assert needle in info.value.feedback
    assert "verify_move" in info.value.feedback


def test_the_door_tool_and_its_answers():
    from adaptenv.adapt.llm.tools import DoorInstruction, door_tool, parse_door_instruction

    doors = ["door|2|3", "door|3|4"]
    params = door_tool(doors).parameters
    assert params["properties"]["door_id"]["enum"] == doors and params["required"] == ["door_id", "open"]
    assert parse_door_instruction({"door_id": "door|3|4", "open": False}, doors) == DoorInstruction(
        door_id="door|3|4", open=False)
    with pytest.raises(MoveInstructionError) as exc:
        parse_door_instruction({"door_id": "door|9|9", "open": "yes", "why": 1}, doors)
    text = exc.value.feedback
    assert "door_id 'door|9|9' is not allowed" in text and "open must be true or false" in text
    assert "unexpected field(s): why" in text and "set_door_openness" in text
