"""The ProcTHOR house document as typed, editable data that round-trips losslessly.

Every model keeps keys it does not declare (``extra="allow"``) and is written back with
``exclude_unset``, so ``save_house(load_house(p), q)`` reproduces the original document as parsed
JSON (:mod:`adaptenv.scene.house` reads and writes the files, and re-exports everything here).
Coordinates are meters with y up; yaw is ``rotation.y`` in degrees (0 faces +z, 90 faces +x).
Parsing refuses numbers no real house has (NaN, infinity, a house wider than ``MAX_HOUSE_SIZE``; see
:func:`number_problems`), so nothing downstream meets them.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationError

from adaptenv.errors import HouseError, Problem
from adaptenv.files import FileRefused, JSONTooDeep, loads_json, read_bytes
from adaptenv.limits import HOUSE_BYTES

SCHEMA_VERSION = "1.0.0"
AGENT_POSE_KINDS = ("default", "arm", "locobot", "stretch")

#: The widest house (m, along any axis, over rooms, walls, objects and agent starts) that is accepted.
#: ProcTHOR-10K houses are at most a few tens of metres across (the 10-room house in tests/data spans
#: 15.8 x 17.5 m); at the simulator's 5 cm cells 100 m is a 2000 x 2000 raster, so a house in the
#: wrong units (mm, or scaled by 1e6) is refused instead of exhausting memory.
MAX_HOUSE_SIZE = 100.0
#: The farthest (m) any world coordinate may lie from the origin (ProcTHOR houses start at (0, 0)).
MAX_COORDINATE = 1000.0
#: The largest angle (degrees, rotations and camera horizon) accepted; real files use 0..360.
MAX_ANGLE = 3600.0


class _Model(BaseModel):
    model_config = ConfigDict(extra="allow", populate_by_name=True, allow_inf_nan=False)


class Vec3(_Model):
    """A point or Euler rotation ``{x, y, z}``."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


class Room(_Model):
    """A room: id ``room|N``, a type, and its rectilinear floor polygon (implicitly closed)."""

    id: str
    roomType: str
    floorPolygon: list[Vec3]


class Wall(_Model):
    """One side of a wall: id ``wall|room|minX|minZ|maxX|maxZ``; ``empty`` walls are open."""

    id: str
    roomId: str
    polygon: list[Vec3]
    empty: bool | None = None


class Opening(_Model):
    """A door or window cut into ``wall0`` (and its twin ``wall1``); hole in wall0-local coordinates."""

    id: str
    assetId: str
    room0: str
    room1: str
    wall0: str
    wall1: str
    holePolygon: list[Vec3]
    assetPosition: Vec3 | None = None
    openable: bool | None = None
    openness: float | None = None


class HouseObject(_Model):
    """A placed asset; ``children`` rest on it and carry absolute world positions."""

    id: str
    assetId: str
    position: Vec3
    rotation: Vec3 = Field(default_factory=Vec3)
    kinematic: bool | None = None
    children: list[HouseObject] = Field(default_factory=list)

    @property
    def yaw(self) -> float:
        """Yaw in degrees, in [0, 360)."""
        return self.rotation.y % 360.0


class AgentPose(_Model):
    """Where the agent starts: position (y = camera height), yaw in ``rotation.y``."""

    position: Vec3
    rotation: Vec3 = Field(default_factory=Vec3)
    horizon: float | None = None
    standing: bool | None = None


class Metadata(_Model):
    """House metadata; AI2-THOR reads ``agentPoses``, older readers ``agent``."""

    agent: AgentPose | None = None
    agentPoses: dict[str, AgentPose] | None = None
    schema_: str | None = Field(default=None, alias="schema")
    roomSpecId: str | None = None


class House(_Model):
    """A whole ProcTHOR house; ``proceduralParameters`` is passed through untouched."""

    rooms: list[Room]
    walls: list[Wall] = Field(default_factory=list)
    doors: list[Opening] = Field(default_factory=list)
    windows: list[Opening] = Field(default_factory=list)
    objects: list[HouseObject] = Field(default_factory=list)
    proceduralParameters: dict[str, Any] = Field(default_factory=dict)
    metadata: Metadata = Field(default_factory=Metadata)
    _dropped_children: list[tuple[str, str]] = PrivateAttr(default_factory=list)

    @property
    def dropped_children(self) -> list[tuple[str, str]]:
        """(object id, asset id) of the child objects of unknown assets left out when the house was read
        (``--skip-unknown-assets``; see :func:`adaptenv.scene.validate.drop_unknown_children`)."""
        return self._dropped_children

    def to_dict(self) -> dict[str, Any]:
        """The house as a JSON-ready dict, unknown keys included."""
        return self.model_dump(mode="json", by_alias=True, exclude_unset=True)

    def iter_objects(self) -> Iterator[tuple[HouseObject, HouseObject | None]]:
        """Every object with its parent (None for top-level objects), parents first."""
        for obj in self.objects:
            yield obj, None
            for child in obj.children:
                yield child, obj

    def object_by_id(self, object_id: str) -> HouseObject:
        """The object (top-level or child) with this id; KeyError if there is none."""
        for obj, _ in self.iter_objects():
            if obj.id == object_id:
                return obj
        raise KeyError(object_id)

    def agent_pose(self) -> tuple[float, float, float] | None:
        """The start pose (x, z, yaw degrees) from metadata, preferring ``agentPoses.default``."""
        pose = None
        if self.metadata.agentPoses and "default" in self.metadata.agentPoses:
            pose = self.metadata.agentPoses["default"]
        elif self.metadata.agent is not None:
            pose = self.metadata.agent
        if pose is None:
            return None
        return pose.position.x, pose.position.z, pose.rotation.y % 360.0

    def set_agent_pose(self, x: float, z: float, yaw: float) -> None:
        """Write the start pose to both ``metadata.agent`` and every ``metadata.agentPoses`` kind."""
        def pose(standing: bool | None) -> AgentPose:
            return AgentPose(position=Vec3(x=x, y=0.95, z=z), rotation=Vec3(x=0.0, y=yaw % 360.0, z=0.0),
                             horizon=30.0, standing=standing)

        self.metadata.agent = pose(True)
        self.metadata.agentPoses = {k: pose(None if k == "locobot" else True) for k in AGENT_POSE_KINDS}
        if self.metadata.schema_ is None:
            self.metadata.schema_ = SCHEMA_VERSION


def move_object(obj: HouseObject, dx: float, dz: float, dyaw: float = 0.0) -> None:
    """Move an object rigidly in the floor plane, children included (they keep absolute positions).

    The object turns by ``dyaw`` degrees about its own centre, then shifts by (dx, dz).
    """
    cx, cz = obj.position.x, obj.position.z
    t = math.radians(dyaw)
    cos_t, sin_t = math.cos(t), math.sin(t)
    for child in obj.children:
        rx, rz = child.position.x - cx, child.position.z - cz
        # Yaw turns +z toward +x, so a point (x, z) maps to (x cos + z sin, -x sin + z cos).
        child.position = Vec3(**{**child.position.model_dump(), "x": cx + rx * cos_t + rz * sin_t + dx,
                                 "z": cz - rx * sin_t + rz * cos_t + dz})
        if dyaw:
            child.rotation = Vec3(**{**child.rotation.model_dump(), "y": (child.rotation.y + dyaw) % 360.0})
    obj.position = Vec3(**{**obj.position.model_dump(), "x": cx + dx, "z": cz + dz})
    if dyaw:
        obj.rotation = Vec3(**{**obj.rotation.model_dump(), "y": (obj.rotation.y + dyaw) % 360.0})


def is_interior_leaf_door(door: Opening) -> bool:
    """Whether a door can open and close between two rooms: openable (it has a leaf) and not the front door."""
    return bool(door.openable) and door.room0 != door.room1 and "exterior" not in door.wall1


def is_shut(door: Opening) -> bool:
    """Whether a door is shut (openness 0); a door without an openness is open."""
    return door.openness is not None and door.openness <= 0


def set_door_openness(house: House, door_id: str, openness: float) -> None:
    """Set one door's openness (0 shut, 1 open) in place; KeyError when the house has no such door."""
    for door in house.doors:
        if door.id == door_id:
            door.openness = float(openness)
            return
    raise KeyError(door_id)


def json_path(loc: tuple[Any, ...] | list[Any]) -> str:
    """Format a location tuple such as ``('doors', 2, 'wall0')`` as ``doors[2].wall0``."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out or "$"


def short(value: Any) -> str:
    """A value for a one-line message: numbers to 3 significant digits, objects and arrays as ``{...}``
    and ``[...]``, anything else a repr of at most 40 characters."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        try:
            return f"{value:.3g}"
        except OverflowError:
            return "an integer too large for a float"
    if isinstance(value, dict | list):
        return "{...}" if isinstance(value, dict) else "[...]"
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _problems_from_validation(err: ValidationError, file: str | None) -> list[Problem]:
    problems = []
    for e in err.errors():
        loc = tuple(p for p in e["loc"] if not (isinstance(p, str) and p in ("function-after",)))
        msg = e["msg"][0].lower() + e["msg"][1:]
        if e["type"] == "missing":
            text = f"the required key '{loc[-1]}' is missing; add it as the ProcTHOR format requires"
            loc = loc[:-1]
        elif e["type"] == "finite_number":
            text = f"the value {short(e.get('input'))} is not a finite number; write a plain number (meters or degrees)"
        else:
            text = f"the value {short(e.get('input'))} is invalid ({msg}); fix it to match the ProcTHOR format"
        problems.append(Problem(json_path(loc), text, file))
    return problems


def _world_points(house: House) -> Iterator[tuple[tuple[Any, ...], Vec3]]:
    """Every point in world coordinates (room and wall corners, objects, agent starts) with its location."""
    for i, room in enumerate(house.rooms):
        for j, p in enumerate(room.floorPolygon):
            yield ("rooms", i, "floorPolygon", j), p
    for i, wall in enumerate(house.walls):
        for j, p in enumerate(wall.polygon):
            yield ("walls", i, "polygon", j), p
    for i, obj in enumerate(house.objects):
        yield ("objects", i, "position"), obj.position
        for j, child in enumerate(obj.children):
            yield ("objects", i, "children", j, "position"), child.position
    for loc, pose in _agent_poses(house):
        yield (*loc, "position"), pose.position


def _agent_poses(house: House) -> Iterator[tuple[tuple[Any, ...], AgentPose]]:
    """The agent start poses in metadata with their location."""
    if house.metadata.agent is not None:
        yield ("metadata", "agent"), house.metadata.agent
    for kind, pose in (house.metadata.agentPoses or {}).items():
        yield ("metadata", "agentPoses", kind), pose


def _bounded_values(house: House) -> Iterator[tuple[tuple[Any, ...], float, float, str]]:
    """Angles and wall-local lengths with their location, limit and unit."""
    for kind in ("doors", "windows"):
        for i, op in enumerate(getattr(house, kind)):
            points = [(("holePolygon", j), p) for j, p in enumerate(op.holePolygon)]
            points += [(("assetPosition",), op.assetPosition)] if op.assetPosition is not None else []
            for sub, p in points:
                for axis in "xyz":
                    yield (kind, i, *sub, axis), getattr(p, axis), MAX_HOUSE_SIZE, "m"
    rotations = [(("objects", i), o.rotation) for i, o in enumerate(house.objects)]
    rotations += [(("objects", i, "children", j), c.rotation)
                  for i, o in enumerate(house.objects) for j, c in enumerate(o.children)]
    rotations += [(loc, pose.rotation) for loc, pose in _agent_poses(house)]
    for loc, r in rotations:
        for axis in "xyz":
            yield (*loc, "rotation", axis), getattr(r, axis), MAX_ANGLE, "degrees"
    for loc, pose in _agent_poses(house):
        if pose.horizon is not None:
            yield (*loc, "horizon"), pose.horizon, MAX_ANGLE, "degrees"


def number_problems(house: House, file: str | None = None) -> list[Problem]:
    """Numbers no real house has: coordinates spanning more than MAX_HOUSE_SIZE or lying farther than
    MAX_COORDINATE from the origin, angles and wall-local lengths beyond their limits, NaN and infinity."""
    points = list(_world_points(house))
    xyz = np.array([(p.x, p.y, p.z) for _, p in points], dtype=float).reshape(-1, 3)
    bounded = list(_bounded_values(house))
    bad = [((*points[i][0], "xyz"[a]), xyz[i, a]) for i, a in zip(*np.nonzero(~np.isfinite(xyz)), strict=True)]
    bad += [(loc, v) for loc, v, _, _ in bounded if not math.isfinite(v)]
    if bad:  # only a house edited in code gets here: the parser refuses NaN and infinity
        return [Problem(json_path(loc), f"the value {short(v)} is not a finite number; write a plain number "
                        "(meters or degrees)", file) for loc, v in bad]
    out: list[Problem] = []
    for a, axis in enumerate("xyz" if len(xyz) else ""):
        col = xyz[:, a]
        span = float(col.max()) - float(col.min())  # Python floats: 1e308 - -1e308 is inf, no warning
        if span > MAX_HOUSE_SIZE:
            with np.errstate(over="ignore"):
                i = int(np.argmax(np.abs(col - np.median(col))))
            out.append(Problem(json_path((*points[i][0], axis)), f"the value {short(col[i])} makes the house "
                               f"{short(span)} m across along {axis}, more than any real house (the limit is "
                               f"{MAX_HOUSE_SIZE:.0f} m); give every coordinate in meters", file))
        elif np.abs(col).max() > MAX_COORDINATE:
            i = int(np.argmax(np.abs(col)))
            out.append(Problem(json_path((*points[i][0], axis)), f"the value {short(col[i])} m is more than "
                               f"{MAX_COORDINATE:.0f} m from the origin; move the house near (0, 0)", file))
    for loc, v, limit, unit in bounded:
        if abs(v) > limit:
            out.append(Problem(json_path(loc), f"the value {short(v)} {unit} is beyond the limit of {short(limit)} "
                               f"{unit}; give a value between {short(-limit)} and {short(limit)}", file))
    return out


def parse_house(doc: Any, file: str | None = None) -> House:
    """Build a House from a parsed JSON document; HouseError lists every structural problem, including
    numbers that are not finite or make the house larger than any real one."""
    if not isinstance(doc, dict):
        raise HouseError([Problem("$", f"the document is a JSON {type(doc).__name__}, not an object; "
                                  "a house is a JSON object with 'rooms', 'walls', 'doors', ...", file)])
    try:
        house = House.model_validate(doc)
    except ValidationError as err:
        raise HouseError(_problems_from_validation(err, file)) from None
    if problems := number_problems(house, file):
        raise HouseError(problems)
    return house


def read_house_document(path: str | Path) -> Any:
    """Read a JSON file, turning unreadable or non-JSON content into a HouseError."""
    p = Path(path)
    if p.name.lower().endswith((".jsonl", ".jsonl.gz")):
        raise HouseError([Problem("$", "this is a house dataset (one house per line), not one house file; pass it "
                                  "to --houses (FILE.jsonl.gz:0:100 picks lines) or split it into files with "
                                  "`adaptenv houses export`", str(p))])
    try:
        text = read_bytes(p, HOUSE_BYTES, "house").decode("utf-8")
    except FileNotFoundError:
        raise HouseError([Problem("$", "the file does not exist; check the path", str(p))]) from None
    except FileRefused as exc:
        raise HouseError([Problem("$", f"the file {exc.reason}", str(p))]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise HouseError([Problem("$", f"the file cannot be read ({exc}); check it is a UTF-8 JSON file "
                                  "(a gzip dataset of houses, one per line, must be named .jsonl.gz)", str(p))]) from None
    try:
        return loads_json(text)
    except json.JSONDecodeError as exc:
        raise HouseError([Problem("$", f"the file is not valid JSON ({exc.msg} at line {exc.lineno}, "
                                  f"column {exc.colno}); fix the syntax", str(p))]) from None
    except JSONTooDeep as exc:
        raise HouseError([Problem("$", f"the file is refused: {exc}; "
                                  "write a ProcTHOR house JSON file", str(p))]) from None
    except ValueError as exc:  # an integer of more than 4300 digits
        raise HouseError([Problem("$", f"the file is not valid JSON ({str(exc).split(';')[0]}); "
                                  "fix the number", str(p))]) from None
