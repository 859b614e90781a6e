#!/bin/bash
# Held-in selection evaluations of docs/results/map-pi0/DECLARED.md: 500 episodes per validation suite, seed 0.
cd "$(dirname "$0")"  # a folder of your choice
for cand in "$@"; do
  pol=$cand; [ "$cand" != pretrained ] && pol=$cand.pt
  for s in val-long val-far val-clutter; do
    [ -f val/$cand/$s/summary.json ] && continue
    adaptenv evaluate --policy $pol --houses suite:$s -n 500 --seed 0 --workers 2 -o val/$cand/$s > val/$cand-$s.log 2>&1 || mkdir -p val
  done
done
