"""The asset catalog (derived from the ProcTHOR databases) and the one place that says what an object is.

``load_catalog()`` reads ``scene/data/assets.json`` (built by ``tools/build_asset_catalog.py``;
ProcTHOR data, Apache-2.0, see ``scene/data/NOTICE``). :func:`object_role` and :func:`is_movable`
decide, for every consumer, whether an object is floor furniture, wall decor, structure or a
small object resting on something.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from typing import Literal

ROOM_TYPES = ("Kitchen", "LivingRoom", "Bedroom", "Bathroom")
_ROOM_KEY = {"Kitchen": "inKitchens", "LivingRoom": "inLivingRooms", "Bedroom": "inBedrooms",
             "Bathroom": "inBathrooms"}

#: Types that are parts of the building, never furniture.
STRUCTURE_TYPES = frozenset({"Doorway", "Doorframe", "Window"})
#: Types that only ever hang on walls (ProcTHOR annotations: onWall and not onFloor).
WALL_TYPES = frozenset({"Blinds", "HandTowelHolder", "LightSwitch", "Painting", "ToiletPaperHanger",
                        "TowelHolder", "ShowerHead", "ShowerCurtain"})
#: Floor objects that are plumbing or built-in and therefore never moved by a generator.
FIXTURE_TYPES = frozenset({"CounterTop", "Sink", "Toilet"})
#: A top-level object whose bottom is above this height (m) is wall-mounted (e.g. a wall TV).
WALL_MOUNT_MIN_BOTTOM = 0.5
#: Objects at least this tall (m) block the agent's line of sight; lower ones do not.
OCCLUDER_MIN_HEIGHT = 1.2

ObjectRole = Literal["floor", "wall", "structure", "small"]


@dataclass(frozen=True)
class AssetInfo:
    """One asset: its object type and bounding box (full extents, m; z is depth, the front)."""

    asset_id: str
    object_type: str
    size: tuple[float, float, float]
    primary: str | None = None
    secondary: tuple[str, ...] = ()
    split: str | None = None
    open_size: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class TypeInfo:
    """ProcTHOR placement annotations of one object type."""

    object_type: str
    room_weights: dict[str, int] = field(default_factory=dict)
    in_corner: bool = False
    on_edge: bool = False
    in_middle: bool = False
    on_floor: bool = False
    on_wall: bool = False
    pickupable: bool = False
    multiple_per_room: bool = False

    def weight_in(self, room_type: str) -> int:
        """0 never, 1 sometimes, 2 common in rooms of this type."""
        return self.room_weights.get(room_type, 0)


@dataclass(frozen=True)
class WallHole:
    """Size of the hole a door or window asset cuts in a wall (asset-local min and max, m)."""

    min: tuple[float, float]
    max: tuple[float, float]
    offset: tuple[float, float, float]

    @property
    def width(self) -> float:
        return self.max[0] - self.min[0]

    @property
    def height(self) -> float:
        return self.max[1] - self.min[1]


@dataclass(frozen=True)
class AssetCatalog:
    """Asset ids, types, placement annotations, wall holes and valid material names."""

    assets: dict[str, AssetInfo]
    types: dict[str, TypeInfo]
    wall_holes: dict[str, WallHole]
    materials: dict[str, tuple[str, ...]]
    skyboxes: tuple[str, ...]
    attribution: str

    def asset(self, asset_id: str) -> AssetInfo:
        """The asset with this id; KeyError names the id if ProcTHOR does not have it."""
        try:
            return self.assets[asset_id]
        except KeyError:
            raise KeyError(f"unknown ProcTHOR assetId {asset_id!r}") from None

    def type_info(self, object_type: str) -> TypeInfo:
        """Placement annotations of a type (all-false defaults for types without annotations)."""
        return self.types.get(object_type) or TypeInfo(object_type)

    def assets_of_type(self, object_type: str, split: str | None = None) -> list[AssetInfo]:
        """Assets of one type, sorted by id; ``split`` keeps only train/val/test assets."""
        out = [a for a in self.assets.values() if a.object_type == object_type]
        if split is not None:
            out = [a for a in out if a.split == split]
        return sorted(out, key=lambda a: a.asset_id)

    @property
    def object_types(self) -> tuple[str, ...]:
        """All object types, sorted; the index of a type here is its stable class id."""
        return tuple(sorted(self.types))

    @property
    def material_names(self) -> frozenset[str]:
        return frozenset(n for names in self.materials.values() for n in names)


@lru_cache(maxsize=1)
def load_catalog() -> AssetCatalog:
    """Load the catalog shipped in the package (parsed once per process; the result is immutable)."""
    doc = json.loads(resources.files("adaptenv.scene").joinpath("data/assets.json").read_text("utf-8"))
    assets = {
        aid: AssetInfo(aid, a["type"], tuple(a["size"]), a.get("primary"), tuple(a.get("secondary", ())),
                       a.get("split"), tuple(a["open_size"]) if a.get("open_size") else None)
        for aid, a in doc["assets"].items()
    }
    types = {}
    for t, ann in doc["types"].items():
        types[t] = TypeInfo(
            t, {rt: int(ann.get(_ROOM_KEY[rt]) or 0) for rt in ROOM_TYPES},
            bool(ann.get("inCorner")), bool(ann.get("onEdge")), bool(ann.get("inMiddle")),
            bool(ann.get("onFloor")), bool(ann.get("onWall")), bool(ann.get("isPickupable")),
            bool(ann.get("multiplePerRoom")))
    holes = {k: WallHole(tuple(h["min"]), tuple(h["max"]), tuple(h["offset"])) for k, h in doc["wall_holes"].items()}
    return AssetCatalog(assets, types, holes, {k: tuple(v) for k, v in doc["materials"].items()},
                        tuple(doc["skyboxes"]), doc["attribution"])


def object_role(object_type: str, bottom_height: float, is_child: bool) -> ObjectRole:
    """Classify an object: ``floor`` furniture (a floor obstacle), ``wall`` decor, ``structure``, ``small``.

    Children (objects resting on another) are ``small``; a top-level object is wall-mounted when its
    type only hangs on walls or its bottom is above :data:`WALL_MOUNT_MIN_BOTTOM`.
    """
    if object_type in STRUCTURE_TYPES:
        return "structure"
    if is_child:
        return "small"
    if object_type in WALL_TYPES or bottom_height > WALL_MOUNT_MIN_BOTTOM:
        return "wall"
    return "floor"


def is_movable(object_type: str, role: ObjectRole) -> bool:
    """Whether a generator may move the object: floor furniture that is not a built-in fixture."""
    return role == "floor" and object_type not in FIXTURE_TYPES
