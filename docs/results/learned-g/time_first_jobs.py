"""Seconds per accepted edit of the learned and the built-in G, one after the other on the first N held-out jobs of
``compare.py`` in one process (the rows' own timing; nothing else should run):

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 python docs/results/learned-g/time_first_jobs.py 8
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import compare  # noqa: E402

from adaptenv.agents.network import configure_torch  # noqa: E402

configure_torch()
names = [n for n, _ in compare.jobs("heldout")][:int(sys.argv[1])]
compare.one_job((0, names[0], "pretrained", ("learned",), None, "heldout"))  # compiles the kernels first
totals: dict[str, tuple[float, int]] = {}
for k, name in enumerate(names):
    for r in compare.one_job((k, name, "pretrained", ("learned", "builtin"), None, "heldout")):
        if r.get("solved"):
            s, e = totals.get(r["generator"], (0.0, 0))
            totals[r["generator"]] = (s + r["seconds"], e + r["edits"])
for g, (s, e) in totals.items():
    print(f"{g}: {s:.2f} s, {e} accepted edits, {s / e:.3f} s per accepted edit")
learned, builtin = (totals[g][0] / totals[g][1] for g in ("learned", "builtin"))
print(f"built-in / learned: {builtin / learned:.2f}")
