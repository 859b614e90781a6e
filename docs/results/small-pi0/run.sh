#!/bin/bash
# Train one smaller map-reading pi_0 by the shipped pretrained-ppo's recipe (its card's four stages: map-explorer
# DAgger, then three anchored-PPO stages), then score it on the validation suites (docs/results/small-pi0/DECLARED.md).
# Resumable: a finished stage is skipped.
# Usage, from a clone with the virtual environment of `make install-dev`:
#   bash docs/results/small-pi0/run.sh OUT NAME HIDDEN FEATURES CONV MAP [DAGGER_FRAMES]   # default 2000000
set -euo pipefail
root=$(git rev-parse --show-toplevel)
out=$(realpath -m "$1")/$2
shift 2
mkdir -p "$out"
cd "$out"
export NUMBA_NUM_THREADS=1
run() { PYTHONPATH="$root/src" "$root/.venv/bin/adaptenv" "$@"; }
houses() { [ -d "../houses$1" ] || run houses generate -o "../houses$1" --n 200 --seed "$1" > /dev/null; }
houses 7000
houses 7001
ppo=(--frames 1000000 --explore-bonus 0.002 --max-episode-steps 600 --eval-episodes 200 --threads 1 --no-progress)
[ -f A.pt ] || run train --houses preset:pretrain-train --frames "${5:-2000000}" --seed 0 --beta-end 0.5 \
  --max-episode-steps 600 --map --teacher map-explorer --precision bf16 --threads 1 --no-progress \
  --hidden "$1" --feature-dim "$2" --conv-channels "$3" --map-dim "$4" -o A.pt --run-dir A
[ -f a.pt ] || run ppo --houses preset:pretrain-train --init A.pt -o a.pt --run-dir a --seed 0 --kl-coef 0.3 \
  --eval-every 12 --min-start-distance 4.0 "${ppo[@]}"
[ -f c.pt ] || run ppo --houses ../houses7000 --init a.pt -o c.pt --run-dir c --seed 1 --kl-coef 0.1 \
  --eval-every 24 --min-start-distance 6.0 "${ppo[@]}"
[ -f f.pt ] || run ppo --houses ../houses7001 --init c.pt -o f.pt --run-dir f --seed 2 --kl-coef 0.03 \
  --eval-every 24 --min-start-distance 6.0 "${ppo[@]}"
for s in val-long val-far val-clutter; do
  [ -f "val/$s/summary.json" ] || run evaluate --policy f.pt --houses suite:$s --episodes 500 --seed 0 --workers 1 \
    --batch 100 -o "val/$s" > /dev/null
done
