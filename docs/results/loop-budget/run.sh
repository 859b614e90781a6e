#!/bin/bash
# The held-in check of DECLARED.md: one dr loop run at 344,064 frames per iteration, then its final policy on the
# validation suites (500 episodes each, seed 0). Usage: bash docs/results/loop-budget/run.sh OUT
set -euo pipefail
root=$(git rev-parse --show-toplevel)
out=$(realpath -m "$1")
mkdir -p "$out"
cd "$out"
[ -f pi0-c.pt ] || git -C "$root" show 605ebc7:src/adaptenv/agents/data/pretrained-ppo.pt > pi0-c.pt
export NUMBA_NUM_THREADS=1
run() { PYTHONPATH="$root/src" "$root/.venv/bin/adaptenv" "$@"; }
run experiment --config "$root/configs/heldin-loop-budget.json" -o "$out/run" --executor inprocess
for s in val-far val-clutter val-long; do
  [ -f "val/$s/summary.json" ] || run evaluate --policy "$out/run/dr/seed_0/iter_0003/policy.pt" --houses suite:$s \
    --episodes 500 --seed 0 --workers 1 --batch 64 -o "val/$s" > /dev/null
done
python3 - <<'PY'
import json
s = {v: json.load(open(f"val/{v}/summary.json"))["success"] for v in ("val-far", "val-clutter", "val-long")}
print("1M-frame loop", s, "mean", round(sum(s.values()) / 3, 4))
PY
