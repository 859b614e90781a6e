#!/usr/bin/env bash
# `adaptenv bench edits --json` alternated between two checkouts of adaptenv, nothing else running:
#   bash docs/results/bench-edits/alternate.sh OLD_SRC NEW_SRC [PAIRS]
# OLD_SRC and NEW_SRC are the src/ folders of two worktrees (git worktree add DIR COMMIT); each line printed is
# "old|new, validated edits/s, validated edits per CPU s", then the medians.
set -euo pipefail
old=$1 new=$2 pairs=${3:-9}
py=${PYTHON:-python}
out=$(mktemp)
for _ in $(seq "$pairs"); do
  for v in old new; do
    src=$([ "$v" = old ] && echo "$old" || echo "$new")
    PYTHONPATH=$src NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 "$py" -c "
import sys, adaptenv
assert adaptenv.__file__.startswith('$src'), adaptenv.__file__
from adaptenv.cli import app
sys.argv = ['adaptenv', 'bench', 'edits', '--json']
app()" | "$py" -c "import json, sys; d = json.load(sys.stdin); print('$v', round(d['validated edits per s']), round(d['validated edits per CPU s']))" | tee -a "$out"
  done
done
"$py" -c "
import statistics
rows = [line.split() for line in open('$out')]
for v in ('old', 'new'):
    print(v, 'median', statistics.median(int(r[1]) for r in rows if r[0] == v), 'edits/s')"
