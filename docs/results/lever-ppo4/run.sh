#!/bin/bash
# The test of DECLARED.md, resumable: finished runs are skipped. pi_0 is candidate c (pretrained-ppo as
# shipped at commit 605ebc7), taken from git into OUT; the experiment runs with this clone's source.
# Usage, from a clone with the virtual environment of `make install-dev`: bash docs/results/lever-ppo4/run.sh [OUT]
set -euo pipefail
root=$(git rev-parse --show-toplevel)
out=$(realpath -m "${1:-runs/lever-ppo4}")
mkdir -p "$out"
cd "$out"
[ -f pi0-c.pt ] || git -C "$root" show 605ebc7:src/adaptenv/agents/data/pretrained-ppo.pt > pi0-c.pt
export NUMBA_NUM_THREADS=1
PYTHONPATH="$root/src" "$root/.venv/bin/adaptenv" experiment --config "$root/configs/experiment-lever-ppo4.json" \
  -o "$out" --final-episodes 1000 --executor process --workers 2
