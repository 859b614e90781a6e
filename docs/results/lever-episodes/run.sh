#!/bin/bash
# The test of DECLARED.md, resumable: finished runs are skipped. Its configs are this folder's; the source is that
# of the checkout it is run from (the results used 46d3dd2, the fourth lever test's, so that its runs pair with
# that test's `none` and `oracle`). pi_0 is candidate c (pretrained-ppo as shipped at commit 605ebc7).
# Usage, from a checkout with the virtual environment of `make install-dev`:
#   bash PATH/TO/docs/results/lever-episodes/run.sh [OUT]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(git rev-parse --show-toplevel)
out=$(realpath -m "${1:-runs/lever-episodes}")
mkdir -p "$out"
cd "$out"
[ -f pi0-c.pt ] || git -C "$root" show 605ebc7:src/adaptenv/agents/data/pretrained-ppo.pt > pi0-c.pt
export NUMBA_NUM_THREADS=1
for arm in near far; do  # the two arms side by side, one process each, seed by seed
  PYTHONPATH="$root/src" "$root/.venv/bin/adaptenv" experiment --config "$here/experiment-$arm.json" \
    -o "$out/$arm" --final-episodes 1000 --executor process --workers 1 2> "$out/$arm.log" &
done
wait
