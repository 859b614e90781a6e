#!/bin/bash
# The held-in check of DECLARED.md: the loop-budget run with the encoder frozen and bf16 PPO updates, then its
# final policy on the validation suites (500 episodes each, seed 0), paired episode by episode with docs/results/loop-budget/val.
# Usage, from a clone with the virtual environment of `make install-dev`: bash docs/results/frozen-bf16-ppo/run.sh OUT
set -euo pipefail
root=$(git rev-parse --show-toplevel)
out=$(realpath -m "$1")
mkdir -p "$out"
cd "$out"
[ -f pi0-c.pt ] || git -C "$root" show 605ebc7:src/adaptenv/agents/data/pretrained-ppo.pt > pi0-c.pt
export NUMBA_NUM_THREADS=1
run() { PYTHONPATH="$root/src" "$root/.venv/bin/adaptenv" "$@"; }
run experiment --config "$root/configs/heldin-frozen-bf16-ppo.json" -o "$out/run" --executor inprocess
for s in val-far val-clutter val-long; do
  [ -f "val/$s/summary.json" ] || run evaluate --policy "$out/run/dr/seed_0/iter_0003/policy.pt" --houses suite:$s \
    --episodes 500 --seed 0 --workers 1 --batch 64 -o "val/$s" > /dev/null
done
FULL="$root/docs/results/loop-budget/val" "$root/.venv/bin/python" - <<'PY'
import csv, os
import numpy as np
from scipy import stats
full, bf16, diffs = {}, {}, []
for s in ("val-far", "val-clutter", "val-long"):
    a = [r["success"] == "True" for r in csv.DictReader(open(f"{os.environ['FULL']}/{s}/episodes.csv"))]
    b = [r["success"] == "True" for r in csv.DictReader(open(f"val/{s}/episodes.csv"))]
    full[s], bf16[s] = np.mean(a), np.mean(b)
    diffs += [float(y) - float(x) for x, y in zip(a, b, strict=True)]
d = np.asarray(diffs)
half = stats.t.ppf(0.975, d.size - 1) * d.std(ddof=1) / np.sqrt(d.size)
print("full", {k: round(float(v), 3) for k, v in full.items()}, "mean", round(float(np.mean(list(full.values()))), 4))
print("frozen+bf16", {k: round(float(v), 3) for k, v in bf16.items()}, "mean", round(float(np.mean(list(bf16.values()))), 4))
print(f"frozen+bf16 - full, paired over {d.size} episodes: {100 * d.mean():+.1f} points [{100 * (d.mean() - half):+.1f}, "
      f"{100 * (d.mean() + half):+.1f}]")
PY
