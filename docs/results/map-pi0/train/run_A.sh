#!/bin/bash
# Candidate A of docs/results/map-pi0/DECLARED.md
cd "$(dirname "$0")"  # a folder of your choice
adaptenv train --houses preset:pretrain-train --frames 2000000 --seed 0 --map --teacher map-explorer \
  --max-episode-steps 600 --precision bf16 --beta-end 0.5 --calibrate-episodes 200 --eval-every 20 --eval-episodes 96 \
  -o A.pt --run-dir A --no-progress "$@"
