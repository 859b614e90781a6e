#!/bin/bash
# The lever test of DECLARED.md, resumable: finished runs are skipped.
adaptenv experiment --config configs/experiment-lever.json -o "${1:-runs/lever}" --final-episodes 1000 \
  --executor process --workers 2
