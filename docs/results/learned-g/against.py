"""The fifth comparison's rows against the fourth's: what repeats, and the new scorer against the one shipped before.

    python docs/results/learned-g/against.py   # prints what DECLARED-5.md asks of the two row files
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from compare import paired_interval  # noqa: E402


def rows(name: str) -> dict[tuple[str, str], dict]:
    """(job, G) -> row of one rows file in this folder (solved jobs only)."""
    return {(r["job"], r["generator"]): r for r in map(json.loads, (HERE / name).open()) if r["solved"]}


def line(what: str, d: np.ndarray) -> str:
    lo, hi = paired_interval(d)
    return f"{what}: {100 * d.mean():+.1f} points, 95% interval [{100 * lo:+.1f}, {100 * hi:+.1f}] over {len(d)} paired runs"


if __name__ == "__main__":
    new, old = rows("rows-pretrained-objectives.jsonl"), rows("rows-pretrained-fresh.jsonl")
    jobs = sorted({j for j, _ in new})
    for g in ("builtin", "random"):
        same = all(new[j, g][k] == old[j, g][k] for j in jobs for k in ("success_after", "paired_after", "fresh_after"))
        print(f"{g}: the fourth comparison's rows repeated exactly: {same}")
    print("fresh draws before every G, the same in both:", all(new[j, "learned"]["fresh_before"] == old[j, "learned"]["fresh_before"]
                                                             for j in jobs))
    # a larger drop is a lower fresh_after (fresh_before is the same house for both)
    print(line("learned (objectives scorer) - learned (scorer shipped before) fresh drop",
               np.array([old[j, "learned"]["fresh_after"] - new[j, "learned"]["fresh_after"] for j in jobs])))
    print(line("builtin+rollouts0 - builtin fresh drop",
               np.array([new[j, "builtin"]["fresh_after"] - new[j, "builtin+rollouts0"]["fresh_after"] for j in jobs])))
