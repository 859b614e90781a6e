#!/bin/bash
# The second PPO lever test of DECLARED.md, resumable: finished runs are skipped.
# Its pi_0 is candidate c, shipped as pretrained-ppo at commit 605ebc7 (the first PPO lever test's pi_0);
# this script takes that checkpoint from git into OUT and runs the experiment with the current code.
# Usage, from a clone with the virtual environment of `make install-dev`: bash docs/results/lever-ppo2/run.sh [OUT]
set -euo pipefail
root=$(git rev-parse --show-toplevel)
out=$(realpath -m "${1:-runs/lever-ppo2}")
mkdir -p "$out"
cd "$out"
[ -f pi0-c.pt ] || git -C "$root" show 605ebc7:src/adaptenv/agents/data/pretrained-ppo.pt > pi0-c.pt
export NUMBA_NUM_THREADS=1
PYTHONPATH="$root/src" "$root/.venv/bin/adaptenv" experiment --config "$root/configs/experiment-lever-ppo2.json" -o "$out" \
  --final-episodes 1000 --executor process --workers 2
