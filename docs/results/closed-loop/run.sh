#!/bin/bash
# The experiment of DECLARED.md, resumable: finished runs are skipped, runs go about seed by seed (every method of
# seed 0, then seed 1, ...). pi_0 is the shipped pretrained-ppo of this clone.
# Usage, from a clone with the virtual environment of `make install-dev`: bash docs/results/closed-loop/run.sh [OUT]
set -euo pipefail
root=$(git rev-parse --show-toplevel)
out=$(realpath -m "${1:-runs/closed-loop}")
mkdir -p "$out"
cd "$out"
export NUMBA_NUM_THREADS=1
# glibc keeps freed memory (what keep_freed_memory does from commit 4ec6c12 on; outputs unchanged): set since
# 2026-11-26 17:15 UTC, the top pad since 17:36 UTC (docs/results/closed-loop/README.md)
export MALLOC_TOP_PAD_=268435456 MALLOC_MMAP_THRESHOLD_=33554432 MALLOC_TRIM_THRESHOLD_=2147483647
PYTHONPATH="$root/src" "$root/.venv/bin/adaptenv" experiment --config "$root/configs/experiment-closed-loop.json" \
  -o "$out" --final-episodes 1000 --executor process --workers 2
