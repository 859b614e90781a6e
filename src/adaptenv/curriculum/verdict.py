"""The verdict line of an experiment: the reference minus each method on held-out success, in plain words.

Read from ``summary.json``'s ``episode_effects`` (:func:`adaptenv.curriculum.experiment.episode_effects`); a
module of its own with no heavy imports, so that the report can state it without loading torch.
"""

from __future__ import annotations

from typing import Any


def verdict_lines(summary: dict[str, Any]) -> list[str]:
    """One plain line per compared method: the reference's held-out success minus the method's, paired over
    episodes, with its 95% interval, and whether the difference is within noise (the interval holds 0)."""
    ref, lines = summary["reference"], []
    for m, effects in summary.get("episode_effects", {}).items():
        e = effects.get("all")
        if e is None:
            continue
        if e["low"] <= 0.0 <= e["high"]:
            say = (f"within noise: the interval includes 0, so these {e['episodes']} episodes cannot tell {ref} "
                   f"from {m}")
        else:
            say = f"{ref} is {'better' if e['diff'] > 0 else 'worse'} than {m} beyond noise (the interval excludes 0)"
        lines.append(f"Verdict: {ref} - {m} held-out success = {100 * e['diff']:+.1f} points, 95% interval "
                     f"[{100 * e['low']:+.1f}, {100 * e['high']:+.1f}], paired over the {e['episodes']} held-out "
                     f"episodes both were evaluated on; {say}.")
    return lines
