"""Print the scarce-homes lever test's tables from OUT/results/*.json (and OUT/runs/*/policy.json).

Usage: .venv/bin/python docs/results/scarce-homes/table.py OUT

Columns are success in percent. The lever and room readings follow DECLARED.md: differences paired
over seeds with a 95% t-interval (a single seed gives the difference alone, which decides nothing).
"""

from __future__ import annotations

import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy import stats

SETS = ("far", "long-unseen", "rearranged", "unseen-assets", "tail")


def value(row: dict, s: str) -> float:
    """Success in points of a result row on set ``s`` (tail: the tail success)."""
    h = row["heldout"][s]
    return 100.0 * (h["tail_success"] if s == "tail" else h["success"])


def paired(a: list[float], b: list[float]) -> str:
    """Mean of a - b with its 95% t-interval over paired seeds."""
    d = np.array(a) - np.array(b)
    if len(d) < 2:
        return f"{d.mean():+.1f} (1 seed)"
    half = stats.t.ppf(0.975, len(d) - 1) * d.std(ddof=1) / np.sqrt(len(d))
    return f"{d.mean():+.1f} [{d.mean() - half:+.1f}, {d.mean() + half:+.1f}]"


def main(out: Path) -> None:
    rows = [json.loads(p.read_text()) for p in sorted((out / "results").glob("*.json"))]
    print("| job | train houses | success on own training episodes | validation (val-long / val-unseen-assets) by frames |")
    print("|---|---|---|---|")
    for card in sorted((out / "runs").glob("*/policy.json")):
        c = json.loads(card.read_text())
        job = card.parent.name
        res = next((r for r in rows if r["job"] == job), None)
        val = ""
        if res:
            frames = sorted(res["validation"].get("val-long", {}), key=int)
            val = "; ".join(f"{int(f):,}: {100 * res['validation']['val-long'][f]:.0f} / "
                            f"{100 * res['validation']['val-unseen-assets'][f]:.0f}" for f in frames)
        print(f"| {job} | {c['n_houses']} | {100 * c['final_train_success']:.1f} | {val} |")
    if not rows:
        return
    print()
    print("| job | " + " | ".join(SETS) + " | tail: mean of its 2,000 |")
    print("|---|" + "---|" * (len(SETS) + 1))
    for r in rows:
        print(f"| {r['job']} | " + " | ".join(f"{value(r, s):.1f}" for s in SETS)
              + f" | {100 * r['heldout']['tail']['mean_success']:.1f} |")
    by = defaultdict(dict)
    for r in rows:
        by[(r["perception"], r["n"], r["arm"])][r["seed"]] = r
    for (mode, n) in sorted({(m, n) for m, n, _ in by}):
        arms = {a: by[(mode, n, a)] for m, nn, a in by if (m, nn) == (mode, n)}
        if "none" not in arms or "fresh" not in arms:
            continue
        print(f"\n{mode}, N = {n}: differences in points (paired over the seeds both arms finished)")
        for s in SETS:
            parts = []
            for arm in ("fresh", "oracle", "swap", "rearrange"):
                if arm in arms:
                    seeds = sorted(set(arms[arm]) & set(arms["none"]))
                    parts.append(f"{arm} - none {paired([value(arms[arm][k], s) for k in seeds], [value(arms['none'][k], s) for k in seeds])}")
            print(f"- {s}: " + "; ".join(parts))


if __name__ == "__main__":
    main(Path(sys.argv[1]))
