#!/bin/bash
# The second PPO lever test of DECLARED.md, resumable: finished runs are skipped.
# Its pi_0 is candidate c, shipped as pretrained-ppo at commit 605ebc7 (the first PPO lever test's pi_0);
# this script takes that checkpoint from git into OUT. The test ran at commit 3bce57a, before the loop's PPO
# fine-tuning kept its learner across iterations, so the script runs it from a checkout of that commit.
# Usage, from a clone with the virtual environment of `make install-dev`: bash docs/results/lever-ppo2/run.sh [OUT]
set -euo pipefail
root=$(git rev-parse --show-toplevel)
out=$(realpath -m "${1:-runs/lever-ppo2}")
tree="${TMPDIR:-/tmp}/adaptenv-lever-ppo2-3bce57a"
[ -d "$tree" ] || git -C "$root" worktree add --detach "$tree" 3bce57a >/dev/null
mkdir -p "$out"
cd "$out"
[ -f pi0-c.pt ] || git -C "$root" show 605ebc7:src/adaptenv/agents/data/pretrained-ppo.pt > pi0-c.pt
export NUMBA_NUM_THREADS=1
PYTHONPATH="$tree/src" "$root/.venv/bin/adaptenv" experiment --config "$tree/configs/experiment-lever-ppo2.json" -o "$out" \
  --final-episodes 1000 --executor process --workers 2
