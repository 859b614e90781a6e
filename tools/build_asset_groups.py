"""Derive adaptenv's asset-group pairs from ProcTHOR's asset groups.

Usage: python tools/build_asset_groups.py PROCTHOR_DATABASES_DIR [-o src/adaptenv/scene/data/asset_groups.json]

Reads every ``asset_groups/*.json`` (ProcTHOR, Copyright 2022 Allen Institute for AI, Apache
License 2.0) and writes, per group, which object type stands next to (or on) which: one
``{"group", "anchor", "member", "relation", "rotation"}`` entry per distinct pair, where ``anchor``
is the type the member is placed relative to, ``relation`` ProcTHOR's ``verticalAlignment``
(``nextTo`` on the floor beside it, ``above`` on it) and ``rotation`` the member's yaw relative to
the anchor in degrees. The output is a changed (reduced) form of that data and carries the
attribution below.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

ATTRIBUTION = (
    "Derived from the ProcTHOR asset groups (allenai/procthor, procthor/databases/asset_groups/, commit 53d5bd4), "
    "Copyright 2022 Allen Institute for AI, licensed under the Apache License 2.0 "
    "(http://www.apache.org/licenses/LICENSE-2.0). Changed by adaptenv: reduced to the object types of each "
    "group, which type each member is placed relative to, the vertical alignment and the relative rotation."
)


def build(db: Path) -> dict:
    """Return the asset-group document built from the ProcTHOR database folder ``db``."""
    pairs: list[dict] = []
    for path in sorted((db / "asset_groups").glob("*.json")):
        meta = json.loads(path.read_text())["assetMetadata"]
        seen: set[tuple] = set()
        for entry in meta.values():
            parent = entry.get("parentInstanceId")
            if parent is None:
                continue
            anchor = next(iter(meta[str(parent)]["assetIds"]))
            row = {"group": path.stem, "anchor": anchor, "member": next(iter(entry["assetIds"])),
                   "relation": entry["position"]["verticalAlignment"], "rotation": float(entry.get("rotation", 0))}
            key = tuple(row.values())
            if key not in seen:
                seen.add(key)
                pairs.append(row)
    return {"attribution": ATTRIBUTION, "pairs": pairs}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("databases", type=Path, help="ProcTHOR's procthor/databases folder")
    ap.add_argument("-o", "--out", type=Path, default=Path("src/adaptenv/scene/data/asset_groups.json"))
    args = ap.parse_args()
    args.out.write_text(json.dumps(build(args.databases), indent=1) + "\n", encoding="utf-8")
    print(args.out)


if __name__ == "__main__":
    main()
