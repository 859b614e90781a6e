#!/bin/bash
# The test of DECLARED.md, resumable: finished runs are skipped. pi_0 is pretrained-ppo as shipped at the commit
# DECLARED.md names, taken from git into OUT; the experiment runs with this clone's source. The primary pair
# (rearrange, none) runs for every seed first, then the whole config adds dr and random (the same runs, in
# another order).
# Usage, from a clone with the virtual environment of `make install-dev`: bash docs/results/lever-rearranged/run.sh [OUT]
set -euo pipefail
root=$(git rev-parse --show-toplevel)
out=$(realpath -m "${1:-runs/lever-rearranged}")
config="$root/configs/experiment-lever-rearranged.json"
mkdir -p "$out"
cd "$out"
[ -f pi0.pt ] || git -C "$root" show c6896a8:src/adaptenv/agents/data/pretrained-ppo.pt > pi0.pt
echo "5aafbd850d91b4d2dadca0aabc1baf97de15aed46a5cae00e0bc908f2376f7fe  pi0.pt" | sha256sum --check --quiet
"$root/.venv/bin/python" -c 'import json, sys; c = json.load(open(sys.argv[1])); c["methods"] = ["rearrange", "none"]
c.pop("lever", None); json.dump(c, open("primary-pair.json", "w"), indent=1)' "$config"
export NUMBA_NUM_THREADS=1
export MALLOC_TOP_PAD_=268435456 MALLOC_MMAP_THRESHOLD_=33554432 MALLOC_TRIM_THRESHOLD_=2147483647
for c in primary-pair.json "$config"; do
  PYTHONPATH="$root/src" "$root/.venv/bin/adaptenv" experiment --config "$c" \
    -o "$out" --final-episodes 1000 --executor process --workers 2
done
