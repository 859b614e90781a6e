#!/bin/bash
# Section 1 of DECLARED.md: the dr loop run with finetune_keep_learner true (validation suites for its
# per-iteration checks), then both final policies on the validation suites, 500 episodes each, seed 0.
# Usage: bash docs/results/lever-ppo3/heldin.sh OUT FRESH_POLICY
#   FRESH_POLICY: the second lever test's dr seed 0 final policy (its OUT/dr/seed_0/iter_0003/policy.pt,
#   made by docs/results/lever-ppo2/run.sh), the run with a fresh learner each iteration.
set -euo pipefail
root=$(git rev-parse --show-toplevel)
out=$(realpath -m "$1")
fresh=$(realpath "$2")
mkdir -p "$out"
cd "$out"
[ -f pi0-c.pt ] || git -C "$root" show 605ebc7:src/adaptenv/agents/data/pretrained-ppo.pt > pi0-c.pt
export NUMBA_NUM_THREADS=1
run() { PYTHONPATH="$root/src" "$root/.venv/bin/adaptenv" "$@"; }
run experiment --config "$root/configs/heldin-lever-ppo3.json" -o "$out/keep" --executor inprocess
for arm in keep fresh; do
  policy=$([ $arm = keep ] && echo "$out/keep/dr/seed_0/iter_0003/policy.pt" || echo "$fresh")
  for s in val-far val-clutter val-long; do
    [ -f "val/$arm/$s/summary.json" ] || run evaluate --policy "$policy" --houses suite:$s --episodes 500 --seed 0 \
      --workers 1 --batch 64 -o "val/$arm/$s" > /dev/null
  done
done
for arm in keep fresh; do
  python3 - "$arm" <<'PY'
import json, sys
arm = sys.argv[1]
s = {v: json.load(open(f"val/{arm}/{v}/summary.json"))["success"] for v in ("val-far", "val-clutter", "val-long")}
print(arm, s, "mean", round(sum(s.values()) / 3, 4))
PY
done
