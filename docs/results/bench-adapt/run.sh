#!/bin/bash
# bench adapt before the plausibility rules and with them, one after the other on the same machine.
# Usage, from a clone with the virtual environment of `make install-dev`:
#   bash docs/results/bench-adapt/run.sh [OLD_REV] [NEW_REV]   (defaults: 24efd42 7fae0cd)
set -euo pipefail
old=${1:-24efd42} new=${2:-7fae0cd}
root=$(git rev-parse --show-toplevel)
py=$root/.venv/bin/python
export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1
for rev in "$old" "$new"; do
  tree=$(mktemp -d)
  git -C "$root" worktree add --detach "$tree" "$rev" >/dev/null
  (cd "$tree" && PYTHONPATH=$tree/src "$py" -c "from adaptenv.cli import main; main()" bench adapt --houses 50 --steps 5 --policy pretrained --json) \
    > "bench-adapt-$rev.json"
  git -C "$root" worktree remove --force "$tree"
done
