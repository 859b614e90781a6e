"""The asset catalog (derived from the ProcTHOR databases) and the one place that says what an object is.

``load_catalog()`` reads ``scene/data/assets.json`` (built by ``tools/build_asset_catalog.py``;
ProcTHOR data, Apache-2.0, see ``scene/data/NOTICE``), extended by any user asset tables given
with :func:`use_assets` (the CLI's ``--assets FILE``) or the ``ADAPTENV_ASSETS`` environment
variable (files separated by ``os.pathsep``; worker processes inherit it). :func:`object_role`
and :func:`is_movable` decide, for every consumer, whether an object is floor furniture, wall
decor, structure or a small object resting on something.

A user asset table is a JSON object ``{"assets": {ASSET_ID: {"type": T, "size": [x, y, z],
"footprint": [[x, z], ...]}}}``: the ProcTHOR object type, the full bounding box (m, local axes,
z = depth/front) and, optionally, the floor outline in local (x, z) about the box centre for
objects that are not boxes. ``objectType`` and ``boundingBox: {x, y, z}`` (ProcTHOR's own keys)
are accepted too.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from adaptenv.configfile import parse_config, printable, read_json
from adaptenv.errors import ConfigError
from adaptenv.limits import ASSET_TABLE_BYTES

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
    footprint: tuple[tuple[float, float], ...] | None = None
    """Floor outline (local x, z about the box centre) of an asset that is not a box; None for a box."""


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
            raise KeyError(f"unknown assetId {asset_id!r} (not in the ProcTHOR catalog nor in an --assets table; "
                           f"{TABLE_HINT})") from None

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


#: Environment variable listing user asset tables (``os.pathsep``-separated) that extend the catalog.
ASSETS_ENV = "ADAPTENV_ASSETS"
#: Environment variable that, set to 1, makes house loading leave out child objects of unknown assets.
SKIP_UNKNOWN_ENV = "ADAPTENV_SKIP_UNKNOWN_ASSETS"
#: How to get a table for Objaverse assets, for every message about unknown asset ids.
TABLE_HINT = ("for Objaverse assets build one with `adaptenv assets from-objathor ANNOTATIONS -o TABLE` "
              "and pass --assets TABLE, or pass --skip-unknown-assets to leave out the unknown objects that "
              "rest on others")
#: Depth (m) of one arm of an L- or C-shaped counter: every straight ProcTHOR counter
#: (``Countertop_I_*``) is 0.611 m (2 ft) deep, and ``Countertop_L_4x4`` is 2 x 0.611 m square.
COUNTER_ARM_DEPTH = 0.611


def counter_footprint(asset_id: str, size: tuple[float, float, float]) -> tuple[tuple[float, float], ...] | None:
    """Local floor outline of ProcTHOR's L- and C-shaped counters (None for every other asset).

    An L (``Countertop_L_*``) is an arm along its back (local -z) plus an arm along its local +x
    side, each :data:`COUNTER_ARM_DEPTH` deep, leaving the front-left (-x, +z) square open: that is
    where no child object stands on the L counter of ``tests/data/procthor-10k-train-1.json``, and
    it faces the room when the counter's back and +x side touch the walls of a corner, as they do
    there. A C (``Countertop_C_*``) adds the mirror arm along -x and opens to its front (+z).
    """
    hx, hz = size[0] / 2.0, size[2] / 2.0
    d = min(COUNTER_ARM_DEPTH, size[0], size[2])
    if asset_id.startswith("Countertop_L_"):
        return ((-hx, -hz), (hx, -hz), (hx, hz), (hx - d, hz), (hx - d, -hz + d), (-hx, -hz + d))
    if asset_id.startswith("Countertop_C_") and size[0] > 2 * d:
        return ((-hx, -hz), (hx, -hz), (hx, hz), (hx - d, hz), (hx - d, -hz + d), (-hx + d, -hz + d),
                (-hx + d, hz), (-hx, hz))
    return None


def load_catalog(*tables: str | Path) -> AssetCatalog:
    """The shipped ProcTHOR catalog extended by the user tables in ``$ADAPTENV_ASSETS`` and ``tables``
    (cached per set of tables; the result is immutable).

    Passing ``tables`` here only builds that catalog (give it to ``load_house(..., catalog=)``,
    ``SceneGeometry.from_house``, ...); :func:`use_assets` makes every adaptenv function use them.
    """
    env = [p for p in os.environ.get(ASSETS_ENV, "").split(os.pathsep) if p]
    return _catalog_with(tuple(env + [str(Path(t).resolve()) for t in tables]))


def use_assets(*paths: str | Path) -> AssetCatalog:
    """Extend the catalog every adaptenv function uses with user asset tables (this process and the
    worker processes it starts); returns the extended catalog. Raises ConfigError on a bad table."""
    current = [p for p in os.environ.get(ASSETS_ENV, "").split(os.pathsep) if p]
    for p in paths:
        read_asset_table(p)  # fail now, with the file named, rather than in a worker
        if str(Path(p).resolve()) not in current:
            current.append(str(Path(p).resolve()))
    os.environ[ASSETS_ENV] = os.pathsep.join(current)
    return load_catalog()


def skip_unknown_assets(on: bool = True) -> None:
    """Make house loading leave out child objects whose asset is unknown (this process and the worker
    processes it starts; the CLI's ``--skip-unknown-assets``). Unknown top-level objects stay errors."""
    if on:
        os.environ[SKIP_UNKNOWN_ENV] = "1"
    else:
        os.environ.pop(SKIP_UNKNOWN_ENV, None)


def skipping_unknown_assets() -> bool:
    """Whether :func:`skip_unknown_assets` is on (``$ADAPTENV_SKIP_UNKNOWN_ASSETS`` is 1)."""
    return os.environ.get(SKIP_UNKNOWN_ENV, "") == "1"


@lru_cache(maxsize=8)
def _catalog_with(tables: tuple[str, ...]) -> AssetCatalog:
    base = _shipped_catalog()
    extra: dict[str, AssetInfo] = {}
    for path in tables:
        extra.update(read_asset_table(path, known_types=frozenset(base.types)))
    return replace(base, assets={**base.assets, **extra}) if extra else base


TABLE_METADATA = frozenset({"assets", "source", "note"})
"""Top-level keys of an asset table; ``source`` and ``note`` are free text for the reader."""
Extent = Annotated[float, Field(gt=0, allow_inf_nan=False)]
Coordinate = Annotated[float, Field(allow_inf_nan=False)]


class BoundingBox(BaseModel):
    """ProcTHOR's ``boundingBox: {x, y, z}`` (full extents, m)."""

    model_config = ConfigDict(extra="forbid")

    x: Extent
    y: Extent
    z: Extent


class UserAsset(BaseModel):
    """One row of a user asset table as written in the file (``type``/``size`` or ProcTHOR's
    ``objectType``/``boundingBox``); checked in strict JSON mode, unknown keys refused."""

    model_config = ConfigDict(extra="forbid")

    type: str | None = None
    objectType: str | None = None
    size: tuple[Extent, Extent, Extent] | None = None
    boundingBox: BoundingBox | None = None
    footprint: list[tuple[Coordinate, Coordinate]] | None = Field(None, min_length=3)
    """Floor outline, local (x, z) about the box centre; at least 3 points."""
    primary: str | None = None
    split: Literal["train", "val", "test"] | None = None
    from_: str | None = Field(None, alias="from")
    """Provenance only (which annotation field gave the type); not read."""
    note: str | None = None
    """Free text for the reader; not read."""


def read_asset_table(path: str | Path, known_types: frozenset[str] | None = None) -> dict[str, AssetInfo]:
    """Parse a user asset table (see the module docstring); ConfigError names the file, asset and field."""
    p = Path(path)
    doc = read_json(p, "asset table (see docs/scene.md)", source=f"--assets {p}", limit=ASSET_TABLE_BYTES)
    table = doc.get("assets", doc) if isinstance(doc, dict) else None
    if not isinstance(table, dict) or not table:
        raise ConfigError(f"--assets {p}: expected a JSON object {{\"assets\": {{ASSET_ID: {{\"type\": ..., "
                          '"size": [x, y, z]}}} with at least one asset')
    if "assets" in doc:
        other = next((k for k in doc if k not in TABLE_METADATA), None)
        if other is not None:
            raise ConfigError(f"--assets {p}: {printable(other)} is not a known field next to \"assets\" (allowed: "
                              f"{', '.join(sorted(TABLE_METADATA))}); remove it")
    known = known_types if known_types is not None else frozenset(_shipped_catalog().types)
    return {aid: _user_asset(p, aid, entry, known) for aid, entry in table.items()}


def _user_asset(path: Path, asset_id: str, entry: Any, known: frozenset[str]) -> AssetInfo:
    """One row of a user asset table as an AssetInfo."""
    where = f"--assets {path}: asset {asset_id!r}"
    row = parse_config(UserAsset, entry, where, fix="fix that value (the table format is in docs/scene.md)")
    object_type = row.type or row.objectType
    if object_type not in known:
        raise ConfigError(f"{where} has type {object_type!r}, not a ProcTHOR object type (the type decides its "
                          f"semantic class); use one of the catalog's types, e.g. Sofa, Chair, Bed, Fridge")
    box = row.boundingBox
    size = row.size or ((box.x, box.y, box.z) if box is not None else None)
    if size is None:
        raise ConfigError(f"{where} needs \"size\": [x, y, z], three positive extents in meters")
    outline = tuple(row.footprint) if row.footprint is not None else None
    return AssetInfo(asset_id, object_type, size, row.primary, (), row.split, None, outline)


@lru_cache(maxsize=1)
def _shipped_catalog() -> AssetCatalog:
    """The catalog shipped in the package (parsed once per process)."""
    doc = json.loads(resources.files("adaptenv.scene").joinpath("data/assets.json").read_text("utf-8"))
    assets = {
        aid: AssetInfo(aid, a["type"], tuple(a["size"]), a.get("primary"), tuple(a.get("secondary", ())),
                       a.get("split"), tuple(a["open_size"]) if a.get("open_size") else None,
                       counter_footprint(aid, tuple(a["size"])))
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


def object_label(object_id: str, object_type: str | None) -> str:
    """How a person reads an object: its id, led by its type when the id does not name it (ProcTHOR-100K's
    ``6|1|3`` is ``Chair 6|1|3``; ProcTHOR-10K's ``Chair|3|0|3`` stays as it is)."""
    head = object_id.split("|", 1)[0].lower()
    if not object_type or (head and (object_type.lower().startswith(head) or head.startswith(object_type.lower()))):
        return object_id
    return f"{object_type} {object_id}"


def object_types(objects: Iterable[Any], catalog: AssetCatalog | None = None) -> dict[str, str | None]:
    """Object id -> object type of objects with ``id`` and ``assetId`` (a house's objects, children and doors);
    None for an object of an unknown asset."""
    catalog = catalog or load_catalog()
    return {obj.id: (a.object_type if (a := catalog.assets.get(obj.assetId)) is not None else None) for obj in objects}


def object_labels(objects: Iterable[Any], catalog: AssetCatalog | None = None) -> dict[str, str]:
    """Object id -> :func:`object_label` of objects with ``id`` and ``assetId`` (see :func:`object_types`)."""
    return {oid: object_label(oid, t) for oid, t in object_types(objects, catalog).items()}


def is_movable(object_type: str, role: ObjectRole) -> bool:
    """Whether a generator may move the object: floor furniture that is not a built-in fixture."""
    return role == "floor" and object_type not in FIXTURE_TYPES
