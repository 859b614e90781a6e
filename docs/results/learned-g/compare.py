"""Learned, built-in and random G at the same edit budget on held-out houses (see DECLARED.md in this folder).

    python compare.py run OUT [--agent NAME] [--workers N]   # resumable: OUT/rows-AGENT.jsonl, one row per (job, G)
    python compare.py table OUT [--agent NAME]               # the declared table, with paired 95% intervals

``--generators`` names the generators (default ``learned,builtin,random``): ``learned`` is the shipped scorer with
the library's defaults, and options, chained with ``+``, change one setting each: ``checksK`` (the agent shown its K
best edits), ``objectivesK`` (its K best edits measured on the route objectives, no rollout; ``objectives0`` is the
one-pass G), ``randomP`` (P percent of its candidates random moves, the rest the built-in G's route moves), ``lazy1`` (route moves fitted to the
plausibility rules in score order, when their turn comes), as in ``learned+random50+objectives0``. ``builtin+rolloutsK`` is the built-in G with ``rollout_candidates=K``, and
``--checkpoint FILE`` replaces the shipped scorer. ``--tag T`` writes ``rows-AGENT-T.jsonl`` instead, so a second
comparison keeps its own rows. The first generator is the one the intervals compare with the others. Rows of runs
made before a default changed name their G as it was then (see each ``DECLARED-*.md``).

Jobs: the first ``HOUSES`` houses of ``preset:pretrain-unseen`` (procedural houses no G was built or trained on) and
the real-format ProcTHOR house of tests/data on ``REAL_SEEDS`` episode seeds. Per job: an episode the agent solves
(10 draws at most, seed ``[SEED, job]``), then ``STEPS`` edits by each G (seed ``[SEED, job, 1]``), then the agent
again on that episode and on ``PAIRED`` other episodes of the same target in the same house (seed ``[SEED, job, 2]``,
the same before and after), and on ``FRESH`` fresh action draws of the adapted episode itself (the same start and
target, new sampling seeds: draws no G's rollout check saw). Each house G writes is audited against the original.
``--jobs heldin`` runs on the first ``HOUSES`` houses of ``preset:pretrain-train`` instead (held-in houses, the
learned G's data houses: for choosing settings, never for the comparison).
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

HOUSES, REAL_SEEDS, STEPS, SEED, PAIRED, FRESH = 40, 4, 3, 0, 8, 8
GENERATORS = ("learned", "builtin", "random")
REAL = Path(__file__).resolve().parents[3] / "tests" / "data" / "procthor-10k-train-1.json"


@functools.cache
def jobs(which: str = "heldout") -> list[tuple[str, object]]:
    """(job name, house) for every job of ``which`` (``heldout`` or ``heldin``), in a fixed order."""
    from adaptenv.agents.houses import load_house_set
    from adaptenv.scene.house import load_house

    if which == "heldin":
        return [(f"train-{k:02d}", h) for k, h in enumerate(list(load_house_set("preset:pretrain-train").houses)[:HOUSES])]
    out = [(f"unseen-{k:02d}", h) for k, h in enumerate(list(load_house_set("preset:pretrain-unseen").houses)[:HOUSES])]
    real = load_house(REAL, validate=False)
    return out + [(f"real-seed{s}", real) for s in range(REAL_SEEDS)]


def make(gen: str, checkpoint: str | None):
    """The generator ``gen`` names (see the module docstring)."""
    from adaptenv.adapt.generators import make_generator

    base, *mods = gen.split("+")
    opts = {m.rstrip("abcdefghijklmnopqrstuvwxyz").rstrip("0123456789"):
            int("".join(ch for ch in m if ch.isdigit()) or 0) for m in mods}
    if base == "learned":  # options not named keep the library's defaults
        if "random" in opts:
            opts["random_share"] = opts.pop("random") / 100
        if "lazy" in opts:
            opts["lazy_fit"] = bool(opts.pop("lazy"))
        return make_generator("learned", checkpoint=checkpoint, **opts)
    if base == "builtin" and "rollouts" in opts:
        return make_generator("builtin", rollout_candidates=opts["rollouts"])
    return make_generator(gen)


def one_job(args: tuple[int, str, str, tuple[str, ...], str | None]) -> list[dict]:
    """Every G's row for job ``n`` with agent ``agent``."""
    n, name, agent_name, generators, checkpoint, which = args
    from adaptenv.adapt.analysis import BuiltinAnalyzer
    from adaptenv.adapt.generators.random_perturbation import random_single_edits
    from adaptenv.adapt.plausibility import audit
    from adaptenv.adapt.step import adapt_scene
    from adaptenv.adapt.target import fresh_measurement
    from adaptenv.agents.registry import resolve_policy
    from adaptenv.agents.rollout import draw_episode, find_solved_episode, rollout
    from adaptenv.sim.world import compile_world

    house = dict(jobs(which))[name]
    agent, analyzer = resolve_policy(agent_name, seed=SEED), BuiltinAnalyzer()
    world = compile_world(house, name)
    found = find_solved_episode(world, agent, np.random.default_rng([SEED, n]), tries=10)
    if found is None:
        return [{"job": name, "agent": agent_name, "solved": False}]
    episode, before = found
    rng = np.random.default_rng([SEED, n, 2])
    paired = [draw_episode(world, rng, episode.target_type) for _ in range(PAIRED)]
    paired_before = [rollout(world, ep, agent).metrics.success for ep in paired]
    fresh_before = fresh_measurement(world, [episode], agent, FRESH).success
    rows = []
    for gen in generators:
        t0 = time.perf_counter()
        rng = np.random.default_rng([SEED, n, 1])
        if gen == "random":  # STEPS accepted random single-object edits (ACCEL's editor), validated, not audited
            new, log = random_single_edits(house, STEPS, rng, episode_targets=[episode.target_type],
                                           start=episode.start[:2])
            edits, problems = sum(e.accepted and e.changed for e in log.edits), []
            new_world = compile_world(new, name)
            after = rollout(new_world, episode, agent)  # timed, as adapt_scene's own rollout after G is
        else:
            res = adapt_scene(house, episode, policy=agent, analyzer=analyzer, generator=make(gen, checkpoint),
                              steps=STEPS, rng=rng, before=before, name=name)
            new, edits, problems, new_world, after = res.house, int(res.edits_applied), res.problems, res.world, res.after
        seconds = time.perf_counter() - t0
        paired_after = [rollout(new_world, ep, agent).metrics.success for ep in paired]
        fresh_after = fresh_measurement(new_world, [episode], agent, FRESH).success
        violations = [str(v) for v in audit(house, new).violations]
        rows.append({"job": name, "agent": agent_name, "solved": True, "generator": gen, "target": episode.target_type,
                     "success_after": bool(after.metrics.success), "spl_before": float(before.metrics.spl),
                     "spl_after": float(after.metrics.spl), "edits": edits,
                     "paired_before": float(np.mean(paired_before)), "paired_after": float(np.mean(paired_after)),
                     "fresh_before": float(fresh_before), "fresh_after": float(fresh_after),
                     "seconds": round(seconds, 3), "violations": violations, "problems": problems})
    return rows


def rows_path(out: Path, agent: str, tag: str) -> Path:
    return out / (f"rows-{agent}-{tag}.jsonl" if tag else f"rows-{agent}.jsonl")


def run(out: Path, agent: str, workers: int, generators: tuple[str, ...], checkpoint: str | None, tag: str,
        which: str = "heldout") -> None:
    """Run every job not yet in ``OUT/rows-AGENT[-TAG].jsonl`` (append-only, so a stopped run resumes)."""
    out.mkdir(parents=True, exist_ok=True)
    path = rows_path(out, agent, tag)
    done = {json.loads(line)["job"] for line in path.open()} if path.exists() else set()
    todo = [(n, name, agent, generators, checkpoint, which) for n, (name, _) in enumerate(jobs(which))
            if name not in done]
    with ProcessPoolExecutor(workers) as pool, path.open("a") as f:
        for rows in pool.map(one_job, todo):
            f.write("".join(json.dumps(r) + "\n" for r in rows))
            f.flush()
            print(rows[0]["job"], flush=True)


def paired_interval(diff: np.ndarray, seed: int = 0, n: int = 10_000) -> tuple[float, float]:
    """95% bootstrap interval of the mean of ``diff`` (paired over jobs)."""
    rng = np.random.default_rng(seed)
    means = diff[rng.integers(0, len(diff), (n, len(diff)))].mean(axis=1)
    return float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))


def table(out: Path, agent: str, generators: tuple[str, ...], tag: str) -> None:
    """Print the declared table for ``agent``'s rows."""
    rows = [json.loads(line) for line in rows_path(out, agent, tag).open()]
    solved = sorted({r["job"] for r in rows if r["solved"]})
    print(f"agent {agent}: {len(solved)} of {len({r['job'] for r in rows})} jobs with a solved episode; "
          f"{STEPS} edits per G")
    fresh = all("fresh_after" in r for r in rows if r["solved"])
    print("| G | runs | edits accepted | success after | drop (points) | drop per edit | paired drop (points) | "
          "audit violations | s per accepted edit |" + (" fresh drop (points) |" if fresh else ""))
    print("|---|---|---|---|---|---|---|---|---|" + ("---|" if fresh else ""))
    by = {g: {r["job"]: r for r in rows if r.get("generator") == g} for g in generators}
    for g in generators:
        mine = [by[g][j] for j in solved]
        edits = sum(r["edits"] for r in mine)
        drop = 100 * (1 - np.mean([r["success_after"] for r in mine]))
        paired = 100 * np.mean([r["paired_before"] - r["paired_after"] for r in mine])
        secs = sum(r["seconds"] for r in mine) / max(edits, 1)
        print(f"| {g} | {len(mine)} | {edits} | {1 - drop / 100:.3f} | {drop:.1f} | {drop / max(edits / len(mine), 1e-9):.1f} "
              f"| {paired:.1f} | {sum(len(r['violations']) for r in mine)} | {secs:.2f} |"
              + (f" {100 * np.mean([r['fresh_before'] - r['fresh_after'] for r in mine]):.1f} |" if fresh else ""))
    first = generators[0]
    for other in generators[1:]:
        d = np.array([float(by[other][j]["success_after"]) - float(by[first][j]["success_after"]) for j in solved])
        lo, hi = paired_interval(d)
        print(f"{first} - {other} drop: {100 * d.mean():+.1f} points, 95% interval [{100 * lo:+.1f}, {100 * hi:+.1f}] "
              f"over {len(d)} paired runs")
        if fresh:  # a larger drop is a lower fresh_after (fresh_before is the same house for every G)
            d = np.array([by[other][j]["fresh_after"] - by[first][j]["fresh_after"] for j in solved])
            lo, hi = paired_interval(d)
            print(f"{first} - {other} fresh drop: {100 * d.mean():+.1f} points, 95% interval "
                  f"[{100 * lo:+.1f}, {100 * hi:+.1f}] over {len(d)} paired runs")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("step", choices=("run", "table"))
    ap.add_argument("out", type=Path)
    ap.add_argument("--agent", default="pretrained")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--generators", default=",".join(GENERATORS))
    ap.add_argument("--checkpoint", default=None, help="a learned-G scorer instead of the shipped one")
    ap.add_argument("--tag", default="")
    ap.add_argument("--jobs", choices=("heldout", "heldin"), default="heldout")
    a = ap.parse_args()
    gens = tuple(a.generators.split(","))
    if a.step == "run":
        run(a.out, a.agent, a.workers, gens, a.checkpoint, a.tag, a.jobs)
    else:
        table(a.out, a.agent, gens, a.tag)
