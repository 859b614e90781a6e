"""Read and write ProcTHOR house files; the typed house (:mod:`adaptenv.scene.model`) is re-exported here.

``load_house`` parses a file into a :class:`House` and runs the semantic checks of
:mod:`adaptenv.scene.validate`, which works on the model alone, so this module sits above both.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from adaptenv.errors import HouseError
from adaptenv.files import atomic_write_text
from adaptenv.scene.model import (
    AGENT_POSE_KINDS,
    MAX_ANGLE,
    MAX_COORDINATE,
    MAX_HOUSE_SIZE,
    SCHEMA_VERSION,
    AgentPose,
    House,
    HouseObject,
    Metadata,
    Opening,
    Room,
    Vec3,
    Wall,
    is_interior_leaf_door,
    is_shut,
    json_path,
    move_object,
    number_problems,
    parse_house,
    read_house_document,
    set_door_openness,
    short,
)
from adaptenv.scene.validate import validate_read_house


def load_house(path: str | Path, *, validate: bool = True, catalog: Any = None,
               skip_unknown: bool | None = None) -> House:
    """Load a ProcTHOR house JSON file.

    Args:
        path: the house file.
        validate: also run the semantic checks of :func:`adaptenv.scene.validate.validate_house`
            (wall ids, door walls, asset ids, polygons, objects inside rooms).
        catalog: the AssetCatalog to check asset ids against (default ``load_catalog()``; e.g.
            ``load_catalog("my_assets.json")`` for a house of Objaverse assets).
        skip_unknown: leave out child objects whose asset the catalog does not know (recorded in
            ``House.dropped_children``); default: the process setting (``--skip-unknown-assets``).

    Raises:
        HouseError: with one sentence per problem naming the file and JSON path.
    """
    doc = read_house_document(path)
    house = parse_house(doc, str(path))
    problems = validate_read_house(house, file=str(path), catalog=catalog, skip_unknown=skip_unknown,
                                   validate=validate)
    if problems:
        raise HouseError(problems)
    return house


def save_house(house: House, path: str | Path) -> Path:
    """Write a house as JSON (unknown keys preserved); creates parent folders. Returns the path."""
    p = Path(path)
    atomic_write_text(p, json.dumps(house.to_dict(), indent=1))
    return p


__all__ = [
    "AGENT_POSE_KINDS", "MAX_ANGLE", "MAX_COORDINATE", "MAX_HOUSE_SIZE", "SCHEMA_VERSION", "AgentPose", "House",
    "HouseObject", "Metadata", "Opening", "Room", "Vec3", "Wall", "is_interior_leaf_door", "is_shut", "json_path",
    "load_house", "move_object", "number_problems", "parse_house", "read_house_document", "save_house",
    "set_door_openness", "short",
]
