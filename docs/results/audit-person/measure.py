"""Adapt houses with G and audit the results: success before and after, violations per rule.

Two steps, so that the adaptation can run on any revision and the audit with the current rules:

    python measure.py adapt OUT TAG [POLICY [G;...]]  # adapt every house with each G (default: built-in and
                                                      # failure-mode) checked with POLICY; writes OUT/TAG/
                                                      # (a G with settings: builtin:max_candidates=16,fit_to_rules=false)
    python measure.py audit OUT TAG...  # audit OUT/TAG/ with the rules of the code on PYTHONPATH; prints a table
    python measure.py cost OUT TAG...   # the search's counts per step (drawn, passing the dry run, policy-checked)

``adapt`` appends to OUT/TAG/rows.jsonl, so several G can be run into one TAG one after another. With
``MEASURE_ONLY=validation-00,real-seed0`` in the environment it adapts only the runs named (each keeps its seeds: a
subset's rows are those of the full run).

Houses: the first ``HOUSES`` houses of ``preset:validation`` (procedural) and the real-format ProcTHOR house of
tests/data on ``REAL_SEEDS`` episode seeds. Per house: an episode the policy solves (10 draws at most), then
``STEPS`` edits by each G (candidates checked with the policy), then the policy again on the same episode.
"""

from __future__ import annotations

import json
import os
import sys
from collections import Counter
from pathlib import Path

import numpy as np

HOUSES, REAL_SEEDS, STEPS, SEED = 20, 3, 3, 0
#: The policy solving the episodes and checking G's candidates: ``pretrained`` at the commits before cf96152 was the
#: scan-only agent (``pretrained-scan`` since); ``pretrained`` is now the PPO-tuned map agent.
POLICY = "pretrained"
GENERATORS = ("builtin", "failure-modes")
REAL = Path(__file__).resolve().parents[3] / "tests" / "data" / "procthor-10k-train-1.json"


def jobs():
    """(job name, house) for every house adapted."""
    from adaptenv.agents.houses import load_house_set
    from adaptenv.scene.house import load_house

    hs = load_house_set("preset:validation")
    for k, house in enumerate(list(hs.houses)[:HOUSES]):
        yield f"validation-{k:02d}", house
    real = load_house(REAL, validate=False)
    for s in range(REAL_SEEDS):
        yield f"real-seed{s}", real


def adapt(out: Path, tag: str, policy: str = POLICY, generators: tuple[str, ...] = GENERATORS) -> None:
    from adaptenv.adapt.analysis import BuiltinAnalyzer
    from adaptenv.adapt.step import adapt_scene
    from adaptenv.agents.registry import resolve_policy
    from adaptenv.agents.rollout import find_solved_episode
    from adaptenv.scene.house import save_house
    from adaptenv.sim.world import compile_world

    folder = out / tag
    folder.mkdir(parents=True, exist_ok=True)
    agent, analyzer = resolve_policy(policy, seed=SEED), BuiltinAnalyzer()
    with open(folder / "rows.jsonl", "a") as rows:
        only = {j for j in os.environ.get("MEASURE_ONLY", "").split(",") if j}
        for n, (name, house) in enumerate(jobs()):
            if only and name not in only:
                continue
            world = compile_world(house, name)
            found = find_solved_episode(world, agent, np.random.default_rng([SEED, n]), tries=10)
            if found is None:
                rows.write(json.dumps({"job": name, "solved": False}) + "\n")
                continue
            episode, before = found
            save_house(house, folder / f"{name}-original.json")
            for gen in generators:
                res = adapt_scene(house, episode, policy=agent, analyzer=analyzer, generator=_generator(gen),
                                  steps=STEPS, rng=np.random.default_rng([SEED, n, 1]), before=before, name=name)
                save_house(res.house, folder / f"{name}-{_slug(gen)}.json")
                rows.write(json.dumps({"job": name, "solved": True, "generator": gen, "target": episode.target_type,
                                       "success_before": bool(before.metrics.success),
                                       "success_after": bool(res.after.metrics.success),
                                       "spl_before": float(before.metrics.spl), "spl_after": float(res.after.metrics.spl),
                                       "edits": int(res.edits_applied), "policy": policy,
                                       "steps": [_counts(s) for s in res.generation.steps]}) + "\n")
                rows.flush()
            print(name, flush=True)


def _generator(spec: str):
    """A G from ``name`` or ``name:key=value,...`` (values read as JSON: 16, false)."""
    from adaptenv.adapt.generators import make_generator

    name, _, settings = spec.partition(":")
    kw = {k: json.loads(v) for k, v in (item.split("=") for item in settings.split(",") if item)}
    return make_generator(name, **kw)


def _slug(spec: str) -> str:
    """A file-name form of a G spec."""
    return spec.replace(":", "-").replace(",", "-").replace("=", "")


def _counts(step) -> dict:
    """A G step's search cost: candidates drawn, passing their dry run, checked with the policy; its status."""
    return {"status": step.status, "drawn": int(step.candidates), "passed": int(getattr(step, "passed", 0)),
            "checked": int(getattr(step, "checked", 0)), "check_steps": int(step.check_steps)}


def audit(out: Path, tags: list[str]) -> None:
    from adaptenv.adapt.plausibility import RULES
    from adaptenv.adapt.plausibility import audit as run_audit
    from adaptenv.scene.house import load_house

    print("| revision | G | houses | edits | success before | success after | drop (points) | SPL after | "
          "violations (new audit) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for tag in tags:
        folder = out / tag
        rows = [json.loads(line) for line in (folder / "rows.jsonl").read_text().splitlines()]
        for gen in dict.fromkeys(r["generator"] for r in rows if "generator" in r):
            mine = [r for r in rows if r.get("generator") == gen]
            if not mine:
                continue
            counts: Counter[str] = Counter()
            for r in mine:
                original = load_house(folder / f"{r['job']}-original.json", validate=False)
                adapted = load_house(folder / f"{r['job']}-{_slug(gen)}.json", validate=False)
                report = run_audit(original, adapted)
                counts.update(v.rule for v in report.violations)
                for v in report.violations:
                    print(f"  {tag} {gen} {r['job']}: {v}", file=sys.stderr)
            before = np.mean([r["success_before"] for r in mine])
            after = np.mean([r["success_after"] for r in mine])
            spl = np.mean([r["spl_after"] for r in mine])
            bad = ", ".join(f"{k} {counts[k]}" for k in RULES if counts[k]) or "0"
            print(f"| {tag} | {gen} | {len(mine)} | {sum(r['edits'] for r in mine)} | {before:.3f} | {after:.3f} | "
                  f"{100 * (before - after):.1f} | {spl:.3f} | {bad} |")


def cost(out: Path, tags: list[str]) -> None:
    """Print each G's mean counts per step (rows of 51fb814 on; earlier rows have none)."""
    print("| revision | G | candidates drawn | passing their dry run | checked with the policy (max) |")
    print("|---|---|---|---|---|")
    for tag in tags:
        rows = [json.loads(line) for line in (out / tag / "rows.jsonl").read_text().splitlines()]
        for gen in dict.fromkeys(r["generator"] for r in rows if "generator" in r):
            steps = [s for r in rows if r.get("generator") == gen for s in r.get("steps", [])]
            if steps:
                mean = {k: np.mean([s[k] for s in steps]) for k in ("drawn", "passed", "checked")}
                print(f"| {tag} | {gen} | {mean['drawn']:.1f} | {mean['passed']:.1f} | {mean['checked']:.2f} "
                      f"({max(s['checked'] for s in steps)}) |")


if __name__ == "__main__":
    if len(sys.argv) >= 4 and sys.argv[1] == "adapt":
        policy = sys.argv[4] if len(sys.argv) > 4 else POLICY
        adapt(Path(sys.argv[2]), sys.argv[3], policy, tuple(sys.argv[5].split(";")) if len(sys.argv) > 5 else GENERATORS)
    elif len(sys.argv) >= 4 and sys.argv[1] == "audit":
        audit(Path(sys.argv[2]), sys.argv[3:])
    elif len(sys.argv) >= 4 and sys.argv[1] == "cost":
        cost(Path(sys.argv[2]), sys.argv[3:])
    else:
        sys.exit(__doc__)
