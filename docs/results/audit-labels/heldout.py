"""The learned audit's agreement on labels its tolerances were not chosen on.

Usage: PYTHONPATH=src python docs/results/audit-labels/heldout.py [moves.jsonl]

The placement model's tolerances (``TOLERANCE`` in :mod:`adaptenv.adapt.placement_model`) were set while looking at
all 72 labelled moves, so the agreement the README reports is measured on the set they were tuned on. This script
declares a split before looking at its result and never changes the shipped tolerances:

- every move's hand-written rules are audited once (the placement model given no range, so ``unlike_reference``
  refuses nothing), and the moved object's placement-model features before and after are read once;
- one number, a factor ``s`` on every tolerance, is chosen on the *choice* half (fewest false accepts, then fewest
  false refusals, then the factor nearest 1) from FACTORS;
- the agreement on the other, *held-out* half is reported for that factor and for the shipped tolerances (s = 1).

Two splits: ``first/second`` (moves m000-m035 choose, m036-m071 are held out: the first half holds the random moves
of the real house and of procedural house 11, the second those of procedural house 12 and the built-in G's edits),
and ``even/odd`` (even ids choose, odd ids are held out: every source on both sides).
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

from adaptenv.adapt.edits import Edit, apply_edit
from adaptenv.adapt.placement_model import (
    FEATURES,
    TAILS,
    TOLERANCE,
    HouseLayout,
    PlacementModel,
    default_model,
    object_features,
    placement_class,
)
from adaptenv.adapt.plausibility import audit
from adaptenv.scene.assets import load_catalog
from adaptenv.scene.geometry import SceneGeometry
from adaptenv.scene.house import House, load_house
from adaptenv.scene.procedural import GenerationConfig, generate_house

ROOT = Path(__file__).resolve().parents[3]
LABELS = Path(__file__).resolve().parent / "moves.jsonl"
#: The tolerance factors the choice half may pick from (declared before any split was looked at).
FACTORS = (0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0)


def _house(source: str, cache: dict[str, House]) -> House:
    if source not in cache:
        if source.startswith("procedural:"):
            _, seed, rooms = source.split(":")
            cache[source] = generate_house(int(seed), GenerationConfig(n_rooms=int(rooms)))
        else:
            cache[source] = load_house(ROOT / source, validate=False)
    return cache[source]


def _reads(row: dict, cache: dict[str, House]) -> dict:
    """The hand-written rules' verdict and the learned features (value, before, range) of one labelled move."""
    catalog, model = load_catalog(), default_model()
    house, m = _house(row["house"], cache), row["move"]
    moved = apply_edit(house, Edit(object_id=row["object"], achieved_dx=m["dx"], achieved_dz=m["dz"],
                                   yaw_before=m["yaw_before"], yaw_after=m["yaw_after"]))
    hand = [v.rule for v in audit(house, moved, catalog=catalog, model=PlacementModel({})).violations]
    reads = []
    for h in (house, moved):
        g = SceneGeometry.from_house(h, catalog)
        floor = {f.object_id: f for f in g.floor_objects}
        reads.append(object_features(HouseLayout.of(g), floor[row["object"]], floor))
    before, now = reads
    ranges = {}
    for f in FEATURES:
        r = model.range(row["type"], placement_class(catalog, row["type"]), f)
        if r is not None and math.isfinite(now[f]):
            ranges[f] = (now[f], before[f], r.low, r.high)
    return {"id": row["id"], "label": row["label"], "hand": hand, "learned": ranges}


def refused(read: dict, s: float) -> bool:
    """The audit's verdict on one move with every tolerance times ``s`` (as ``placement_model.unlike`` reads it)."""
    if read["hand"]:
        return True
    for f, (x, b, low, high) in read["learned"].items():
        tol = TOLERANCE[f] * s
        if TAILS[f] == "high" and x > high + tol and (not math.isfinite(b) or x > b + tol):
            return True
        if TAILS[f] == "low" and x < low - tol and (not math.isfinite(b) or x < b - tol):
            return True
    return False


def agreement(reads: list[dict], s: float) -> tuple[int, int, int, int]:
    """(false accepts, implausible moves, false refusals, plausible moves) at factor ``s``."""
    bad = [r for r in reads if r["label"] == "implausible"]
    good = [r for r in reads if r["label"] == "plausible"]
    return (sum(not refused(r, s) for r in bad), len(bad), sum(refused(r, s) for r in good), len(good))


def choose(reads: list[dict]) -> float:
    """The factor with the fewest false accepts, then false refusals, then nearest 1."""
    return min(FACTORS, key=lambda s: (agreement(reads, s)[0], agreement(reads, s)[2], abs(math.log(s))))


def main() -> None:
    path = Path(sys.argv[1]) if len(sys.argv) > 1 else LABELS
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    cache: dict[str, House] = {}
    reads = [_reads(r, cache) for r in rows]
    fa, nb, fr, ng = agreement(reads, 1.0)
    print(f"all {len(reads)} moves, shipped tolerances: {fa} of {nb} implausible accepted, {fr} of {ng} plausible "
          "refused")
    half = len(reads) // 2
    splits = {"first/second": (reads[:half], reads[half:]), "even/odd": (reads[0::2], reads[1::2])}
    for name, (pick, held) in splits.items():
        s = choose(pick)
        for what, part in (("choice", pick), ("held-out", held)):
            for label, f in ((f"chosen s={s:g}", s), ("shipped s=1", 1.0)):
                fa, nb, fr, ng = agreement(part, f)
                print(f"{name} {what} ({len(part)} moves), {label}: {fa} of {nb} implausible accepted, "
                      f"{fr} of {ng} plausible refused")


if __name__ == "__main__":
    main()
