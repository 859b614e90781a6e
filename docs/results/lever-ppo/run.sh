#!/bin/bash
# The lever test of DECLARED.md with anchored PPO, resumable: finished runs are skipped.
adaptenv experiment --config configs/experiment-lever-ppo.json -o "${1:-runs/lever-ppo}" --final-episodes 1000 \
  --executor process --workers 2
