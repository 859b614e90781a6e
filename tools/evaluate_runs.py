"""Choose between loop variants on validation suites: evaluate runs' final policies, then compare two methods.

    python tools/evaluate_runs.py evaluate --name val --suites val-long,val-far,val-clutter [--episodes 100] RUN...
    python tools/evaluate_runs.py compare --name val --seeds 0,1,2,3 METHOD_A_FOLDER METHOD_B_FOLDER
    python tools/evaluate_runs.py reference --name explorer --policy map-explorer --suites far,clutter --seeds 0,1 OUT
    python tools/evaluate_runs.py layouts --seeds 0,1,2,3 METHOD_FOLDER...
    python tools/evaluate_runs.py assemble --config EXPERIMENT.json --out FOLDER METHOD=FOLDER[:NAME]...
    python tools/evaluate_runs.py pack EXPERIMENT_FOLDER DEST
    python tools/evaluate_runs.py time EXPERIMENT_FOLDER [--seeds 0,1] [--log STDERR_LOG...]
    python tools/evaluate_runs.py table EXPERIMENT_FOLDER

``evaluate`` writes ``RUN/<name>.json`` with the last iteration's policy on each suite (a suite name,
or any house-set spec with a colon such as ``preset:NAME``), on the
episodes of the run's seed (as ``adaptenv experiment --final-episodes`` draws them, so two methods'
runs of one seed are paired); runs that have the file are skipped. ``reference`` plays a fixed
policy (a ``--policy`` spec: ``map-explorer``, a checkpoint, ...) on the same episodes, seed by seed,
into ``OUT/seed_K/<name>.json``, so that ``compare --name-b <name>`` pairs runs with it. ``compare``
prints, per suite and for the mean of the suites, the difference A - B averaged over the seeds, its 95% interval,
the paired t test (scipy) and, per suite, Holm's adjusted p over the suites. ``layouts`` counts,
per run, the distinct house layouts fine-tuned on over all iterations (a child ``house~t02f03``
has its parent's layout) and the scenes by kind. ``assemble`` gathers methods run in different
experiment folders (from other machines or commits) into one, with the experiment's own summaries and HTML report. ``pack`` copies
an experiment's results without policies or scenes (``pack_experiment``), small enough to commit; run
``adaptenv experiment`` on the copy to go on where it stopped. ``time`` prints where an experiment's time went,
per method summed over its seeds: the loop's own clock by stage and the final evaluation (``final_eval.json``'s
``seconds``, or for older runs the lines of a background experiment's stderr log).
``table`` prints an experiment's final evaluation (``summary_final.json``) in points: every method's held-out
success, its change from pi_0 and its budget, then the reference minus each method with intervals and p values.
docs/RESULTS.md's tables, those of docs/results/ and docs/BENCHMARKS.md's stage tables are this script's output.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict
from pathlib import Path

import numpy as np


def evaluate(name: str, suites: list[str], episodes: int, runs: list[Path]) -> None:
    """Evaluate each run's final policy on ``suites`` into ``run/<name>.json``."""
    from adaptenv.agents.checkpoint import load_checkpoint
    from adaptenv.curriculum.executor import InProcessExecutor
    from adaptenv.curriculum.jobs import PolicyWeights
    from adaptenv.curriculum.loop import evaluate_sets
    from adaptenv.curriculum.records import read_iterations

    specs = {s: s if ":" in s else f"suite:{s}" for s in suites}
    for run in runs:
        out = run / f"{name}.json"
        if out.is_file():
            continue
        seed = json.loads((run / "run.json").read_text())["seed"]
        last = read_iterations(run)[-1].iteration
        weights = PolicyWeights.of(load_checkpoint(run / f"iter_{last:04d}" / "policy.pt").policy())
        final = evaluate_sets(weights, specs, episodes, seed, InProcessExecutor())
        doc = {"episodes": episodes, "seed": seed, "iteration": last, "final": {k: v.model_dump() for k, v in final.items()}}
        out.write_text(json.dumps(doc, indent=1), encoding="utf-8")
        print(run, {k: round(v.success, 3) for k, v in final.items()}, flush=True)


def reference(name: str, policy: str, suites: list[str], episodes: int, seeds: list[int], out: Path) -> None:
    """Play ``policy`` on each seed's final episodes of ``suites`` (as ``adaptenv experiment --final-episodes``
    draws them) into ``out/seed_K/<name>.json``, in the layout ``compare`` reads; finished seeds are skipped."""
    from adaptenv.agents.evaluate import run_episodes, sample_episodes
    from adaptenv.agents.registry import resolve_policy
    from adaptenv.curriculum.jobs import EVAL_BATCH, heldout_set
    from adaptenv.curriculum.loop import set_metrics

    player = resolve_policy(policy)  # sampler seed 0, as the loop's PolicyWeights.policy(); episodes seed the rest
    for seed in seeds:
        path = out / f"seed_{seed}" / f"{name}.json"
        if path.is_file():
            continue
        final = {}
        for suite in suites:
            hs = heldout_set(suite if ":" in suite else f"suite:{suite}")
            results, _ = run_episodes(hs.worlds, sample_episodes(hs.worlds, episodes, seed),
                                      player, batch=EVAL_BATCH)
            final[suite] = set_metrics(results).model_dump()
        path.parent.mkdir(parents=True, exist_ok=True)
        doc = {"policy": policy, "episodes": episodes, "seed": seed, "final": final}
        path.write_text(json.dumps(doc, indent=1), encoding="utf-8")
        print(path, {k: round(v["success"], 3) for k, v in final.items()}, flush=True)


def compare(name: str, seeds: list[int], a: Path, b: Path, name_b: str | None = None) -> None:
    """Print A - B per suite (95% interval, paired t test, Holm's p over the suites) and for the mean of the suites,
    paired by seed.

    ``name_b``: B's file name when it differs (``final_eval`` for an experiment's own final evaluation).
    """
    from scipy import stats

    from adaptenv.curriculum.experiment import holm

    def load(folder: Path, file: str) -> dict[str, np.ndarray]:
        docs = [json.loads((folder / f"seed_{k}" / f"{file}.json").read_text()) for k in seeds]
        return {s: np.array([d["final"][s]["success"] for d in docs]) for s in docs[0]["final"]}

    def test(d: np.ndarray) -> tuple[str, float | None]:
        if len(d) < 2:
            return "n/a", None
        half = stats.t.ppf(0.975, len(d) - 1) * d.std(ddof=1) / np.sqrt(len(d))
        return f"[{d.mean() - half:+.3f}, {d.mean() + half:+.3f}]", float(stats.ttest_1samp(d, 0.0).pvalue)

    def fmt(p: float | None) -> str:
        return "n/a" if p is None else f"{p:.3f}"

    sa, sb = load(a, name), load(b, name_b or name)
    diffs = {s: sa[s] - sb[s] for s in sa}
    tests = {s: test(d) for s, d in diffs.items()}
    adjusted = holm({s: p for s, (_, p) in tests.items()})
    print(f"A = {a}, B = {b}, seeds {seeds}")
    print("| suite | A | B | A - B | 95% interval | p (paired t) | p (Holm over the suites) | per seed |\n"
          "|---|---|---|---|---|---|---|---|")
    for s, d in diffs.items():
        per_seed = ", ".join(f"{round(x, 2) + 0.0:+.2f}" for x in d)
        interval, p = tests[s]
        print(f"| {s} | {sa[s].mean():.3f} | {sb[s].mean():.3f} | {d.mean():+.3f} | {interval} | {fmt(p)} "
              f"| {fmt(adjusted[s])} | {per_seed} |")
    d = np.mean([sa[s] for s in sa], 0) - np.mean([sb[s] for s in sa], 0)
    interval, p = test(d)
    print(f"| mean of the suites | {np.mean(list(sa.values())):.3f} | {np.mean([sb[s] for s in sa]):.3f} "
          f"| {d.mean():+.3f} | {interval} | {fmt(p)} | | |")


def assemble(config: Path, out: Path, sources: list[str]) -> None:
    """Gather each method's runs from its own experiment folder into one experiment folder ``out`` and summarize them
    there (summary.json, summary_final.json with Holm over every comparison, plots; ``adaptenv report out`` then
    draws the HTML report).

    ``sources``: ``METHOD=FOLDER`` (the runs' own ``final_eval.json``) or ``METHOD=FOLDER:NAME`` (this tool's
    ``NAME.json``). Run folders are linked, not copied; each gets a ``final_eval.json`` from its evaluation, with
    pi_0's figures of its seed (same policy, same episodes) taken from a run that has them.
    """
    from adaptenv.curriculum.experiment import ExperimentConfig, final_evaluation, summarize

    cfg = ExperimentConfig.load(config)
    given: dict[str, tuple[Path, str]] = {}
    for src in sources:
        method, _, where = src.partition("=")
        folder, _, name = where.partition(":")
        if not method or not folder:
            raise SystemExit(f"assemble: {src!r} is not METHOD=FOLDER[:NAME]")
        given[method] = (Path(folder), name or "final_eval")
    if sorted(given) != sorted(cfg.methods):
        raise SystemExit(f"assemble: {config} lists methods {cfg.methods}, the sources give {sorted(given)}; "
                         "give one METHOD=FOLDER per method")
    docs: dict[tuple[str, int], dict] = {}
    for method, (folder, name) in given.items():
        for seed in cfg.seeds:
            src = folder / f"seed_{seed}"
            if not (src / f"{name}.json").is_file():
                raise SystemExit(f"assemble: {src / name}.json is missing; evaluate that run first")
            docs[(method, seed)] = json.loads((src / f"{name}.json").read_text())
            dst = out / method / f"seed_{seed}"
            dst.mkdir(parents=True, exist_ok=True)
            for entry in src.iterdir():
                link = dst / entry.name
                if entry.name not in ("final_eval.json", f"{name}.json") and not link.is_symlink():
                    link.symlink_to(entry.resolve())
    episodes = {d["episodes"] for d in docs.values()}
    if len(episodes) != 1:
        raise SystemExit(f"assemble: the evaluations have different episode counts {sorted(episodes)}; "
                         "evaluate every run on the same number")
    for (method, seed), doc in docs.items():
        initial = doc.get("initial") or next((d["initial"] for (_, s), d in docs.items() if s == seed and "initial" in d),
                                             None)
        if initial is None:
            raise SystemExit(f"assemble: no run of seed {seed} has pi_0's figures ('initial'); include a method "
                             "evaluated by `adaptenv experiment --final-episodes`")
        final = {"episodes": doc["episodes"], "iteration": doc["iteration"], "initial": initial, "final": doc["final"]}
        (out / method / f"seed_{seed}" / "final_eval.json").write_text(json.dumps(final, indent=1))
    (out / "experiment.json").write_text(json.dumps(asdict(cfg), indent=1))
    summarize(out, cfg)
    final_evaluation(out, cfg, episodes.pop())
    print((out / "summary_final.md").read_text())


def layouts(seeds: list[int], folders: list[Path]) -> None:
    """Print, per method folder and seed, the distinct layouts trained on and the trained scenes by kind."""
    print("| method | seed | distinct layouts | fresh houses | children | training houses |\n|---|---|---|---|---|---|")
    for folder in folders:
        for seed in seeds:
            run = folder / f"seed_{seed}"
            names = [x for it in sorted(run.glob("iter_*")) if it.name != "iter_0000"
                     for x in json.loads((it / "scenes.json").read_text())["trained_on"]]
            children = sum("~" in x for x in names)
            fresh = sum("~" not in x and x.startswith("dr") for x in names)
            distinct = len({x.split("~")[0] for x in names})
            print(f"| {folder.name} | {seed} | {distinct} | {fresh} | {children} | {len(names) - children - fresh} |")


STAGES = ("rollouts", "scenes", "finetune", "evaluate")


def final_eval_seconds(logs: list[Path]) -> dict[tuple[str, int], float]:
    """Seconds of each run's final evaluation, from the lines ``adaptenv experiment`` writes to a non-terminal stderr:
    from ``HH:MM:SS method seed k: run finished`` (or ``final evaluation:``) to its ``final evaluation written``. A
    resumed experiment repeats both lines for its finished runs at once; the longest span counts."""
    import re
    from datetime import datetime

    begun: dict[tuple[str, int], datetime] = {}
    out: dict[tuple[str, int], float] = {}
    line_re = re.compile(r"^(\d\d:\d\d:\d\d) (\S+) seed (\d+): (run finished|final evaluation:|final evaluation written)")
    for log in logs:
        for line in log.read_text(encoding="utf-8").splitlines():
            if not (m := line_re.match(line)):
                continue
            at, key = datetime.strptime(m.group(1), "%H:%M:%S"), (m.group(2), int(m.group(3)))
            if m.group(4) != "final evaluation written":
                begun[key] = at
            elif key in begun:
                span = (at - begun.pop(key)).total_seconds() % 86400  # a run may cross midnight
                out[key] = max(span, out.get(key, 0.0))
    return out


def timing(folder: Path, logs: list[Path], seeds: list[int] | None = None) -> None:
    """Print seconds per method (summed over its seeds, or over ``seeds``) by stage of the loop and for the final
    evaluation."""
    from adaptenv.curriculum.experiment import ExperimentConfig
    from adaptenv.curriculum.records import read_iterations

    cfg = ExperimentConfig.load(folder / "experiment.json")
    from_logs = final_eval_seconds(logs)
    rows, seeds_done = {}, set()
    for m in cfg.methods:
        row = dict.fromkeys((*STAGES, "final"), 0.0)
        for k in seeds if seeds is not None else cfg.seeds:
            run = folder / m / f"seed_{k}"
            if not (run / "final_eval.json").is_file():
                continue
            seeds_done.add(k)
            for rec in read_iterations(run):
                for stage in STAGES:
                    row[stage] += rec.stage_seconds.get(stage, 0.0)
            doc = json.loads((run / "final_eval.json").read_text())
            seconds = doc.get("seconds", from_logs.get((m, k)))
            if seconds is None:
                raise SystemExit(f"time: {run}/final_eval.json has no seconds; pass the experiment's stderr log "
                                 "with --log")
            row["final"] += seconds
        rows[m] = row
    if not seeds_done:
        raise SystemExit(f"time: no run in {folder} has a final evaluation yet (final_eval.json); run "
                         "`adaptenv experiment ... --final-episodes N` to the end first")
    total = {c: sum(r[c] for r in rows.values()) for c in (*STAGES, "final")}
    whole = sum(total.values())
    print(f"seconds per method, summed over seeds {sorted(seeds_done)} (each run's own clock; two run at once)")
    print("| method | rollouts | scenes (F, G, checks) | fine-tuning | held-out evaluation | final evaluation | total |\n"
          "|---|---|---|---|---|---|---|")
    for m, r in rows.items():
        print(f"| `{m}` | " + " | ".join(f"{r[c]:,.0f}" for c in (*STAGES, "final")) + f" | {sum(r.values()):,.0f} |")
    print("| all | " + " | ".join(f"{total[c]:,.0f} ({total[c] / whole:.0%})" for c in (*STAGES, "final"))
          + f" | {whole:,.0f} |")


def table(folder: Path) -> None:
    """Print the final evaluation's success table (percent, mean +- s.e. over seeds) and the reference's effects."""
    if not (folder / "summary_final.json").is_file():
        sys.exit(f"{folder}: no summary_final.json; run `adaptenv experiment --config CONFIG -o {folder} "
                 "--final-episodes N` first (it writes it once the runs have their final evaluation)")
    summary = json.loads((folder / "summary_final.json").read_text())
    methods, ref = summary["methods"], summary["reference"]
    sets = list(json.loads((folder / "experiment.json").read_text())["loop"]["heldout"])  # the config's order
    initial = [json.loads(p.read_text())["figures"] for p in sorted((folder / "initial_eval").glob("seed_*.json"))
               if int(p.stem.split("_")[1]) in summary["seeds"]]
    print(f"seeds {summary['seeds']}, {summary['episodes']} episodes per suite; pi_0: "
          + ", ".join(f"{s} {100 * np.mean([d[s]['success'] for d in initial]):.1f}" for s in sets))
    print("| method | " + " | ".join(f"`{s}`" for s in sets) + " | change from pi_0 (" + ", ".join(sets)
          + ") | env steps | gradient updates | edits |\n|---|" + "---|" * (len(sets) + 4))
    for m, row in methods.items():
        cells = [f"{100 * row[f'success:{s}']['mean']:.1f} ± {100 * (row[f'success:{s}']['se'] or 0):.1f}" for s in sets]
        gains = ", ".join(f"{100 * row[f'success_gain:{s}']['mean']:+.1f}" for s in sets)
        budget = [f"{row[k]['mean']:,.0f}" for k in ("env_steps:all", "grad_updates:all", "edits:all")]
        print(f"| `{m}` | " + " | ".join(cells) + f" | {gains} | " + " | ".join(budget) + " |")
    if not summary["effects"]:
        print(f"\n`{ref}` is the only method: no comparison (pair it with another experiment's runs by `compare`)")
        return
    print(f"\n`{ref}` minus each method, points (paired over seeds; Holm over all {sum(len(v) for v in summary['effects'].values())} comparisons)")
    print("| method | suite | difference | 95% interval | p | p (Holm) |\n|---|---|---|---|---|---|")
    for m, effects in summary["effects"].items():
        for key, e in sorted(effects.items(), key=lambda kv: sets.index(kv[0].split(":", 1)[1])):
            p, ph = summary["tests"][m][key], summary["holm"][m][key]
            diff = "n/a (one seed) | n/a" if e is None else \
                f"{100 * e['diff']:+.1f} | [{100 * e['low']:+.1f}, {100 * e['high']:+.1f}]"
            print(f"| `{m}` | {key.split(':', 1)[1]} | {diff} "
                  f"| {'n/a' if p is None else f'{p:.3f}'} | {'n/a' if ph is None else f'{ph:.2f}'} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    ev = sub.add_parser("evaluate")
    ev.add_argument("--name", required=True)
    ev.add_argument("--suites", required=True)
    ev.add_argument("--episodes", type=int, default=100)
    ev.add_argument("runs", nargs="+", type=Path)
    cmp = sub.add_parser("compare")
    cmp.add_argument("--name", required=True)
    cmp.add_argument("--seeds", required=True)
    cmp.add_argument("--name-b", default=None, help="B's file name when it differs (e.g. final_eval)")
    cmp.add_argument("a", type=Path)
    cmp.add_argument("b", type=Path)
    ref = sub.add_parser("reference")
    ref.add_argument("--name", required=True)
    ref.add_argument("--policy", required=True, help="a --policy spec: map-explorer, a checkpoint path, ...")
    ref.add_argument("--suites", required=True)
    ref.add_argument("--episodes", type=int, default=1000)
    ref.add_argument("--seeds", required=True)
    ref.add_argument("out", type=Path)
    asm = sub.add_parser("assemble")
    asm.add_argument("--config", required=True, type=Path, help="experiment config naming the methods, seeds, reference")
    asm.add_argument("--out", required=True, type=Path)
    asm.add_argument("sources", nargs="+", help="METHOD=FOLDER or METHOD=FOLDER:NAME")
    pk = sub.add_parser("pack")
    pk.add_argument("folder", type=Path)
    pk.add_argument("dest", type=Path)
    tm = sub.add_parser("time")
    tm.add_argument("folder", type=Path)
    tm.add_argument("--log", type=Path, nargs="*", default=[], help="stderr logs of a background experiment")
    tm.add_argument("--seeds", default=None, help="only these seeds (default: the config's)")
    tb = sub.add_parser("table")
    tb.add_argument("folder", type=Path)
    lay = sub.add_parser("layouts")
    lay.add_argument("--seeds", required=True)
    lay.add_argument("folders", nargs="+", type=Path)
    args = parser.parse_args()
    if args.command == "evaluate":
        evaluate(args.name, args.suites.split(","), args.episodes, args.runs)
    elif args.command == "compare":
        compare(args.name, [int(s) for s in args.seeds.split(",")], args.a, args.b, args.name_b)
    elif args.command == "reference":
        reference(args.name, args.policy, args.suites.split(","), args.episodes,
                  [int(k) for k in args.seeds.split(",")], args.out)
    elif args.command == "assemble":
        assemble(args.config, args.out, args.sources)
    elif args.command == "pack":
        from adaptenv.curriculum.experiment import pack_experiment

        print(f"packed {len(pack_experiment(args.folder, args.dest))} finished runs into {args.dest}")
    elif args.command == "time":
        timing(args.folder, args.log, [int(k) for k in args.seeds.split(",")] if args.seeds else None)
    elif args.command == "table":
        table(args.folder)
    else:
        layouts([int(s) for s in args.seeds.split(",")], args.folders)


if __name__ == "__main__":
    main()
