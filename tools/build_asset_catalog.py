"""Derive adaptenv's compact asset catalog from the ProcTHOR databases.

Usage: python tools/build_asset_catalog.py PROCTHOR_DATABASES_DIR [-o src/adaptenv/scene/data/assets.json]

Reads asset-database.json, placement-annotations.json, wall-holes.json, material-database.json and
skyboxes.json (ProcTHOR, Copyright 2022 Allen Institute for AI, Apache License 2.0) and writes one
JSON file with only what adaptenv uses. The output is a changed (reduced) form of that data and
carries the attribution below.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

ATTRIBUTION = (
    "Derived from the ProcTHOR databases (allenai/procthor, procthor/databases/, commit 53d5bd4), "
    "Copyright 2022 Allen Institute for AI, licensed under the Apache License 2.0 "
    "(http://www.apache.org/licenses/LICENSE-2.0). Changed by adaptenv: reduced to asset ids, "
    "object types, bounding boxes, properties, placement annotations, wall-hole sizes and material "
    "and skybox names, and re-encoded."
)

ANNOTATION_KEYS = ("inKitchens", "inLivingRooms", "inBedrooms", "inBathrooms", "inCorner", "inMiddle",
                   "onEdge", "onFloor", "onWall", "isPickupable", "isKinematic", "multiplePerRoom")


def _r(v: float) -> float:
    return round(float(v), 4)


def build(db: Path) -> dict:
    """Return the catalog document built from the ProcTHOR database folder ``db``."""
    assets_db = json.loads((db / "asset-database.json").read_text())
    annotations = json.loads((db / "placement-annotations.json").read_text())
    holes = json.loads((db / "wall-holes.json").read_text())
    materials = json.loads((db / "material-database.json").read_text())
    skyboxes = json.loads((db / "skyboxes.json").read_text())

    assets = {}
    for object_type, entries in sorted(assets_db.items()):
        for a in entries:
            bb = a["boundingBox"]
            open_bb = None
            for state in (a.get("states") or {}).values():
                if isinstance(state, dict) and "boundingBox" in state:
                    ob = state["boundingBox"]
                    open_bb = [_r(ob["x"]), _r(ob["y"]), _r(ob["z"])]
            assets[a["assetId"]] = {
                "type": object_type,
                "size": [_r(bb["x"]), _r(bb["y"]), _r(bb["z"])],
                "primary": a.get("primaryProperty"),
                "secondary": sorted(a.get("secondaryProperties") or []),
                "split": a.get("split"),
                **({"open_size": open_bb} if open_bb else {}),
            }
    types = {}
    for object_type in sorted(assets_db):
        types[object_type] = {k: annotations[k].get(object_type) for k in ANNOTATION_KEYS if k in annotations}
    wall_holes = {
        asset_id: {"min": [_r(h["min"]["x"]), _r(h["min"]["y"])], "max": [_r(h["max"]["x"]), _r(h["max"]["y"])],
                   "offset": [_r(h["offset"]["x"]), _r(h["offset"]["y"]), _r(h["offset"]["z"])]}
        for asset_id, h in sorted(holes.items())
    }
    return {
        "attribution": ATTRIBUTION,
        "assets": assets,
        "types": types,
        "wall_holes": wall_holes,
        "materials": {k: sorted(v) for k, v in sorted(materials.items())},
        "skyboxes": sorted(skyboxes),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("databases", type=Path, help="the ProcTHOR databases folder")
    parser.add_argument("-o", "--output", type=Path,
                        default=Path(__file__).resolve().parents[1] / "src/adaptenv/scene/data/assets.json")
    args = parser.parse_args()
    doc = build(args.databases)
    args.output.write_text(json.dumps(doc, separators=(",", ":"), sort_keys=False) + "\n")
    print(f"wrote {args.output} ({len(doc['assets'])} assets, {len(doc['types'])} types)")


if __name__ == "__main__":
    main()
