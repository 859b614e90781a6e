"""The ``--assets`` table for houses of Objaverse assets, built from objathor's annotation file.

objathor (github.com/allenai/objathor) publishes one annotation file per asset-set version:
``python -m objathor.dataset.download_annotations --version 2023_07_28`` saves it as
``~/.objathor-assets/2023_07_28/annotations.json.gz`` (the version SPOC's ProcTHOR-Objaverse houses
use). It is a JSON object keyed by asset uid (the houses' ``assetId``); the fields read here:

- ``thor_metadata.assetMetadata.boundingBox``: the box of the asset as AI2-THOR loads it,
  ``{"min": {x, y, z}, "max": {x, y, z}}`` in meters (``{x, y, z}`` extents are accepted too). This
  is the size; without it the annotator's ``width``/``depth``/``height`` (cm, x/z/y) or ``size``
  ([width, depth, height] cm) are used.
- the type, from the first of ``ref_category``, ``most_specific_lemma`` (the synset's most specific
  word: ``flowerpot`` tells more than a synset ``pot.n.NN``), ``synset`` (WordNet, e.g.
  ``straight_chair.n.01``; its sense number is not used) and ``category`` (free text, e.g.
  ``eames chair``) that names a catalog type (:func:`type_for_name`). Assets none of them maps are typed :data:`FALLBACK_TYPE` with a note,
  or left out.
- ``split`` (train/val/test), kept so that procedural houses of one split draw only its assets.

A single asset's annotation (objathor's per-asset ``annotations.json.gz``, one object with ``uid``)
is read as a file of one asset.
"""

from __future__ import annotations

import json
import math
import re
import zlib
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal

from adaptenv.errors import ConfigError
from adaptenv.files import FileRefused, atomic_write_text, gunzip, loads_json, read_bytes
from adaptenv.limits import ANNOTATIONS_BYTES
from adaptenv.scene.assets import load_catalog

#: Catalog type of an asset whose annotation names no catalog type: a generic floor decoration,
#: which no task targets; the scan sees it as an obstacle of that class.
FALLBACK_TYPE = "RoomDecor"
#: The largest extent (m) of a usable asset size: no asset is larger than a house.
MAX_SIZE = 100.0
#: Annotation fields that may name the type, in the order they are tried.
TYPE_FIELDS = ("ref_category", "most_specific_lemma", "synset", "category")

#: Names (lower case, words separated by spaces) of catalog types that are not the type's own name.
ALIASES: dict[str, str] = {
    **dict.fromkeys(("couch", "settee", "loveseat", "love seat", "sofa bed", "sectional"), "Sofa"),
    **dict.fromkeys(("easy chair", "recliner", "club chair", "wing chair", "lounge chair"), "ArmChair"),
    **dict.fromkeys(("straight chair", "side chair", "dining chair", "office chair", "swivel chair"), "Chair"),
    **dict.fromkeys(("refrigerator", "icebox"), "Fridge"),
    **dict.fromkeys(("ashcan", "trash can", "trash bin", "wastebin", "wastebasket", "waste basket", "dustbin",
                     "bin"), "GarbageCan"),
    **dict.fromkeys(("plant", "potted plant", "pot plant", "flowerpot", "flower pot", "planter", "bonsai"),
                    "HousePlant"),
    **dict.fromkeys(("tv", "tv set", "television receiver", "television set"), "Television"),
    **dict.fromkeys(("tv stand", "television stand", "tv cabinet", "media console", "entertainment center"),
                    "TVStand"),
    **dict.fromkeys(("toilet bowl", "commode", "flush toilet", "water closet"), "Toilet"),
    **dict.fromkeys(("washbasin", "wash basin", "basin", "lavatory"), "Sink"),
    **dict.fromkeys(("counter", "kitchen counter", "kitchen island"), "CounterTop"),
    **dict.fromkeys(("table", "dinner table", "kitchen table"), "DiningTable"),
    **dict.fromkeys(("nightstand", "night table", "bedside table", "end table"), "SideTable"),
    **dict.fromkeys(("chest of drawers", "bureau", "wardrobe", "armoire", "cabinet", "cupboard", "sideboard"),
                    "Dresser"),
    **dict.fromkeys(("shelf", "shelves", "bookshelf", "bookcase"), "ShelvingUnit"),
    **dict.fromkeys(("microwave oven",), "Microwave"),
    **dict.fromkeys(("washer", "automatic washer"), "WashingMachine"),
    **dict.fromkeys(("dryer", "tumble dryer"), "ClothesDryer"),
    **dict.fromkeys(("lamp", "standard lamp"), "FloorLamp"),
    **dict.fromkeys(("table lamp",), "DeskLamp"),
    **dict.fromkeys(("bar stool",), "Stool"),
    **dict.fromkeys(("pouf", "pouffe", "hassock"), "Ottoman"),
    **dict.fromkeys(("footrest",), "Footstool"),
    **dict.fromkeys(("hamper", "laundry basket", "clothes hamper"), "LaundryHamper"),
    **dict.fromkeys(("picture", "poster", "picture frame", "wall art"), "Painting"),
    **dict.fromkeys(("sculpture", "figurine"), "Statue"),
    **dict.fromkeys(("vacuum",), "VacuumCleaner"),
    **dict.fromkeys(("coffee maker", "espresso maker"), "CoffeeMachine"),
    **dict.fromkeys(("teddy",), "TeddyBear"),
}

Unmapped = Literal["keep", "skip"]


@dataclass
class ObjathorTable:
    """The asset table built from an annotation file, and what became of each annotation."""

    assets: dict[str, dict[str, Any]]
    """Asset uid -> table row (``type``, ``size``, optional ``split``, ``from``/``note``)."""
    mapped_by: dict[str, int] = field(default_factory=dict)
    """How many assets each annotation field typed."""
    unmapped: list[str] = field(default_factory=list)
    """Uids no field maps to a catalog type (typed FALLBACK_TYPE, or left out with ``unmapped="skip"``)."""
    no_size: list[str] = field(default_factory=list)
    """Uids left out because the annotation gives no usable size."""

    def to_json(self, source: str) -> dict[str, Any]:
        """The table document ``--assets`` reads (extra keys say where it came from)."""
        return {"source": source, "note": f"assets no annotation field maps to a catalog type are typed "
                                          f"{FALLBACK_TYPE}", "assets": self.assets}


def _words(name: str) -> list[str]:
    """Lower-case words of a type, synset or free-text name ("straight_chair.n.01" -> straight, chair)."""
    m = re.fullmatch(r"([\w\-]+)\.[a-z]\.\d+", name.strip())
    if m:
        name = m.group(1)
    name = re.sub(r"(?<=[a-z])(?=[A-Z])", " ", name)  # CamelCase -> Camel Case
    return re.findall(r"[a-z0-9]+", name.lower())


@lru_cache(maxsize=4)
def _by_key(types: frozenset[str]) -> dict[str, str]:
    """Catalog types by their lower-case name without spaces ("diningtable" -> DiningTable)."""
    return {t.lower(): t for t in types}


def type_for_name(name: str, types: frozenset[str] | None = None) -> str | None:
    """The catalog type ``name`` denotes, or None.

    ``name`` may be a type ("DiningTable", or "ObjaDiningTable" as Objaverse houses' object ids
    spell it), a WordNet synset ("ashcan.n.01") or words ("dining table", "eames chair"): the
    longest tail of its words that is a type's name or an :data:`ALIASES` entry wins (a plural
    "s" dropped as a last try).
    """
    types = types if types is not None else frozenset(load_catalog().types)
    name = name.strip()
    if name in types:
        return name
    by_key = _by_key(types)
    words = _words(name)
    for i in range(len(words)):
        phrase = " ".join(words[i:])
        for candidate in (phrase, phrase[:-1] if phrase.endswith("s") else ""):
            t = ALIASES.get(candidate) or by_key.get(candidate.replace(" ", ""))
            if candidate and t in types:
                return t
    return None


def annotation_type(entry: dict[str, Any], types: frozenset[str]) -> tuple[str, str] | None:
    """(catalog type, the field that named it) of one annotation, or None when no field maps."""
    for key in TYPE_FIELDS:
        value = entry.get(key)
        if isinstance(value, str) and value.strip() and (t := type_for_name(value, types)) is not None:
            return t, key
    return None


def annotation_size(entry: dict[str, Any]) -> tuple[float, float, float] | None:
    """Full extents (x, y, z) in meters: AI2-THOR's bounding box, else the annotator's cm estimate."""
    box = _field(_field(_field(entry, "thor_metadata"), "assetMetadata"), "boundingBox")
    size: Any = None
    try:
        if isinstance(box, dict) and isinstance(box.get("min"), dict) and isinstance(box.get("max"), dict):
            size = [float(box["max"][k]) - float(box["min"][k]) for k in "xyz"]
        elif isinstance(box, dict):
            size = [float(box[k]) for k in "xyz"]
        elif all(isinstance(entry.get(k), (int, float)) and not isinstance(entry.get(k), bool)
                 for k in ("width", "height", "depth")):
            size = [entry["width"] / 100, entry["height"] / 100, entry["depth"] / 100]
        elif isinstance(entry.get("size"), list) and len(entry["size"]) == 3:
            w, d, h = (float(v) for v in entry["size"])
            size = [w / 100, h / 100, d / 100]
    except (KeyError, TypeError, ValueError):
        return None
    if size is None or not all(math.isfinite(v) and 0 < v <= MAX_SIZE for v in size):
        return None  # NaN, Infinity, nothing or more than a house
    rounded = (round(size[0], 4), round(size[1], 4), round(size[2], 4))
    return rounded if all(v > 0 for v in rounded) else None  # under 0.05 mm: no size a table may hold


def _field(node: Any, key: str) -> Any:
    """``node[key]`` when ``node`` is a JSON object, else None (a file of another shape has no such field)."""
    return node.get(key) if isinstance(node, dict) else None


def read_annotations(path: str | Path) -> dict[str, dict[str, Any]]:
    """Annotations keyed by uid from an objathor ``annotations.json(.gz)``; ConfigError names the file."""
    p = Path(path)
    fix = ("pass objathor's annotations.json.gz (python -m objathor.dataset.download_annotations "
           "--version 2023_07_28), see docs/scene.md")
    try:
        raw = read_bytes(p, ANNOTATIONS_BYTES, "annotation file")
        doc = loads_json((gunzip(raw, ANNOTATIONS_BYTES, "annotation file", p) if raw[:2] == b"\x1f\x8b"
                          else raw).decode("utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{p}: no such annotation file; {fix}") from None
    except FileRefused:
        raise
    except (OSError, EOFError, zlib.error, UnicodeDecodeError, ValueError) as exc:  # ValueError: bad or deep JSON
        raise ConfigError(f"{p}: cannot read it as JSON or gzipped JSON ({exc}); {fix}") from None
    if isinstance(doc, dict) and isinstance(doc.get("uid"), str) and not isinstance(doc.get(doc["uid"]), dict):
        doc = {doc["uid"]: doc}  # one asset's own annotation file
    entries = {str(k): v for k, v in doc.items() if isinstance(v, dict)} if isinstance(doc, dict) else {}
    if not any(_looks_like_annotation(v) for v in entries.values()):
        raise ConfigError(f"{p}: not an objathor annotation file (expected a JSON object keyed by asset uid whose "
                          f"entries have thor_metadata.assetMetadata.boundingBox and category or synset); {fix}")
    return entries


def _looks_like_annotation(entry: dict[str, Any]) -> bool:
    return "thor_metadata" in entry or any(k in entry for k in ("synset", "category", "ref_category"))


def table_from_annotations(annotations: dict[str, dict[str, Any]], *, unmapped: Unmapped = "keep") -> ObjathorTable:
    """The ``--assets`` table rows of objathor annotations (see the module docstring)."""
    types = frozenset(load_catalog().types)
    table = ObjathorTable({})
    for uid, entry in sorted(annotations.items()):
        size = annotation_size(entry)
        if size is None:
            table.no_size.append(uid)
            continue
        typed = annotation_type(entry, types)
        row: dict[str, Any] = {"type": typed[0] if typed else FALLBACK_TYPE, "size": list(size)}
        if entry.get("split") in ("train", "val", "test"):
            row["split"] = entry["split"]
        if typed is not None:
            table.mapped_by[typed[1]] = table.mapped_by.get(typed[1], 0) + 1
            row["from"] = f"{typed[1]} {entry[typed[1]]!r}"
        else:
            table.unmapped.append(uid)
            if unmapped == "skip":
                continue
            named = ", ".join(f"{k} {entry[k]!r}" for k in TYPE_FIELDS if isinstance(entry.get(k), str)) or "no name"
            row["note"] = f"no catalog type for {named}: typed {FALLBACK_TYPE}, a generic obstacle; edit it if it is wrong"
        table.assets[uid] = row
    return table


def objathor_table(path: str | Path, out: str | Path, *, unmapped: Unmapped = "keep") -> ObjathorTable:
    """Read objathor annotations at ``path`` and write the ``--assets`` table to ``out``."""
    table = table_from_annotations(read_annotations(path), unmapped=unmapped)
    if not table.assets:
        raise ConfigError(f"{path}: no annotation has both a usable size and a catalog type; nothing to write "
                          "(pass --unmapped keep to keep untyped assets)")
    o = Path(out)
    atomic_write_text(o, json.dumps(table.to_json(Path(path).name), indent=1))
    return table
