#!/bin/bash
# The lever test of DECLARED.md with anchored PPO, resumable: finished runs are skipped.
# Its pi_0 is the round-1 pretrained-ppo (candidate c), shipped at commit 605ebc7; later commits ship
# another checkpoint under that name, so the experiment runs from a checkout of 605ebc7.
# Usage, from a clone with the virtual environment of `make install-dev`: bash docs/results/lever-ppo/run.sh [OUT]
set -euo pipefail
root=$(git rev-parse --show-toplevel)
out=$(realpath -m "${1:-runs/lever-ppo}")
tree="${TMPDIR:-/tmp}/adaptenv-lever-ppo-605ebc7"
[ -d "$tree" ] || git -C "$root" worktree add --detach "$tree" 605ebc7 >/dev/null
cd "$tree"
PYTHONPATH="$tree/src" "$root/.venv/bin/python" -c "from adaptenv.cli import main; main()" experiment \
  --config configs/experiment-lever-ppo.json -o "$out" --final-episodes 1000 --executor process --workers 2
