"""The edit log of bench edits' 2,000 random proposals on each of the houses of seeds 0 to 3, as JSON, to compare two
versions of placement and validation:

    python docs/results/bench-edits/edit_log.py OUT.json   # prints the edits and how many were accepted; `cmp` two outputs
"""

import json
import sys
from pathlib import Path

import numpy as np

from adaptenv.adapt.validation import EditValidator
from adaptenv.bench import adapt_edits

out = []
for seed in (0, 1, 2, 3):
    house = adapt_edits.bench_house(seed)
    v = EditValidator(house)
    ids = [oid for oid, m in zip(v.ctx.ids, v.ctx.movable, strict=True) if m]
    for oid, dx, dy, yaw in adapt_edits.proposals(ids, 2000, np.random.default_rng(seed)):
        v.try_edit(oid, dx, dy, yaw, source="random")
    out += [e.model_dump(mode="json") for e in v.log]
Path(sys.argv[1]).write_text(json.dumps(out), encoding="utf-8")
print(len(out), sum(e["accepted"] for e in out))
