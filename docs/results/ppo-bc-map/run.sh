#!/bin/bash
# The held-in check of DECLARED.md: the loop-budget run with an imitation term to the map explorer, then its
# final policy on the validation suites (500 episodes each, seed 0), paired episode by episode with
# docs/results/loop-budget/val.
# Usage, from a clone with the virtual environment of `make install-dev`: bash docs/results/ppo-bc-map/run.sh OUT
set -euo pipefail
root=$(git rev-parse --show-toplevel)
out=$(realpath -m "$1")
mkdir -p "$out"
cd "$out"
[ -f pi0-c.pt ] || git -C "$root" show 605ebc7:src/adaptenv/agents/data/pretrained-ppo.pt > pi0-c.pt
export NUMBA_NUM_THREADS=1
run() { PYTHONPATH="$root/src" "$root/.venv/bin/adaptenv" "$@"; }
run experiment --config "$root/configs/heldin-ppo-bc-map.json" -o "$out/run" --executor inprocess
for s in val-far val-clutter val-long; do
  [ -f "val/$s/summary.json" ] || run evaluate --policy "$out/run/dr/seed_0/iter_0003/policy.pt" --houses suite:$s \
    --episodes 500 --seed 0 --workers 1 --batch 64 -o "val/$s" > /dev/null
done
PLAIN="$root/docs/results/loop-budget/val" "$root/.venv/bin/python" - <<'PY'
import csv, os
import numpy as np
from scipy import stats


def paired(d):
    d = np.asarray(d, float)
    half = stats.t.ppf(0.975, d.size - 1) * d.std(ddof=1) / np.sqrt(d.size)
    return f"{100 * d.mean():+.1f} points [{100 * (d.mean() - half):+.1f}, {100 * (d.mean() + half):+.1f}]"


plain, bc, diffs = {}, {}, {}
for s in ("val-far", "val-clutter", "val-long"):
    a = [r["success"] == "True" for r in csv.DictReader(open(f"{os.environ['PLAIN']}/{s}/episodes.csv"))]
    b = [r["success"] == "True" for r in csv.DictReader(open(f"val/{s}/episodes.csv"))]
    plain[s], bc[s] = np.mean(a), np.mean(b)
    diffs[s] = [float(y) - float(x) for x, y in zip(a, b, strict=True)]
print("without", {k: round(float(v), 3) for k, v in plain.items()}, "mean", round(float(np.mean(list(plain.values()))), 4))
print("with bc", {k: round(float(v), 3) for k, v in bc.items()}, "mean", round(float(np.mean(list(bc.values()))), 4))
print(f"primary, val-far, with - without, paired over {len(diffs['val-far'])} episodes: {paired(diffs['val-far'])}")
for s in ("val-clutter", "val-long"):
    print(f"{s}, with - without: {paired(diffs[s])}")
print(f"mean of the suites, with - without, paired over {sum(map(len, diffs.values()))} episodes: "
      f"{paired(sum(diffs.values(), []))}")
PY
