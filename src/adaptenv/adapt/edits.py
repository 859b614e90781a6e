"""Edit records: what a generator asked for, what placement achieved, and whether validation kept it.

An :class:`Edit` is the paper's tool call (``object_id``, x/y displacement in normalized grid
units, ``rotation``) plus its outcome. ``rotation`` is the object's requested new *absolute* yaw
in degrees (0 faces world +z / "up" on the map, 90 faces +x / "right"), not a delta; None keeps
the yaw. Grid units follow :class:`~adaptenv.scene.grid.NormalizedGrid`: +dx is right (world +x),
+dy is up (world +z).

A door edit (``openness`` set) opens or shuts one interior door instead: ``object_id`` is then the door's
id, ``openness_before`` and ``openness`` its openness before and after (0 shut, 1 open), and the move
fields stay 0.

An asset swap (``asset_id`` set) replaces one object's asset by another of the same type and asset split,
keeping its place and heading (``y_after``: the new asset's centre height, so it stands where the old one
stood); a material edit (``material`` set) gives a room's floor or walls (``surface``) another catalog
material, ``object_id`` then being the room's id. Both keep the move fields at 0
(:mod:`adaptenv.adapt.appearance` makes and validates them).

An :class:`EditLog` round-trips through JSON, and :func:`apply_edit` / :func:`replay` rebuild an
edited scene from its parent by replaying the *achieved* moves (never re-running placement).

Example:
    >>> log = EditLog.from_json(path.read_text())  # doctest: +SKIP
    >>> child = replay(parent, log)  # doctest: +SKIP
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from adaptenv.errors import AdaptenvError
from adaptenv.files import atomic_write_text
from adaptenv.scene.house import House, move_object, set_door_openness

StopReason = Literal["reached", "blocked_by_object", "blocked_by_wall", "left_room", "rotation_blocked",
                     "invalid"]


class Edit(BaseModel):
    """One requested change of one object and its outcome (meters are world x/z, units the 0..100 grid)."""

    model_config = ConfigDict(frozen=True)

    object_id: str
    dx_units: float = 0.0
    """Requested move right (+) / left (-) in grid units."""
    dy_units: float = 0.0
    """Requested move up (+, world +z) / down (-) in grid units."""
    rotation: float | None = None
    """Requested new absolute yaw in degrees [0, 360); None keeps the current yaw."""
    relocate: bool = False
    """True for a relocation: the object was set down at the move's end (possibly in another room), not marched."""
    achieved_dx: float = 0.0
    """Achieved move along world x, m."""
    achieved_dz: float = 0.0
    """Achieved move along world z, m."""
    achieved_dx_units: float = 0.0
    achieved_dy_units: float = 0.0
    yaw_before: float = 0.0
    yaw_after: float = 0.0
    stop_reason: StopReason = "reached"
    """The first limit met: the translation's stop, else ``rotation_blocked``, else ``reached``."""
    blocked_by: str | None = None
    """Object id, wall id or door/window/open-wall id that stopped the move."""
    steps: int = 0
    """Number of placement steps (delta each) moved."""
    accepted: bool = True
    """False when validation rejected the placed result (the scene was left unchanged)."""
    problems: list[str] = Field(default_factory=list)
    """Why validation rejected it (one sentence per problem)."""
    source: str = "manual"
    """Name of the generator that proposed the edit."""
    intent: str = ""
    """Free-text intent (e.g. the LLM's reason, the suggestion it implements)."""
    undone: bool = False
    """True when the generator took the edit back (replaced by a revision, or its step was aborted)."""
    openness: float | None = None
    """A door edit's requested openness (0 shut, 1 open); None for an object edit."""
    openness_before: float | None = None
    """A door edit's openness before it."""
    asset_id: str | None = None
    """An asset swap's new asset id (same type and split as ``asset_before``); None for any other edit."""
    asset_before: str | None = None
    """An asset swap's old asset id."""
    y_after: float | None = None
    """An asset swap's new centre height (m): the new asset rests where the old one did."""
    material: str | None = None
    """A material edit's new material (a catalog name); ``object_id`` is then a room id. None for any other edit."""
    material_before: str | None = None
    """A material edit's material before it."""
    surface: Literal["floor", "wall"] | None = None
    """A material edit's surface: the room's floor or its walls."""

    @property
    def is_door(self) -> bool:
        """Whether this edit opens or shuts a door (``object_id`` is the door's id)."""
        return self.openness is not None

    @property
    def is_swap(self) -> bool:
        """Whether this edit swaps an object's asset (``object_id`` keeps its place)."""
        return self.asset_id is not None

    @property
    def is_material(self) -> bool:
        """Whether this edit changes a room's floor or wall material (``object_id`` is the room's id)."""
        return self.material is not None

    @property
    def changed(self) -> bool:
        """Whether replaying this edit changes the scene."""
        if not self.accepted or self.undone:
            return False
        if self.is_door:
            return self.openness != self.openness_before
        if self.is_swap:
            return self.asset_id != self.asset_before
        if self.is_material:
            return self.material != self.material_before
        return self.achieved_dx != 0.0 or self.achieved_dz != 0.0 or _yaw_delta(self) != 0.0


def _yaw_delta(edit: Edit) -> float:
    d = (edit.yaw_after - edit.yaw_before) % 360.0
    return 0.0 if min(d, 360.0 - d) < 1e-9 else d


class EditLog(BaseModel):
    """Every edit tried on a scene, in order (rejected ones included, marked ``accepted=False``)."""

    edits: list[Edit] = Field(default_factory=list)

    def append(self, edit: Edit) -> None:
        self.edits.append(edit)

    def __len__(self) -> int:
        return len(self.edits)

    def __iter__(self):  # type: ignore[override]
        return iter(self.edits)

    @property
    def accepted(self) -> list[Edit]:
        return [e for e in self.edits if e.accepted]

    def to_json(self, indent: int | None = 1) -> str:
        return self.model_dump_json(indent=indent)

    @classmethod
    def from_json(cls, text: str) -> EditLog:
        return cls.model_validate_json(text)

    def save(self, path: str | Path) -> Path:
        p = Path(path)
        atomic_write_text(p, self.to_json())
        return p

    @classmethod
    def load(cls, path: str | Path) -> EditLog:
        p = Path(path)
        try:
            return cls.from_json(p.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise AdaptenvError(f"{p}: no such edit log; check the path") from None
        except ValueError as exc:
            raise AdaptenvError(f"{p}: not a valid edit log ({str(exc).splitlines()[0]}); "
                                "write it with EditLog.save") from None


def apply_edit(house: House, edit: Edit, *, in_place: bool = False) -> House:
    """The house with an edit's achieved move (or door openness) replayed; a copy unless ``in_place``.

    Rejected and undone edits change nothing. Raises AdaptenvError when the object (or door) is not in the house.
    """
    out = house if in_place else house.model_copy(deep=True)
    if not edit.accepted or edit.undone:
        return out
    if edit.is_door:
        try:
            set_door_openness(out, edit.object_id, edit.openness)
        except KeyError:
            raise AdaptenvError(f"edit of door {edit.object_id!r}: the house has no door with this id; replay the "
                                "edit on the house it was made on") from None
        return out
    if edit.is_material:
        return _apply_material(out, edit)
    for obj in out.objects:
        if obj.id == edit.object_id and edit.is_swap:
            obj.assetId = edit.asset_id
            if edit.y_after is not None:
                obj.position = obj.position.model_copy(update={"y": edit.y_after})
            return out
        if obj.id == edit.object_id:
            dyaw = _yaw_delta(edit)
            if math.isfinite(dyaw):
                move_object(obj, edit.achieved_dx, edit.achieved_dz, dyaw)
            return out
    raise AdaptenvError(f"edit of {edit.object_id!r}: the house has no top-level object with this id; "
                        "replay the edit on the house it was made on")


def _apply_material(house: House, edit: Edit) -> House:
    """``house`` (changed in place) with a room's floor or walls given the edit's material."""
    room = next((r for r in house.rooms if r.id == edit.object_id), None)
    if room is None:
        raise AdaptenvError(f"material edit of room {edit.object_id!r}: the house has no room with this id; replay "
                            "the edit on the house it was made on")
    if edit.surface == "floor":
        room.floorMaterial = {"name": edit.material}
    else:
        for wall in house.walls:
            if wall.roomId == room.id:
                wall.material = {"name": edit.material}
    return house


def replay(house: House, log: EditLog | list[Edit]) -> House:
    """A copy of ``house`` with every accepted edit of the log applied in order."""
    out = house.model_copy(deep=True)
    for edit in log:
        apply_edit(out, edit, in_place=True)
    return out


#: A net move smaller than this (m) or a net turn smaller than NET_TURN (degrees) is no net change.
NET_MOVE = 0.01
NET_TURN = 1.0


def net_change(original: House, edited: House, object_id: str) -> tuple[float, float, bool]:
    """(distance m, turn degrees, door toggled, asset or material changed) from an object's (or door's, or
    room's) state in ``original`` to ``edited``: what its edits add up to, so an object moved back where it
    stood has (0, 0, False)."""
    rooms = {r.id: r for r in original.rooms}
    if object_id in rooms:
        return 0.0, 0.0, _surfaces(original, object_id) != _surfaces(edited, object_id)
    doors = {d.id: d for d in original.doors}
    if object_id in doors:
        after = next((d for d in edited.doors if d.id == object_id), doors[object_id])
        def openness(d) -> float:  # a door without an openness is open
            return 1.0 if d.openness is None else float(d.openness)

        return 0.0, 0.0, openness(after) != openness(doors[object_id])
    try:
        a, b = original.object_by_id(object_id), edited.object_by_id(object_id)
    except KeyError:
        return 0.0, 0.0, False
    turn = (b.yaw - a.yaw) % 360.0
    return (math.hypot(b.position.x - a.position.x, b.position.z - a.position.z), min(turn, 360.0 - turn),
            a.assetId != b.assetId)


def _surfaces(house: House, room_id: str) -> tuple[str, ...]:
    """A room's floor material and its walls' materials (names), for comparing two versions of a house."""
    room = next((r for r in house.rooms if r.id == room_id), None)
    return (material_name(room, "floorMaterial"),
            *sorted(material_name(w, "material") for w in house.walls if w.roomId == room_id))


def material_name(part: object, key: str) -> str:
    """The material name a room (``floorMaterial``) or wall (``material``) carries, '' when it has none."""
    value = getattr(part, key, None) if part is not None else None
    return str(value.get("name", "")) if isinstance(value, dict) else ""


def edit_counts(edits: list[Edit], original: House, edited: House) -> dict:
    """How a person counts a run's edits: applied edits, distinct objects edited, objects changed on net
    (moved at least NET_MOVE, turned at least NET_TURN, a door opened or shut, an asset swapped or a room's material
    changed) and the net displacement
    (m, summed over the objects); ``objects`` gives each edited object's edits and net move, in edit order."""
    per: dict[str, int] = {}
    for e in edits:
        per[e.object_id] = per.get(e.object_id, 0) + 1
    objects = []
    for oid, n in per.items():
        dist, turn, toggled = net_change(original, edited, oid)
        changed = dist >= NET_MOVE or turn >= NET_TURN or toggled
        objects.append({"id": oid, "edits": n, "net_move_m": round(dist, 4), "net_turn_deg": round(turn, 2),
                        "changed": changed})
    return {"edits": len(edits), "objects_edited": len(per), "objects_changed": sum(o["changed"] for o in objects),
            "net_displacement_m": round(sum(o["net_move_m"] for o in objects if o["changed"]), 4), "objects": objects}
