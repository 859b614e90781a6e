#!/bin/bash
# Round 2 of DECLARED.md: two more anchored-PPO stages (g, h) after a candidate's stage-3 policy f.pt, then the
# validation suites. Resumable. Usage: bash docs/results/small-pi0/more.sh OUT NAME
set -euo pipefail
root=$(git rev-parse --show-toplevel)
out=$(realpath -m "$1")/$2
cd "$out"
export NUMBA_NUM_THREADS=1
run() { PYTHONPATH="$root/src" "$root/.venv/bin/adaptenv" "$@"; }
ppo=(--frames 1000000 --explore-bonus 0.002 --max-episode-steps 600 --eval-episodes 200 --threads 1 --no-progress
     --kl-coef 0.03 --eval-every 24 --min-start-distance 6.0)
for h in 7002 7003; do [ -d "../houses$h" ] || run houses generate -o "../houses$h" --n 200 --seed $h > /dev/null; done
[ -f g.pt ] || run ppo --houses ../houses7002 --init f.pt -o g.pt --run-dir g --seed 3 "${ppo[@]}"
[ -f h.pt ] || run ppo --houses ../houses7003 --init g.pt -o h.pt --run-dir h --seed 4 "${ppo[@]}"
for s in val-long val-far val-clutter; do
  [ -f "val-h/$s/summary.json" ] || run evaluate --policy h.pt --houses suite:$s --episodes 500 --seed 0 --workers 1 \
    --batch 100 -o "val-h/$s" > /dev/null
done
