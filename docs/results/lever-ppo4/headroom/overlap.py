"""Which of seed 0's 1,000 `far` episodes pi_0, the fine-tuned `dr` policy and the map explorer fail, and where
their failures overlap (the files in far-seed0/ are `adaptenv evaluate`'s; README.md gives the commands)."""

import csv
import json
from pathlib import Path

here = Path(__file__).parent / "far-seed0"


def failures(name: str) -> tuple[dict[int, dict], set[int]]:
    rows = {int(r["index"]): r for r in csv.DictReader(open(here / name / "episodes.csv"))}
    return rows, {k for k, r in rows.items() if r["success"] != "True"}


explorer, explorer_fails = failures("explorer")
for name in ("pi0", "dr0"):
    rows, fails = failures(name)
    assert all(rows[k]["seed"] == explorer[k]["seed"] for k in rows), "the same episodes"
    modes = json.loads((here / name / "summary.json").read_text())["failure_modes"]
    timeouts = sum(int(rows[k]["steps"]) >= 600 for k in fails)
    print(f"{name}: {len(fails)} failures ({timeouts} at the 600-step limit; F's modes {modes}); the map explorer "
          f"fails {len(explorer_fails)}; both {len(fails & explorer_fails)}, only {name} {len(fails - explorer_fails)}, "
          f"only the explorer {len(explorer_fails - fails)}")
