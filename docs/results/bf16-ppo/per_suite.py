"""Secondary reading of the bf16-ppo check (and of frozen-bf16-ppo's): per-suite paired differences against the fp32
full update and the frozen encoder, on the same validation episodes. Usage, from the repository root:
    python docs/results/bf16-ppo/per_suite.py [VAL]   # VAL: a check's val/ folder (default: bf16-ppo's packed one)
"""
import csv
import sys

import numpy as np
from scipy import stats

roots = {"full": "docs/results/loop-budget/val", "frozen": "docs/results/frozen-encoder/val"}
mine = sys.argv[1] if len(sys.argv) > 1 else "docs/results/bf16-ppo/val"
label = "VAL" if len(sys.argv) > 1 else "bf16"


def successes(root: str, suite: str) -> np.ndarray:
    return np.array([r["success"] == "True" for r in csv.DictReader(open(f"{root}/{suite}/episodes.csv"))], float)


for suite in ("val-far", "val-clutter", "val-long"):
    b = successes(mine, suite)
    for name, root in roots.items():
        x = b - successes(root, suite)
        half = stats.t.ppf(0.975, x.size - 1) * x.std(ddof=1) / np.sqrt(x.size)
        print(f"{suite} {label} - {name}: {100 * x.mean():+.1f} points [{100 * (x.mean() - half):+.1f}, "
              f"{100 * (x.mean() + half):+.1f}] (paired, {x.size} episodes, uncorrected)")
