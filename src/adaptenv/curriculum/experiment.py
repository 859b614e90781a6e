"""The experiment the paper leaves as future work: methods x seeds under one budget, held-out results.

``run_experiment`` runs :func:`~adaptenv.curriculum.loop.run_loop` for every (method, seed) into
``OUT/<method>/seed_<s>/`` (resumable), then :func:`summarize` writes:

- ``OUT/<method>/per_seed.csv``: rows ``metric:set``, one column per seed (final iteration);
- ``OUT/summary.json`` and ``OUT/summary.md``: mean and standard error per method and set, a
  paired t-test (over seeds: the same seed gives every method the same pi_0 and the same held-out
  episodes) of ours against each baseline, and the unusable houses each house set skipped
  (``skipped_houses``, gathered from the runs' ``run.json``);
- ``OUT/plots/heldout_<set>_vs_iterations.png`` and ``..._vs_env_steps.png``.

``summary.json``'s ``episode_effects`` pairs the runs episode by episode instead of seed by seed (the last
iteration's held-out episodes, the same for every method of a seed), so even a one-seed experiment such as
``adaptenv demo`` gets a paired interval; :func:`verdict_lines` states it in words, and summary.md and the
experiment report open with those lines.

:func:`final_evaluation` (``adaptenv experiment --final-episodes N``) evaluates pi_0 and each run's
last policy again on more held-out episodes, to shrink the evaluation noise in the comparison, and
writes the same tables as ``per_seed_final.csv`` and ``summary_final.{json,md}``.
"""

from __future__ import annotations

import csv
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

try:
    import fcntl
except ImportError:  # not POSIX
    fcntl = None

import numpy as np
from scipy import stats

from adaptenv.adapt.llm.accounting import check_llm_section
from adaptenv.agents.checkpoint import load_checkpoint
from adaptenv.configfile import STRICT, parse_config, read_json
from adaptenv.curriculum.executor import InProcessExecutor
from adaptenv.curriculum.jobs import PolicyWeights
from adaptenv.curriculum.loop import METHODS, LoopConfig, evaluate_sets, run_loop
from adaptenv.curriculum.methods import ADAPTING_METHODS
from adaptenv.curriculum.records import (
    HELDOUT_DIR,
    ITERATIONS,
    STATE,
    IterationRecord,
    RunInfo,
    SkippedHouses,
    atomic_write_text,
    iteration_dir,
    read_iterations,
)
from adaptenv.curriculum.verdict import lever_lines, verdict_lines
from adaptenv.errors import AdaptenvError, ConfigError, RunsFailed
from adaptenv.files import atomic_path, open_append

METRICS = ("success", "spl", "collisions")
#: Figures of the summary table and its tests: the held-out metrics and the paper's Delta R
#: (``success_gain``: final held-out success minus that of pi_0 on the same episodes).
TESTED = (*METRICS, "success_gain")
#: The fix an experiment config's type errors suggest.
CONFIG_FIX = "write it as in configs/experiment-small.json (docs/curriculum.md lists the loop fields)"


@dataclass
class LeverRule:
    """A lever test's declared reading: ``arm`` minus ``control`` held-out success on set ``heldout``, over seeds."""

    arm: str
    """The training distribution tested (e.g. the test's own generator, a ceiling: ``rearrange``, ``oracle``)."""
    control: str = "none"
    """What it is compared with (``none``: fine-tuning on the training houses as they are)."""
    heldout: str = ""
    """Held-out set name (a key of ``loop.heldout``) the rule reads."""
    threshold: float = 5.0
    """Points of success the mean difference must reach for a lever to exist."""

    __pydantic_config__ = STRICT


@dataclass
class ExperimentConfig:
    """Methods x seeds and the loop settings they share (JSON file for ``adaptenv experiment``)."""

    methods: list[str] = field(default_factory=lambda: ["none", "random", "dr", "sfl", "plr", "accel", "ours"])
    """Methods to run; 'ours' is compared against every other one."""
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2, 3, 4])
    """Seeds (at least 5 for the committed results)."""
    loop: dict[str, Any] = field(default_factory=dict)
    """LoopConfig fields shared by every run (method and seed are set per run)."""
    reference: str = "ours"
    """The method tested against every other one."""
    primary: list[str] = field(default_factory=list)
    """The declared primary comparison: the reference against the better of these baselines on each held-out set
    (by mean success over seeds), Holm over the sets only (e.g. ["dr", "sfl"]); empty: none declared."""
    lever: LeverRule | None = None
    """A lever test's rule: the summary opens with one line saying whether the lever exists, with its interval."""

    __pydantic_config__ = STRICT

    def __post_init__(self) -> None:
        if isinstance(self.lever, dict):  # read back from experiment.json
            self.lever = LeverRule(**self.lever)

    @classmethod
    def load(cls, path: str | Path) -> ExperimentConfig:
        """Read and check a config file (before any work); one ConfigError names the file and the field."""
        p = Path(path)
        return parse_config(cls, read_json(p, "experiment config (see configs/)"), str(p), fix=CONFIG_FIX).check(str(p))

    def check(self, source: str = "experiment config") -> ExperimentConfig:
        """Return self, or raise one ConfigError naming the first bad field: types (the loop section's too),
        known methods, no method or seed twice, and every run's loop settings."""
        parse_config(ExperimentConfig, asdict(self), source, fix=CONFIG_FIX)
        per_run = sorted({"method", "seed"} & set(self.loop))
        if per_run:
            raise ConfigError(f"{source}: loop.{per_run[0]} is set per run from methods and seeds; remove it "
                              "from the loop section")
        parse_config(LoopConfig, self.loop, source, prefix="loop", fix=CONFIG_FIX)
        check_llm_section(self.loop.get("llm") or {}, source, "loop.llm")
        for where, m in [*((f"methods[{i}]", m) for i, m in enumerate(self.methods)), ("reference", self.reference)]:
            if m not in METHODS:
                raise ConfigError(f"{source}: {where} {m!r} is unknown; use one of {', '.join(METHODS)}")
        for i, b in enumerate(self.primary):
            if b not in self.methods or b == self.reference:
                raise ConfigError(f"{source}: primary[{i}] {b!r} must be one of the methods other than the "
                                  f"reference {self.reference!r}")
        if self.lever is not None:
            for where, m in (("lever.arm", self.lever.arm), ("lever.control", self.lever.control)):
                if m not in self.methods:
                    raise ConfigError(f"{source}: {where} {m!r} is not one of the methods; add it to methods")
            sets = self.loop_config(self.methods[0], self.seeds[0] if self.seeds else 0).heldout
            if self.lever.heldout not in sets:
                raise ConfigError(f"{source}: lever.heldout {self.lever.heldout!r} is not a held-out set; use one of "
                                  + ", ".join(sets))
        for name, values in (("methods", self.methods), ("seeds", self.seeds)):
            if not values:
                raise ConfigError(f"{source}: {name} is empty; list at least one")
            twice = next((v for i, v in enumerate(values) if v in values[:i]), None)
            if twice is not None:
                raise ConfigError(f"{source}: {name} lists {twice!r} twice; list each once (runs share a folder)")
        matched = self.loop.get("match_method", "ours")
        if "dr-matched" in self.methods and matched not in self.methods[:self.methods.index("dr-matched")]:
            raise ConfigError(f"{source}: methods: dr-matched matches {matched}'s environment steps; list "
                              f"{matched} before dr-matched")
        for m in self.methods:
            for seed in self.seeds:
                self.loop_config(m, seed, Path("OUT")).check(f"{source}: loop")
        return self

    def loop_config(self, method: str, seed: int, out: Path | None = None) -> LoopConfig:
        """One run's settings; ``dr-matched`` runs of experiment folder ``out`` match the same seed's run there."""
        fields = {**self.loop, "method": method, "seed": seed}
        if method not in ADAPTING_METHODS:  # difficulty on request is for the adapting methods; baselines run as usual
            fields = {k: v for k, v in fields.items() if not k.startswith("target_")}
        if method == "dr-matched" and out is not None and not fields.get("match_run"):
            fields["match_run"] = str(run_dir(out, fields.get("match_method", "ours"), seed))
        return LoopConfig(**fields)


def run_dir(out: Path, method: str, seed: int) -> Path:
    return Path(out) / method / f"seed_{seed}"


def _run_one(args: tuple[dict[str, Any], str, str, int]) -> str | None:
    """Worker entry point (picklable): run or resume one (method, seed), then (``final_episodes`` > 0) its final
    evaluation, so a finished run is complete on its own and an interrupted experiment loses no evaluation.
    Returns None, or a line saying why the run failed: one run's failure does not stop the others.

    When stderr is a log rather than a terminal (a background experiment), each finished stage and
    run gets a timestamped line there, so hours of work are not silent; on a terminal the progress bar speaks.
    """
    loop_fields, folder, command, final_episodes = args
    cfg = LoopConfig(**loop_fields)
    say = None if sys.stderr.isatty() else _log_line(f"{cfg.method} seed {cfg.seed}")
    try:
        records = run_loop(cfg, folder, resume=True, command=command, progress=say)
        if say is not None:
            say(f"run finished ({records[-1].iteration} iterations)" if records else "run finished")
        if final_episodes and records and records[-1].iteration == cfg.iterations:
            run_final_eval(Path(folder).parent.parent, cfg.method, cfg.seed, cfg.heldout, final_episodes,
                           InProcessExecutor(), say or (lambda text: None))
    except Exception as exc:  # noqa: BLE001 -- reported with the others' results, not lost in a worker
        why = f"{cfg.method} seed {cfg.seed}: {exc if isinstance(exc, AdaptenvError) else repr(exc)}"
        print(f"{time.strftime('%H:%M:%S')} run failed: {why}", file=sys.stderr, flush=True)
        return why
    return None


def _log_line(prefix: str) -> Callable[[str], None]:
    """A ``progress`` callback that writes ``HH:MM:SS prefix: text`` lines to stderr."""
    def say(text: str) -> None:
        print(f"{time.strftime('%H:%M:%S')} {prefix}: {text}", file=sys.stderr, flush=True)
    return say


def run_experiment(cfg: ExperimentConfig, out: str | Path, *, executor: Any = None, command: str = "",
                   progress: Any = None, final_episodes: int = 0) -> dict[str, Any]:
    """Run every (method, seed) that is not finished yet, then summarize; returns the summary.

    ``final_episodes`` > 0: each run is evaluated on that many held-out episodes per set as soon as it
    finishes (its ``final_eval.json``; see :func:`final_evaluation`). A run that fails does not stop the
    others: once they are done and summarized, :class:`RunsFailed` names every failed run and why."""
    out = Path(out)
    cfg.check()  # before anything is saved
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "experiment.json", json.dumps(asdict(cfg), indent=1))
    # seed by seed: an experiment stopped early leaves whole seeds (every method), the unit of the paired tests
    jobs = [(asdict(cfg.loop_config(m, s, out)), str(run_dir(out, m, s)), command, final_episodes) for s in cfg.seeds
            for m in cfg.methods]
    if executor is None:
        failures = []
        for i, job in enumerate(jobs):
            if progress:
                progress(f"run {i + 1}/{len(jobs)}: {job[0]['method']} seed {job[0]['seed']}")
            failures.append(_run_one(job))
    else:
        failures = executor.map(_run_one, jobs, desc="experiment runs")
    summary = summarize(out, cfg, failed=[why for why in failures if why])
    if failed := [why for why in failures if why]:
        raise RunsFailed(f"{len(failed)} of {len(jobs)} runs failed ({'; '.join(failed)}); the others are in "
                         f"{out}, and running the same command again retries the failed ones where they stopped")
    return summary


def _mean_se(values: list[float]) -> tuple[float, float | None]:
    """Mean and standard error over seeds (None when undefined: fewer than two seeds)."""
    a = np.asarray(values, dtype=float)
    if a.size == 0:
        return float("nan"), None
    se = float(a.std(ddof=1) / math.sqrt(a.size)) if a.size > 1 else None
    return float(a.mean()), se


def final_figures(out: Path, cfg: ExperimentConfig) -> dict[str, dict[int, dict[str, float]]]:
    """method -> seed -> {"metric:set": value} at each run's last iteration, for the runs that finished every
    iteration (a run that failed or stopped early is no row: :func:`unfinished_runs` names it)."""
    table: dict[str, dict[int, dict[str, float]]] = {}
    for m in cfg.methods:
        for s in cfg.seeds:
            recs = read_iterations(run_dir(out, m, s))
            if not recs or recs[-1].iteration < cfg.loop.get("iterations", LoopConfig.iterations):
                continue
            last = recs[-1]
            row = {f"{k}:{name}": getattr(v, k) for name, v in last.heldout.items() for k in METRICS}
            row.update({f"success_gain:{name}": v.success - recs[0].heldout[name].success
                        for name, v in last.heldout.items() if name in recs[0].heldout})
            row.update(_budget(last))
            table.setdefault(m, {})[s] = row
    return table


def unfinished_runs(out: Path, cfg: ExperimentConfig) -> dict[str, str]:
    """``method seed N`` -> how far each run that has not finished every iteration got (it failed, stopped at its
    budget or is still running): these are left out of the figures."""
    total = cfg.loop.get("iterations", LoopConfig.iterations)
    left = {}
    for m in cfg.methods:
        for s in cfg.seeds:
            recs = read_iterations(run_dir(out, m, s))
            done = recs[-1].iteration if recs else None
            if done is None or done < total:
                left[f"{m} seed {s}"] = "not started" if done is None else f"{done} of {total} iterations"
    return left


def _budget(last: Any) -> dict[str, float]:
    """The budget a run spent up to its last record (rows ``<counter>:all``)."""
    return {"env_steps:all": float(last.env_steps), "grad_updates:all": float(last.grad_updates),
            "edits:all": float(last.edits), "iterations:all": float(last.iteration)}


def paired_test(a: list[float], b: list[float]) -> float | None:
    """Two-sided paired t-test p-value of a vs b over seeds (None when it is undefined)."""
    if len(a) < 2 or len(a) != len(b):
        return None
    diff = np.asarray(a) - np.asarray(b)
    if np.allclose(diff, diff[0]):
        return None if diff[0] == 0 else 0.0
    return float(stats.ttest_rel(a, b).pvalue)


def paired_effect(a: list[float], b: list[float]) -> dict[str, float] | None:
    """Mean of a - b over seeds with its t-based 95% interval (None with fewer than two seeds)."""
    if len(a) < 2 or len(a) != len(b):
        return None
    diff = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    mean = float(diff.mean())
    if np.allclose(diff, diff[0]):  # no spread: scipy's interval is undefined, the difference is exact
        return {"diff": mean, "low": mean, "high": mean}
    ci = stats.ttest_rel(a, b).confidence_interval(0.95)
    return {"diff": mean, "low": float(ci.low), "high": float(ci.high)}


def holm(pvalues: dict[str, float | None]) -> dict[str, float | None]:
    """Holm-Bonferroni adjusted p-values of one family of tests (undefined tests stay None)."""
    known = sorted((p, k) for k, p in pvalues.items() if p is not None)
    adjusted: dict[str, float | None] = {k: None for k in pvalues}
    running = 0.0
    for rank, (p, k) in enumerate(known):
        running = max(running, min(1.0, (len(known) - rank) * p))
        adjusted[k] = running
    return adjusted


def summarize(out: str | Path, cfg: ExperimentConfig | None = None, failed: list[str] | None = None) -> dict[str, Any]:
    """Write per-seed CSVs, summary.json, summary.md and plots for an experiment folder; ``failed`` are the lines
    saying why runs failed (they are marked, never rows)."""
    out = Path(out)
    cfg = cfg or ExperimentConfig(**json.loads((out / "experiment.json").read_text(encoding="utf-8")))
    summary = write_summary(out, cfg, final_figures(out, cfg), episode_effects=episode_effects(out, cfg),
                            unfinished=unfinished_runs(out, cfg), failed=failed)
    _plots(out, cfg)
    return summary


def write_summary(out: Path, cfg: ExperimentConfig, table: dict[str, dict[int, dict[str, float]]],
                  suffix: str = "", episodes: int | None = None,
                  episode_effects: dict[str, Any] | None = None, unfinished: dict[str, str] | None = None,
                  failed: list[str] | None = None) -> dict[str, Any]:
    """From method -> seed -> figures: ``<method>/per_seed{suffix}.csv`` and ``summary{suffix}.json/md``.

    ``episodes``: episodes per held-out set behind each figure (the final evaluation's), recorded when given;
    ``episode_effects``: :func:`episode_effects`' result, recorded when given.
    """
    metrics = sorted({k for seeds in table.values() for row in seeds.values() for k in row})
    for m, seeds in table.items():
        cols = sorted(seeds)
        lines = ["metric:set," + ",".join(f"seed_{s}" for s in cols)]
        for key in metrics:
            lines.append(key + "," + ",".join(f"{seeds[s].get(key, float('nan')):.6g}" for s in cols))
        atomic_write_text(out / m / f"per_seed{suffix}.csv", "\n".join(lines) + "\n")

    summary: dict[str, Any] = {"methods": {}, "tests": {}, "effects": {}, "holm": {}, "reference": cfg.reference,
                               "seeds": cfg.seeds}
    if episodes is not None:
        summary["episodes"] = episodes
    for m, seeds in table.items():
        summary["methods"][m] = {key: dict(zip(("mean", "se"), _mean_se([row[key] for row in seeds.values()
                                                                          if key in row]), strict=True))
                                 | {"n": len(seeds)} for key in metrics}
    ref = table.get(cfg.reference, {})
    for m, seeds in table.items():
        if m == cfg.reference:
            continue
        common = sorted(set(ref) & set(seeds))
        shared = [key for key in metrics if all(key in ref[s] and key in seeds[s] for s in common)]  # same sets
        summary["tests"][m] = {key: paired_test([ref[s][key] for s in common], [seeds[s][key] for s in common])
                               for key in shared if key.split(":")[0] in TESTED}
        summary["effects"][m] = {key: paired_effect([ref[s][key] for s in common], [seeds[s][key] for s in common])
                                 for key in shared if key.split(":")[0] == "success"}
    # the family the claim rests on: held-out success of the reference against every method on every set
    family = {f"{m}|{key}": p for m, tests in summary["tests"].items() for key, p in tests.items()
              if key.split(":")[0] == "success"}
    for name, p in holm(family).items():
        m, key = name.split("|")
        summary["holm"].setdefault(m, {})[key] = p
    if cfg.primary:
        summary["primary"] = primary_comparison(table, cfg.reference, cfg.primary)
    if cfg.lever is not None:
        summary["lever"] = lever_reading(table, cfg.lever)
    if episode_effects is not None:
        summary["episode_effects"] = episode_effects
    summary["skipped_houses"] = {k: v.model_dump() for k, v in skipped_in_runs(out, cfg).items()}
    if unfinished:
        summary["unfinished_runs"] = unfinished
    if failed:
        summary["failed_runs"] = failed
    atomic_write_text(out / f"summary{suffix}.json", json.dumps(summary, indent=1, default=float))
    atomic_write_text(out / f"summary{suffix}.md", summary_markdown(summary))
    return summary


def primary_comparison(table: dict[str, dict[int, dict[str, float]]], reference: str,
                       baselines: list[str]) -> dict[str, Any]:
    """The declared primary: on each held-out set, ``reference`` minus the baseline with the higher mean success there
    (the first listed on a tie), paired over their common seeds, with Holm's correction over the sets only."""
    ref = table.get(reference, {})
    sets = sorted({k for row in ref.values() for k in row if k.startswith("success:")})
    rows: dict[str, dict[str, Any]] = {}
    for key in sets:
        means = {b: _mean_se([row[key] for row in table.get(b, {}).values() if key in row])[0] for b in baselines}
        best = max(baselines, key=lambda b: (np.nan_to_num(means[b], nan=-np.inf), -baselines.index(b)))
        common = sorted(s for s in set(ref) & set(table.get(best, {})) if key in ref[s] and key in table[best][s])
        a, b = [ref[s][key] for s in common], [table[best][s][key] for s in common]
        rows[key] = {"baseline": best, "seeds": len(common), "effect": paired_effect(a, b), "p": paired_test(a, b)}
    for key, p_adj in holm({k: r["p"] for k, r in rows.items()}).items():
        rows[key]["p_holm"] = p_adj
    return {"reference": reference, "baselines": list(baselines), "sets": rows}


def lever_reading(table: dict[str, dict[int, dict[str, float]]], rule: LeverRule) -> dict[str, Any]:
    """The lever rule read from method -> seed -> figures: the paired effect over common seeds and whether its mean
    reaches the threshold (None with fewer than two common seeds)."""
    key = f"success:{rule.heldout}"
    arm, control = table.get(rule.arm, {}), table.get(rule.control, {})
    common = sorted(s for s in set(arm) & set(control) if key in arm[s] and key in control[s])
    effect = paired_effect([arm[s][key] for s in common], [control[s][key] for s in common])
    exists = None if effect is None else bool(100 * effect["diff"] >= rule.threshold)
    return {**asdict(rule), "seeds": len(common), "effect": effect, "exists": exists}


def _episode_successes(folder: Path) -> dict[tuple[str, int], float]:
    """(set, episode index) -> success of a run's last held-out evaluation (empty before iteration 1)."""
    recs = read_iterations(folder)
    if not recs or recs[-1].iteration < 1:
        return {}
    found = {}
    for name in recs[-1].heldout:
        path = iteration_dir(folder, recs[-1].iteration) / HELDOUT_DIR / name / "episodes.csv"
        if path.is_file():
            with path.open(newline="", encoding="utf-8") as f:
                found.update({(name, int(row["index"])): float(row["success"] == "True") for row in csv.DictReader(f)})
    return found


def episode_effects(out: Path, cfg: ExperimentConfig) -> dict[str, dict[str, dict[str, float] | None]]:
    """Per method: held-out success of the reference minus the method's, paired over the episodes both runs' last
    iterations were evaluated on (``all``: every seed and set pooled; ``success:<set>``: one set), each with
    the mean difference, its t-based 95% interval, the paired t-test's ``p_episodes`` and ``episodes``."""
    left = unfinished_runs(out, cfg)  # no episodes of a failed or unfinished run

    def successes(m: str, s: int) -> dict[tuple[str, int], float]:
        return {} if f"{m} seed {s}" in left else _episode_successes(run_dir(out, m, s))

    ref = {s: successes(cfg.reference, s) for s in cfg.seeds}
    effects: dict[str, dict[str, dict[str, float] | None]] = {}
    for m in cfg.methods:
        if m == cfg.reference:
            continue
        pairs: dict[str, tuple[list[float], list[float]]] = {}
        for s in cfg.seeds:
            other = successes(m, s)
            for key in sorted(set(ref[s]) & set(other)):
                for group in ("all", f"success:{key[0]}"):
                    a, b = pairs.setdefault(group, ([], []))
                    a.append(ref[s][key])
                    b.append(other[key])
        effects[m] = {}
        for group, (a, b) in sorted(pairs.items()):
            e = paired_effect(a, b)
            effects[m][group] = None if e is None else {**e, "p_episodes": paired_test(a, b), "episodes": len(a)}
    return effects


def skipped_in_runs(out: Path, cfg: ExperimentConfig) -> dict[str, SkippedHouses]:
    """Per house-set spec, the unusable houses the experiment's runs skipped (read from their ``run.json``)."""
    merged: dict[str, dict[str, str]] = {}
    for m in cfg.methods:
        for s in cfg.seeds:
            info = run_dir(out, m, s) / "run.json"
            if info.is_file():
                for spec, sk in RunInfo.model_validate_json(info.read_text(encoding="utf-8")).skipped_houses.items():
                    merged.setdefault(spec, {}).update(sk.houses)
    return {spec: SkippedHouses(count=len(h), houses=h) for spec, h in merged.items()}


FINAL_EVAL = "final_eval.json"
"""Per run: held-out figures of pi_0 and of the last policy on ``episodes`` episodes per set."""


#: pi_0's final-evaluation figures per seed (the same policy and episodes in every run of a seed), computed once.
INITIAL_EVAL = "initial_eval"


def _evaluate_policy(policy_path: Path, specs: dict[str, str], episodes: int, seed: int, ex: Any) -> dict[str, Any]:
    weights = PolicyWeights.of(load_checkpoint(policy_path).policy())
    return {k: v.model_dump() for k, v in evaluate_sets(weights, specs, episodes, seed, ex).items()}


def _initial_figures(out: Path, folder: Path, specs: dict[str, str], episodes: int, seed: int, ex: Any
                     ) -> dict[str, Any]:
    """pi_0's final evaluation for a seed, from the experiment's cache or computed once and cached.

    Runs of a seed that finish together (in other processes) wait on a lock file instead of each
    evaluating pi_0 again; without ``fcntl`` (not POSIX) each computes it.
    """
    cache = out / INITIAL_EVAL / f"seed_{seed}.json"
    cache.parent.mkdir(parents=True, exist_ok=True)
    with open_append(cache.with_suffix(".lock")) as lock:
        if fcntl is not None:
            fcntl.flock(lock, fcntl.LOCK_EX)
        initial = json.loads(cache.read_text(encoding="utf-8")) if cache.is_file() else {}
        if initial.get("episodes") != episodes or initial.get("sets") != specs:
            initial = {"episodes": episodes, "sets": specs,
                       "figures": _evaluate_policy(iteration_dir(folder, 0) / "policy.pt", specs, episodes, seed, ex)}
            atomic_write_text(cache, json.dumps(initial, indent=1))
    return initial


def run_final_eval(out: Path, method: str, seed: int, specs: dict[str, str], episodes: int, ex: Any,
                   say: Callable[[str], None] = lambda text: None) -> tuple[dict[str, Any], IterationRecord] | None:
    """A run's ``final_eval.json`` (pi_0 and the last policy on ``episodes`` episodes per held-out set, the seed's
    episodes, so every method's run of a seed is paired) and its last iteration record; the file is computed only
    when missing or stale. None: no record yet."""
    folder = run_dir(out, method, seed)
    recs = read_iterations(folder)
    if not recs:
        return None
    path = folder / FINAL_EVAL
    doc = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    if doc.get("episodes") == episodes and doc.get("iteration") == recs[-1].iteration:
        return doc, recs[-1]
    say(f"final evaluation: {method} seed {seed} ({episodes} episodes per set)")
    start = time.perf_counter()
    initial = _initial_figures(out, folder, specs, episodes, seed, ex)
    doc = {"episodes": episodes, "iteration": recs[-1].iteration, "initial": initial["figures"],
           "final": _evaluate_policy(iteration_dir(folder, recs[-1].iteration) / "policy.pt", specs, episodes, seed, ex)}
    doc["seconds"] = round(time.perf_counter() - start, 2)  # with pi_0's evaluation when this run made the cache
    atomic_write_text(path, json.dumps(doc, indent=1))
    say(f"final evaluation written: {method} seed {seed}")
    return doc, recs[-1]


def final_evaluation(out: str | Path, cfg: ExperimentConfig, episodes: int, *, executor: Any = None,
                     progress: Any = None) -> dict[str, Any]:
    """Evaluate pi_0 and every run's last policy that has no current ``final_eval.json`` on ``episodes`` held-out
    episodes per set (:func:`run_final_eval`), then write ``summary_final`` from every run's file."""
    out, ex = Path(out), executor if executor is not None else InProcessExecutor()
    specs = cfg.loop_config(cfg.reference, cfg.seeds[0]).heldout
    say = progress or (lambda text: None)
    table: dict[str, dict[int, dict[str, float]]] = {}
    for m in cfg.methods:
        for s in cfg.seeds:
            done = run_final_eval(out, m, s, specs, episodes, ex, say)
            if done is None:
                continue
            doc, last = done
            row = {f"{k}:{name}": float(v[k]) for name, v in doc["final"].items() for k in METRICS}
            row.update({f"success_gain:{name}": v["success"] - doc["initial"][name]["success"]
                        for name, v in doc["final"].items()})
            row.update(_budget(last))
            table.setdefault(m, {})[s] = row
    return write_summary(out, cfg, table, suffix="_final", episodes=episodes)


def summary_markdown(summary: dict[str, Any]) -> str:
    """The results table: mean +- SE per method and held-out figure, p-value of ours vs each method."""
    keys = sorted({k for v in summary["methods"].values() for k in v if k.split(":")[0] in TESTED})
    ref = summary["reference"]
    head = "| method | " + " | ".join(keys) + " | env steps | updates |"
    verdicts = lever_lines(summary) + verdict_lines(summary)
    lines = [*verdicts, *([""] if verdicts else []), *primary_markdown(summary.get("primary")), head,
             "|" + "---|" * (len(keys) + 3)]
    for m, figs in summary["methods"].items():
        cells = []
        for k in keys:
            f = figs.get(k)
            p = summary["tests"].get(m, {}).get(k)
            mark = f" (p={p:.3f})" if p is not None else ""
            se = "n/a" if f and f["se"] is None else f"{f['se']:.3f}" if f else ""
            cells.append(f"{f['mean']:.3f} ± {se}{mark}" if f else "")
        env = figs.get("env_steps:all", {}).get("mean", float("nan"))
        upd = figs.get("grad_updates:all", {}).get("mean", float("nan"))
        lines.append(f"| {m} | " + " | ".join(cells) + f" | {env:,.0f} | {upd:,.0f} |")
    lines.append("")
    lines.append(f"Mean ± standard error over seeds {summary['seeds']}; p: paired t-test of {ref} against the "
                 "method on the same seeds (two-sided).")
    lines += ["", *effects_markdown(summary)]
    lines += ["", skipped_line(summary.get("skipped_houses") or {})]
    if unfinished := summary.get("unfinished_runs"):
        lines += ["", "Not in the table (failed, stopped at a budget or unfinished; run the same command again to "
                  "finish them): " + "; ".join(f"{run} ({how})" for run, how in unfinished.items()) + "."]
    for why in summary.get("failed_runs") or []:
        lines.append(f"- FAILED {why}")
    return "\n".join(lines) + "\n"


def primary_markdown(primary: dict[str, Any] | None) -> list[str]:
    """summary.md's first table: the declared primary comparison, one row per held-out set (none when undeclared)."""
    if not primary:
        return []
    ref, rows = primary["reference"], primary["sets"]
    lines = [f"Declared primary: {ref} minus the better of {' and '.join(primary['baselines'])} on each set, "
             "points of held-out success, paired over seeds, Holm over the sets:", "",
             "| set | baseline | difference | 95% interval | p | p (Holm) |", "|---|---|---|---|---|---|"]
    for key, r in rows.items():
        e = r["effect"]
        diff = "n/a" if e is None else f"{100 * e['diff']:+.1f}"
        ci = "n/a" if e is None else f"[{100 * e['low']:+.1f}, {100 * e['high']:+.1f}]"
        lines.append(f"| {key.split(':', 1)[1]} | {r['baseline']} | {diff} | {ci} | {_p(r['p'])} | {_p(r['p_holm'])} |")
    return [*lines, ""]


def skipped_line(skipped: dict[str, dict[str, Any]]) -> str:
    """One summary.md line: how many unusable houses each house set skipped, and the first few names."""
    sets = [(spec, sk) for spec, sk in skipped.items() if sk["count"]]
    if not sets:
        return "Skipped houses: none (every house of every set was usable)."
    parts = [f"{spec}: {sk['count']} ({', '.join(list(sk['houses'])[:3])}{', ...' if sk['count'] > 3 else ''})"
             for spec, sk in sets]
    return "Skipped houses (cannot be used; reasons in summary.json): " + "; ".join(parts) + "."


def _p(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.4f}"


def effects_markdown(summary: dict[str, Any]) -> list[str]:
    """Held-out success of the reference minus each method: paired mean, 95% interval, p and Holm's p."""
    ref, rows = summary["reference"], []
    for m, effects in summary.get("effects", {}).items():
        for key, e in sorted(effects.items()):
            if e is None:
                continue
            p, ph = summary["tests"][m].get(key), summary["holm"].get(m, {}).get(key)
            rows.append(f"| {m} | {key.split(':', 1)[1]} | {e['diff']:+.3f} | [{e['low']:+.3f}, {e['high']:+.3f}] "
                        f"| {_p(p)} | {_p(ph)} |")
    if not rows:
        return []
    return [f"Effect on held-out success: {ref} minus each method (paired over seeds)", "",
            "| method | set | difference | 95% interval | p | p (Holm) |", "|---|---|---|---|---|---|", *rows, "",
            f"Holm's correction runs over all {len(rows)} success comparisons of this table."]


def curves(out: Path, cfg: ExperimentConfig, set_name: str, x: str) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """method -> (x, mean success, se) over seeds, per iteration (x = 'iteration' or 'env_steps')."""
    result = {}
    for m in cfg.methods:
        runs = [read_iterations(run_dir(out, m, s)) for s in cfg.seeds]
        runs = [r for r in runs if r and all(set_name in rec.heldout for rec in r)]
        if not runs:  # the method never evaluated this set
            continue
        n = min(len(r) for r in runs)
        ys = np.array([[rec.heldout[set_name].success for rec in r[:n]] for r in runs])
        xs = np.array([[getattr(rec, x) for rec in r[:n]] for r in runs]).mean(axis=0)
        se = ys.std(axis=0, ddof=1) / math.sqrt(len(runs)) if len(runs) > 1 else np.zeros(n)
        result[m] = (xs, ys.mean(axis=0), se)
    return result


def _plots(out: Path, cfg: ExperimentConfig) -> None:
    # matplotlib: slow to import, so only when plots are drawn
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    sets = sorted({k for m in cfg.methods for s in cfg.seeds for r in read_iterations(run_dir(out, m, s))[:1]
                   for k in r.heldout})  # methods may evaluate different sets (runs gathered from several experiments)
    (out / "plots").mkdir(exist_ok=True)
    for set_name in sets:
        for x, label in (("iteration", "iteration"), ("env_steps", "environment steps")):
            fig, ax = plt.subplots(figsize=(6, 4), dpi=110)
            for m, (xs, mean, se) in curves(out, cfg, set_name, x).items():
                ax.plot(xs, mean, marker="o", label=m, linewidth=2.2 if m == cfg.reference else 1.2)
                ax.fill_between(xs, mean - se, mean + se, alpha=0.15)
            ax.set_xlabel(label)
            if x == "iteration":
                ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            ax.set_ylabel(f"held-out success ({set_name})")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
            fig.tight_layout()
            with atomic_path(out / "plots" / f"heldout_{set_name}_vs_{x}.png") as tmp:
                fig.savefig(tmp)
            plt.close(fig)

#: What :func:`pack_experiment` keeps of a finished run: enough to summarize it and to skip it on resume.
PACKED_RUN_FILES = ("run.json", STATE, ITERATIONS, FINAL_EVAL)


def pack_experiment(out: str | Path, dest: str | Path, cfg: ExperimentConfig | None = None) -> list[Path]:
    """Copy an experiment's results without policies or scenes to ``dest`` (small enough to commit): its config,
    summaries, pi_0's evaluations, and each finished, finally evaluated run's record, the folder's absolute path
    written as ``OUT``. ``adaptenv experiment`` on ``dest`` with the same config skips those runs and runs the rest.
    Returns the runs packed."""
    out, dest = Path(out), Path(dest)
    here = str(out.resolve())

    def copy(src: Path, to: Path) -> None:
        atomic_write_text(to, src.read_text(encoding="utf-8").replace(here, "OUT"))

    cfg = cfg or ExperimentConfig(**json.loads((out / "experiment.json").read_text(encoding="utf-8")))
    dest.mkdir(parents=True, exist_ok=True)
    top = [p for p in out.iterdir() if p.is_file() and p.suffix in (".json", ".md")]
    top += sorted((out / INITIAL_EVAL).glob("*.json")) + sorted(out.glob("*/per_seed*.csv"))
    for p in top:
        (dest / p.relative_to(out)).parent.mkdir(parents=True, exist_ok=True)
        copy(p, dest / p.relative_to(out))
    packed = []
    for m in cfg.methods:
        for s in cfg.seeds:
            src = run_dir(out, m, s)
            recs = read_iterations(src)
            if not recs or recs[-1].iteration != cfg.loop_config(m, s).iterations or not (src / FINAL_EVAL).is_file():
                continue
            to = run_dir(dest, m, s)
            to.mkdir(parents=True, exist_ok=True)
            for name in PACKED_RUN_FILES:
                copy(src / name, to / name)
            packed.append(to)
    return packed
