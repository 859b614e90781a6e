"""Whether a comparison's rows repeat an earlier one's, the seconds aside (a faster commit must make the same edits):

    python docs/results/learned-g/repeat.py NEW_ROWS OLD_ROWS [--generators learned,builtin]

For each G it prints how many of its (job, G) rows in NEW_ROWS equal the row in OLD_ROWS field for field, without
``seconds``, and names every field that differs.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def rows(path: Path) -> dict[tuple[str, str], dict]:
    """(job, G) -> row without its ``seconds``."""
    out = {}
    for r in map(json.loads, path.open()):
        r.pop("seconds", None)
        out[(r["job"], r.get("generator", ""))] = r
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("new", type=Path)
    ap.add_argument("old", type=Path)
    ap.add_argument("--generators", default="learned,builtin")
    a = ap.parse_args()
    new, old = rows(a.new), rows(a.old)
    for g in a.generators.split(","):
        keys = sorted(k for k in new if k[1] == g)
        same = [k for k in keys if new[k] == old.get(k)]
        print(f"{g}: {len(same)} of {len(keys)} rows repeat the earlier rows exactly (seconds aside)")
        for k in keys:
            if k not in old:
                print(f"  {k[0]}: no earlier row")
            elif new[k] != old[k]:
                print(f"  {k[0]}: differs in " + ", ".join(f for f in new[k] if new[k][f] != old[k].get(f)))
