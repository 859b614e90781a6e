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


def initial_lines(summary: dict[str, Any]) -> list[str]:
    """One line per method against pi_0: its last held-out success minus pi_0's at t=0 on the same episodes, with
    the 95% interval, saying plainly when the method ended below pi_0 beyond noise."""
    lines = []
    for m, e in summary.get("initial_effects", {}).items():
        if e is None:
            continue
        if e["high"] < 0.0:
            say = f"{m} ended below pi_0 beyond noise: fine-tuning made the agent worse"
        elif e["low"] > 0.0:
            say = f"{m} ended above pi_0 beyond noise"
        else:
            say = "within noise of pi_0"
        lines.append(f"Against t=0: {m} - pi_0 held-out success = {100 * e['diff']:+.1f} points, 95% interval "
                     f"[{100 * e['low']:+.1f}, {100 * e['high']:+.1f}] over the same {e['episodes']} episodes; {say}.")
    return lines


def lever_lines(summary: dict[str, Any]) -> list[str]:
    """The lever test's one line (none when the experiment declares no lever rule): the arm minus the control on
    the held-out set, its 95% interval over seeds, and whether the mean reaches the declared threshold."""
    lever = summary.get("lever")
    if not lever:
        return []
    head = f"Lever: {lever['arm']} - {lever['control']} held-out success on {lever['heldout']}"
    e = lever["effect"]
    if e is None:
        return [f"{head}: undecided, {lever['seeds']} seed(s) finished for both; the paired interval needs two."]
    say = "a lever exists" if lever["exists"] else "no lever"
    return [f"{head} = {100 * e['diff']:+.1f} points, 95% interval [{100 * e['low']:+.1f}, {100 * e['high']:+.1f}] "
            f"over {lever['seeds']} paired seeds; threshold {lever['threshold']:+.1f}: {say}."]


def budget_line(summary: dict[str, Any]) -> str | None:
    """One line stating each method's environment steps, and by how much they differ from the reference's
    (None without figures); a verdict between methods of unequal steps is not a matched-budget comparison."""
    steps = {m: figs["env_steps:all"]["mean"] for m, figs in summary.get("methods", {}).items()
             if "env_steps:all" in figs}
    ref = summary.get("reference")
    if ref not in steps or len(steps) < 2:
        return None
    parts = ", ".join(f"{m} {v:,.0f}" for m, v in steps.items())
    ratios = [steps[ref] / v for m, v in steps.items() if m != ref and v > 0]
    if all(abs(r - 1.0) <= 0.05 for r in ratios):
        return f"Environment steps: {parts}; within 5% of each other, so the verdict compares matched budgets."
    spread = ", ".join(f"{steps[ref] / v:.1f}x {m}'s" for m, v in steps.items() if m != ref and v > 0)
    return (f"Environment steps: {parts}; {ref} used {spread}, so the verdict compares unequal budgets "
            "(the same fine-tuning frames, not the same environment steps).")
