"""Time the loop's G (failure-mode or regret-only) on N procedural houses, as the loop runs it, and hash what it returns.

    python tools/time_generate_jobs.py 4 [failure-modes | regret-only]

Each job diagnoses the house with the shipped policy (4 hard episodes), makes 5 edits with their
rollout checks, and diagnoses the child: :func:`adaptenv.curriculum.jobs.run_generate`; the
generator is ``ours``' (failure-modes, the default) or ``ours-nof``'s (regret-only). Run it from
two source trees (``PYTHONPATH=...``) to compare their speed; equal hashes mean equal children and
edit logs. docs/BENCHMARKS.md quotes it.
"""

from __future__ import annotations

import hashlib
import json
import sys
import time

import torch

from adaptenv.agents.registry import load_pretrained
from adaptenv.curriculum.jobs import GenerateJob, PolicyWeights, run_generate
from adaptenv.scene.procedural.generate import generate_house


def main(n: int, generator: str = "failure-modes") -> None:
    torch.set_num_threads(1)
    weights = PolicyWeights.of(load_pretrained("pretrained-scan"))
    jobs = [GenerateJob(generator, generate_house(100 + k), f"dr{k:04d}", 5, (0, 1, 100 + k), weights=weights,
                        diagnose_episodes=4) for k in range(n)]
    times, digests, edits = [], [], []
    for job in jobs:
        t = time.perf_counter()
        out = run_generate(job)
        times.append(time.perf_counter() - t)
        edits.append(out.edits)
        doc = out.house.model_dump_json() + json.dumps(out.edit_log, sort_keys=True, default=str)
        digests.append(hashlib.sha1(doc.encode()).hexdigest()[:12])
    print(json.dumps({"times": [round(x, 2) for x in times], "total": round(sum(times), 2), "digests": digests,
                      "edits": edits}))


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 4, *sys.argv[2:3])
