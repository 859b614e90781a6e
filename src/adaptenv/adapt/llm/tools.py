"""The generator's function tools: the paper's ``propose_move_instruction``, a verification tool, and (for G with
door edits) ``set_door_openness``.

``move_tool`` reproduces the paper's schema field for field (names, types, enums, bounds), so runs
can be compared with the paper's. Servers enforce schemas only on a best-effort basis, so every
answer goes through :func:`parse_move_instruction`, which clamps what can be clamped and reports
everything else as a :class:`MoveInstructionError` whose ``feedback`` is sent back to the model.

Coordinates follow the prompt's normalized 100x100 apartment grid: right and up are positive. The
schema does not say whether ``rotation`` is absolute or relative; the paper's prompt lists objects
with absolute rotations ("sofa at x=27, y=5, rotation=0"), and the generator that applies a move
decides how to read it.
"""

from __future__ import annotations

import json
import math
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from adaptenv.adapt.llm.errors import ModelAnswerError
from adaptenv.adapt.llm.messages import ToolSpec

MOVE_TOOL_NAME = "propose_move_instruction"
MOVE_TOOL_DESCRIPTION = ("Propose the change in position for exactly one object. Movement must be expressed "
                         "in a normalized 100x100 apartment grid as left/right and up/down units.")
MOVE_FIELDS = ("object_id", "x_direction", "x_units", "y_direction", "y_units", "rotation")
X_DIRECTIONS = ("left", "right")
Y_DIRECTIONS = ("up", "down")
#: Bounds of x_units / y_units (grid units) and of rotation (degrees), as in the paper's schema.
UNITS_MAX = 100.0
ROTATION_MAX = 360.0

VERIFY_TOOL_NAME = "verify_move"
VERIFY_TOOL_DESCRIPTION = ("Compare the rendered scene after your move with the effect you intended. Say whether "
                           "it matches; if it does not, you may propose a revised move of the same object.")
DOOR_TOOL_NAME = "set_door_openness"
DOOR_TOOL_DESCRIPTION = ("Instead of moving an object, open or shut exactly one interior door. A shut door is a "
                         "wall to the robot: it has to find another way, or search other rooms.")
DOOR_FIELDS = ("door_id", "open")

#: At most this many ids are listed in an "unknown object_id" message.
MAX_LISTED_IDS = 30


class MoveInstructionError(ModelAnswerError):
    """Arguments of propose_move_instruction (or verify_move) that cannot be used; lists every problem."""


class MoveInstruction(BaseModel):
    """One validated, clamped move: which object, how far along x and y (grid units), which rotation."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    object_id: str
    x_direction: Literal["left", "right"]
    x_units: float = Field(ge=0.0, le=UNITS_MAX)
    y_direction: Literal["up", "down"]
    y_units: float = Field(ge=0.0, le=UNITS_MAX)
    rotation: float = Field(ge=0.0, lt=ROTATION_MAX)
    clamped: tuple[str, ...] = ()
    """What was clamped or wrapped to fit the schema (e.g. ``x_units 120 -> 100``); empty when nothing was."""

    def signed_displacement(self) -> tuple[float, float]:
        """(dx_units, dy_units) on the normalized grid, right and up positive."""
        dx = self.x_units if self.x_direction == "right" else -self.x_units
        dy = self.y_units if self.y_direction == "up" else -self.y_units
        return dx, dy

    def to_arguments(self) -> dict[str, Any]:
        """The tool-call arguments this move corresponds to (for logs and replayed turns)."""
        return self.model_dump(mode="json", exclude={"clamped"})


class DoorInstruction(BaseModel):
    """One validated door edit: which interior door, and whether to open (true) or shut (false) it."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    door_id: str
    open: bool

    def to_arguments(self) -> dict[str, Any]:
        """The tool-call arguments this door edit corresponds to."""
        return self.model_dump(mode="json")


class Verification(BaseModel):
    """The yes/revise answer after a move was rendered; ``revised_move`` only when it did not match."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    matches_intent: bool
    reason: str
    revised_move: MoveInstruction | None = None


def _dedupe(ids: list[str]) -> list[str]:
    """Ids in first-seen order without repeats; ValueError when empty (an enum needs a value)."""
    out = list(dict.fromkeys(str(i) for i in ids))
    if not out:
        raise ValueError("the move tool needs at least one movable object id")
    return out


def move_parameters(allowed_object_ids: list[str]) -> dict[str, Any]:
    """The paper's parameter schema of propose_move_instruction for these movable object ids."""
    return {
        "type": "object",
        "properties": {
            "object_id": {"type": "string", "enum": _dedupe(allowed_object_ids)},
            "x_direction": {"type": "string", "enum": list(X_DIRECTIONS)},
            "x_units": {"type": "number", "minimum": 0, "maximum": 100},
            "y_direction": {"type": "string", "enum": list(Y_DIRECTIONS)},
            "y_units": {"type": "number", "minimum": 0, "maximum": 100},
            "rotation": {"type": "number", "minimum": 0, "maximum": 360},
        },
        "required": list(MOVE_FIELDS),
        "additionalProperties": False,
    }


def move_tool(allowed_object_ids: list[str]) -> ToolSpec:
    """The paper's ``propose_move_instruction`` tool, restricted to the scene's movable object ids."""
    return ToolSpec(MOVE_TOOL_NAME, MOVE_TOOL_DESCRIPTION, move_parameters(allowed_object_ids))


def door_tool(door_ids: list[str]) -> ToolSpec:
    """``set_door_openness``, restricted to the scene's interior doors with a leaf."""
    return ToolSpec(DOOR_TOOL_NAME, DOOR_TOOL_DESCRIPTION, {
        "type": "object",
        "properties": {"door_id": {"type": "string", "enum": _dedupe(door_ids)},
                       "open": {"type": "boolean", "description": "true opens the door, false shuts it"}},
        "required": list(DOOR_FIELDS), "additionalProperties": False})


def verify_tool(allowed_object_ids: list[str] | None = None) -> ToolSpec:
    """The verification tool: ``matches_intent`` (bool) and ``reason`` (str), plus a nullable
    ``revised_move`` with the move parameters when ``allowed_object_ids`` is given.

    Strict schemas need every property required, so "no revision" is ``revised_move: null``.
    """
    properties: dict[str, Any] = {
        "matches_intent": {"type": "boolean",
                           "description": "true if the rendered change has the effect you intended"},
        "reason": {"type": "string", "description": "one or two sentences on what you see in the rendering"},
    }
    if allowed_object_ids is not None:
        properties["revised_move"] = {
            "anyOf": [move_parameters(allowed_object_ids), {"type": "null"}],
            "description": "a corrected move when matches_intent is false, otherwise null",
        }
    return ToolSpec(VERIFY_TOOL_NAME, VERIFY_TOOL_DESCRIPTION,
                    {"type": "object", "properties": properties, "required": list(properties),
                     "additionalProperties": False})


def _number(name: str, value: object, problems: list[str]) -> float | None:
    """A finite float from a JSON number; records a problem for bools, strings, NaN and infinities."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        problems.append(f"{name} must be a number, got {json.dumps(value, default=str)[:40]}")
        return None
    if not math.isfinite(value):
        problems.append(f"{name} must be a finite number, got {value}")
        return None
    return float(value)


def _choice(name: str, value: object, options: tuple[str, ...] | list[str], problems: list[str]) -> str | None:
    """``value`` if it is one of ``options``; records a problem otherwise."""
    if not isinstance(value, str):
        problems.append(f"{name} must be a string, got {json.dumps(value, default=str)[:40]}")
        return None
    if value not in options:
        listed = ", ".join(f"'{o}'" for o in list(options)[:MAX_LISTED_IDS])
        more = f" (and {len(options) - MAX_LISTED_IDS} more)" if len(options) > MAX_LISTED_IDS else ""
        problems.append(f"{name} '{value[:60]}' is not allowed; use one of {listed}{more}")
        return None
    return value


def _fields(args: object, expected: tuple[str, ...], problems: list[str], prefix: str = "") -> dict[str, Any]:
    """``args`` as a dict; records a problem per missing or unexpected field."""
    if not isinstance(args, dict):
        problems.append(f"{prefix.rstrip('.') or 'the arguments'} must be a JSON object, got {type(args).__name__}")
        return {}
    missing = [f for f in expected if f not in args]
    extra = [str(k) for k in args if k not in expected]
    if missing:
        problems.append(f"missing field(s): {', '.join(prefix + f for f in missing)}")
    if extra:
        problems.append(f"unexpected field(s): {', '.join(prefix + f for f in extra)} "
                        f"(only {', '.join(expected)} are allowed)")
    return args


def _move_values(args: object, allowed_ids: list[str], problems: list[str], prefix: str = "") -> dict[str, Any]:
    """Checked and clamped move fields (units to [0, 100], rotation wrapped into [0, 360)); each clamp is noted."""
    a = _fields(args, MOVE_FIELDS, problems, prefix)
    out: dict[str, Any] = {}
    clamps: list[str] = []
    if "object_id" in a:
        out["object_id"] = _choice(prefix + "object_id", a["object_id"], allowed_ids, problems)
    for name, options in (("x_direction", X_DIRECTIONS), ("y_direction", Y_DIRECTIONS)):
        if name in a:
            out[name] = _choice(prefix + name, a[name], options, problems)
    for name in ("x_units", "y_units"):
        if name in a and (v := _number(prefix + name, a[name], problems)) is not None:
            out[name] = min(max(v, 0.0), UNITS_MAX)
            if out[name] != v:
                clamps.append(f"{prefix}{name} {v:g} -> {out[name]:g}")
    if "rotation" in a and (v := _number(prefix + "rotation", a["rotation"], problems)) is not None:
        r = v % ROTATION_MAX
        out["rotation"] = 0.0 if r >= ROTATION_MAX else r
        if out["rotation"] != v and v != ROTATION_MAX:  # 360 is in the paper's schema and means 0
            clamps.append(f"{prefix}rotation {v:g} -> {out['rotation']:g}")
    out["clamped"] = tuple(clamps)
    return out


def _raise(problems: list[str], args: object, tool: str) -> None:
    """Raise MoveInstructionError listing every problem, phrased for the model."""
    listed = "; ".join(problems)
    raise MoveInstructionError(f"invalid {tool} arguments: {listed}",
                               feedback=f"Your {tool} call was invalid: {listed}. Call {tool} again with "
                                        f"valid arguments.",
                               raw=json.dumps(args, default=str))


def parse_move_instruction(args: object, allowed_ids: list[str]) -> MoveInstruction:
    """Validate and clamp propose_move_instruction arguments.

    Units are clamped to [0, 100] and rotation wrapped into [0, 360) (e.g. 360 -> 0, -90 -> 270).
    Unknown ids, wrong types, NaN/infinity, bad enum values and missing or extra fields raise
    :class:`MoveInstructionError` listing all problems; ``exc.feedback`` goes back to the model.

    Example:
        >>> m = parse_move_instruction({"object_id": "Sofa|1", "x_direction": "left", "x_units": 5,
        ...     "y_direction": "up", "y_units": 120, "rotation": -90}, ["Sofa|1"])
        >>> m.signed_displacement(), m.rotation
        ((-5.0, 100.0), 270.0)
    """
    problems: list[str] = []
    values = _move_values(args, [str(i) for i in allowed_ids], problems)
    if problems:
        _raise(problems, args, MOVE_TOOL_NAME)
    return MoveInstruction(**values)


def parse_door_instruction(args: object, allowed_ids: list[str]) -> DoorInstruction:
    """Validate set_door_openness arguments; every problem goes back to the model as one MoveInstructionError."""
    problems: list[str] = []
    a = _fields(args, DOOR_FIELDS, problems)
    door = _choice("door_id", a["door_id"], [str(i) for i in allowed_ids], problems) if "door_id" in a else None
    if "open" in a and not isinstance(a["open"], bool):
        problems.append(f"open must be true or false, got {json.dumps(a['open'], default=str)[:40]}")
    if problems:
        _raise(problems, args, DOOR_TOOL_NAME)
    return DoorInstruction(door_id=str(door), open=bool(a["open"]))


def parse_verification(args: object, allowed_ids: list[str] | None = None) -> Verification:
    """Validate verify_move arguments; a revised move is checked like a move (and dropped when it matched)."""
    problems: list[str] = []
    expected = ("matches_intent", "reason") + (("revised_move",) if allowed_ids is not None else ())
    a = _fields(args, expected, problems)
    matches = a.get("matches_intent")
    if "matches_intent" in a and not isinstance(matches, bool):
        problems.append(f"matches_intent must be true or false, got {json.dumps(matches, default=str)[:40]}")
    reason = a.get("reason")
    if "reason" in a and not isinstance(reason, str):
        problems.append(f"reason must be a string, got {json.dumps(reason, default=str)[:40]}")
    revised = None
    if allowed_ids is not None and a.get("revised_move") is not None:
        revised = _move_values(a["revised_move"], [str(i) for i in allowed_ids], problems, "revised_move.")
    if problems:
        _raise(problems, args, VERIFY_TOOL_NAME)
    move = MoveInstruction(**revised) if revised is not None and not matches else None
    return Verification(matches_intent=bool(matches), reason=str(reason), revised_move=move)
