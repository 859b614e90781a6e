#!/bin/bash
# Seed 0 of the declared closed-loop experiment (docs/results/closed-loop/) with every speed-up the project has:
# the encoder frozen and bf16 PPO updates (each checked on held-in data, docs/RESULTS.md) and evaluation jobs of
# 1,000 episodes on 100 slots. A timing: how long a run takes, not a result (its success figures are not read).
# Usage, from a clone with the virtual environment of `make install-dev`: bash docs/results/closed-loop-fast/run.sh [OUT]
set -euo pipefail
root=$(git rev-parse --show-toplevel)
out=$(realpath -m "${1:-runs/closed-loop-fast}")
mkdir -p "$out"
cd "$out"
export NUMBA_NUM_THREADS=1
export MALLOC_TOP_PAD_=268435456 MALLOC_MMAP_THRESHOLD_=33554432 MALLOC_TRIM_THRESHOLD_=2147483647
PYTHONPATH="$root/src" "$root/.venv/bin/adaptenv" experiment --config "$root/docs/results/closed-loop-fast/config.json" \
  -o "$out" --final-episodes 1000 --executor process --workers 2
