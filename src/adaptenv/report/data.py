"""What a report shows, read from run and experiment folders into plain dataclasses.

Reading is forgiving where a run may still be in progress (a half-written last line of
``iterations.jsonl``, a missing render, an unreadable analysis): the problem becomes a warning shown
in the report instead of a crash. Only a folder that is neither a run nor an experiment is an error.
"""

from __future__ import annotations

import csv
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from pydantic import ValidationError

from adaptenv.adapt.analysis import Analysis
from adaptenv.adapt.edits import EditLog
from adaptenv.adapt.generators import StepRecord
from adaptenv.curriculum.records import (
    HELDOUT_DIR,
    ITERATIONS,
    RUN_INFO,
    GalleryItem,
    IterationRecord,
    RunInfo,
)
from adaptenv.errors import AdaptenvError
from adaptenv.scene.dataset import parse_dataset_spec

SUMMARY = "summary.json"
FINAL_SUMMARY = "summary_final.json"
DATA_SUFFIXES = (".json", ".csv", ".md")
"""Experiment files copied into the report and linked (summary.json, summary.md, per-seed CSVs)."""
METRICS = ("success", "spl")
_P_KEYS = frozenset({"p", "p_value", "p_values", "pvalue", "pvalues", "p-value", "p-values", "tests"})
_SEED_DIR = re.compile(r"^seed_(-?\d+)$")

Kind = Literal["run", "experiment"]


@dataclass
class EditRow:
    """One edit of a gallery scene as the report shows it (grid units; rotation in degrees)."""

    object_id: str
    requested: tuple[float, float]
    achieved: tuple[float, float]
    rotation: float | None
    yaw_before: float
    yaw_after: float
    stop_reason: str
    blocked_by: str | None
    accepted: bool
    verified: bool | None = None
    """Whether the generator's verification passed (None: not verified or not recorded)."""
    verification: str = ""
    note: str = ""
    """Verifier's reason, validation problems, or why a step was skipped."""
    source: str = ""
    intent: str = ""
    outcome: str = ""
    """``no-op`` (changed nothing) or ``undone`` (taken back by its generator); empty otherwise."""
    kind: str = ""
    """The suggestion kind the edit answers (narrow_passage, occlude_target, ...), when recorded."""


@dataclass
class GalleryEntry:
    """One adapted scene: the renders' files, its analysis and its edits, plus reading problems."""

    scene: str
    summary: str
    before: Path | None
    after: Path | None
    analysis: Any = None
    """An :class:`adaptenv.adapt.analysis.Analysis`, or None when absent/unreadable."""
    edits: list[EditRow] = field(default_factory=list)
    generator: str = ""
    warnings: list[str] = field(default_factory=list)
    episodes: EpisodePair | None = None
    """Both houses and both trajectories, when the run recorded them (the report then draws the pair)."""


@dataclass
class EpisodePair:
    """The files of an adaptation's two episodes: pi_t in e_t and pi_t in e_{t+1}."""

    before_house: Path
    after_house: Path
    before_trajectory: Path
    after_trajectory: Path


@dataclass
class RunData:
    """A run folder: who it is (run.json), its finished iterations, and problems met while reading."""

    path: Path
    info: RunInfo | None
    iterations: list[IterationRecord]
    warnings: list[str] = field(default_factory=list)

    @property
    def label(self) -> str:
        return f"{self.info.method}, seed {self.info.seed}" if self.info else self.path.name

    @property
    def sets(self) -> list[str]:
        """Held-out set names in first-seen order."""
        return list(dict.fromkeys(k for r in self.iterations for k in r.heldout))

    @property
    def last(self) -> IterationRecord | None:
        return self.iterations[-1] if self.iterations else None


@dataclass
class ExperimentData:
    """An experiment folder: runs grouped by method, and the runner's summary.json if present."""

    path: Path
    runs: dict[str, list[RunData]]
    summary: dict[str, Any] | None = None
    pvalues: dict[tuple[str, str, str], float] = field(default_factory=dict)
    """(method, set, metric or '') -> p-value, as found in summary.json."""
    baseline: str | None = None
    """summary.json's ``baseline``: every method was compared with this one."""
    reference: str | None = None
    """summary.json's ``reference``: this method was compared with every other (runner's layout)."""
    test: str | None = None
    final: dict[str, Any] | None = None
    """summary_final.json: the final evaluation of every run's last policy (``adaptenv experiment --final-episodes``)."""
    files: list[Path] = field(default_factory=list)
    """Top-level data files to copy into the report (summary.json, CSVs)."""
    warnings: list[str] = field(default_factory=list)

    @property
    def methods(self) -> list[str]:
        return list(self.runs)

    @property
    def sets(self) -> list[str]:
        return list(dict.fromkeys(s for runs in self.runs.values() for r in runs for s in r.sets))


# --------------------------------------------------------------------------- folders

def is_run_dir(path: Path) -> bool:
    """A run folder has run.json or iterations.jsonl."""
    return (path / RUN_INFO).is_file() or (path / ITERATIONS).is_file()


def experiment_runs(path: Path) -> dict[str, list[Path]]:
    """``<method>/seed_<s>/`` run folders below ``path``, methods by name and seeds by number."""
    out: dict[str, list[Path]] = {}
    for method in sorted(p for p in path.iterdir() if p.is_dir()):
        seeds = [(int(m.group(1)), d) for d in method.iterdir()
                 if d.is_dir() and (m := _SEED_DIR.match(d.name)) and is_run_dir(d)]
        if seeds:
            out[method.name] = [d for _, d in sorted(seeds)]
    return out


def detect(path: Path) -> Kind:
    """Whether ``path`` is a run folder or an experiment folder; a one-sentence error otherwise."""
    path = Path(path)
    if not path.exists():
        raise AdaptenvError(f"{path}: no such folder; pass a run folder (with run.json) or an experiment folder")
    if not path.is_dir():
        raise AdaptenvError(f"{path}: not a folder; pass a run folder (with run.json) or an experiment folder")
    if is_run_dir(path):
        return "run"
    if experiment_runs(path):
        return "experiment"
    raise AdaptenvError(f"{path}: not a run folder (no {RUN_INFO} or {ITERATIONS}) nor an experiment folder "
                        "(no <method>/seed_<s>/ run folders); pass the folder a closed-loop run wrote")


# --------------------------------------------------------------------------- runs

def _first_line(exc: Exception) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__


def load_run(path: Path) -> RunData:
    """Read run.json and every valid line of iterations.jsonl (invalid lines become warnings)."""
    path = Path(path)
    warnings: list[str] = []
    info = None
    if (path / RUN_INFO).is_file():
        try:
            info = RunInfo.model_validate_json((path / RUN_INFO).read_text(encoding="utf-8"))
        except (ValidationError, ValueError, OSError) as exc:
            warnings.append(f"{RUN_INFO} is unreadable ({_first_line(exc)}); method and seed unknown")
    else:
        warnings.append(f"{RUN_INFO} is missing; method and seed unknown")
    iterations: list[IterationRecord] = []
    log = path / ITERATIONS
    if log.is_file():
        for n, line in enumerate(log.read_text(encoding="utf-8").splitlines(), 1):
            if not line.strip():
                continue
            try:
                iterations.append(IterationRecord.model_validate_json(line))
            except (ValidationError, ValueError) as exc:
                warnings.append(f"{ITERATIONS} line {n} skipped ({_first_line(exc)})")
    iterations.sort(key=lambda r: r.iteration)
    return RunData(path, info, iterations, warnings)


def _inside(run_dir: Path, rel: str | None) -> Path | None:
    """The file a gallery path names (relative to the run folder), or None when unset or missing."""
    if not rel:
        return None
    p = Path(rel)
    p = p if p.is_absolute() else run_dir / p
    return p if p.is_file() else None


def load_gallery(run_dir: Path, item: GalleryItem) -> GalleryEntry:
    """Resolve one gallery item's files and parse its analysis and edits (problems become warnings)."""
    entry = GalleryEntry(item.scene, item.summary, _inside(run_dir, item.before_png), _inside(run_dir, item.after_png))
    for name, rel, found in (("before render", item.before_png, entry.before), ("after render", item.after_png, entry.after)):
        if rel and found is None:
            entry.warnings.append(f"{name} {rel} is missing")
    pair = [(rel, _inside(run_dir, rel)) for rel in (item.before_house_json, item.after_house_json,
                                                      item.before_trajectory_json, item.after_trajectory_json)]
    if all(found is not None for _, found in pair):
        entry.episodes = EpisodePair(*(found for _, found in pair))
    else:
        entry.warnings += [f"{rel} is missing" for rel, found in pair if rel and found is None]
    if (p := _inside(run_dir, item.analysis_json)) is not None:
        try:
            entry.analysis = Analysis.model_validate_json(p.read_text(encoding="utf-8"))
        except (ValidationError, ValueError, OSError) as exc:
            entry.warnings.append(f"analysis {item.analysis_json} is unreadable ({_first_line(exc)})")
    elif item.analysis_json:
        entry.warnings.append(f"analysis {item.analysis_json} is missing")
    if (p := _inside(run_dir, item.edits_json)) is not None:
        try:
            entry.generator, entry.edits = parse_edits(json.loads(p.read_text(encoding="utf-8")))
        except (ValidationError, ValueError, OSError, TypeError) as exc:
            entry.warnings.append(f"edits {item.edits_json} are unreadable ({_first_line(exc)})")
    elif item.edits_json:
        entry.warnings.append(f"edits {item.edits_json} are missing")
    return entry


def _row(edit: Any, **extra: Any) -> EditRow:
    outcome = "undone" if edit.undone else "no-op" if edit.accepted and not edit.changed else ""
    return EditRow(edit.object_id, (edit.dx_units, edit.dy_units), (edit.achieved_dx_units, edit.achieved_dy_units),
                   edit.rotation, edit.yaw_before, edit.yaw_after, edit.stop_reason, edit.blocked_by, edit.accepted,
                   source=edit.source, intent=edit.intent, outcome=outcome, **extra)


def parse_edits(doc: Any) -> tuple[str, list[EditRow]]:
    """Rows of an edits.json: an ``EditLog`` (``{"edits": [...]}``) or a generator's log (``{"steps": [...]}``).

    Returns the generator name ('' when unknown) and one row per edit (per step for a generator log,
    so the verification result and the reason of skipped steps are kept).
    """
    if isinstance(doc, dict) and isinstance(doc.get("steps"), list):
        rows = []
        for raw in doc["steps"]:
            step = StepRecord.model_validate(raw)
            if step.edit is None:
                rows.append(EditRow("-", (0.0, 0.0), (0.0, 0.0), None, 0.0, 0.0, step.status, None, False,
                                    verified=step.verified, verification=step.verification, note=step.reason))
                continue
            note = step.reason or "; ".join(step.edit.problems)
            rows.append(_row(step.edit, verified=step.verified, verification=step.verification, note=note,
                             kind=step.suggestion_kind or ""))
        return str(doc.get("generator", "")), rows
    if isinstance(doc, list):
        doc = {"edits": doc}
    log = EditLog.model_validate(doc)
    rows = [_row(e, note="; ".join(e.problems)) for e in log.edits]
    return (log.edits[0].source if log.edits and all(e.source == log.edits[0].source for e in log.edits) else ""), rows


def find_path(run_dir: Path, spec: str) -> Path | None:
    """A house folder or file named in a run's config: as given, or relative to the run folder or its parents."""
    p = Path(spec)
    if p.exists():
        return p
    if p.is_absolute():
        return None
    for base in (run_dir, *run_dir.resolve().parents):
        if (base / p).exists():
            return base / p
    return None


@dataclass
class HouseSetFiles:
    """A house set of a run (training or held-out), as the config names it, and the files found."""

    name: str
    spec: str
    files: list[Path]
    note: str = ""
    """Why no files are listed (a preset, or a folder not found)."""


def house_sets(run: RunData) -> list[HouseSetFiles]:
    """The run's training set and each held-out set, with their house files when they can be found."""
    cfg = run.info.config if run.info is not None else {}
    specs = [("training", cfg.get("houses"))] + [(k, v) for k, v in (cfg.get("heldout") or {}).items()]
    out = []
    for name, spec in specs:
        if not isinstance(spec, str) or not spec:
            continue
        if spec.startswith("preset:"):
            out.append(HouseSetFiles(name, spec, [], f"the named set {spec} (regenerate with adaptenv houses "
                                                     f"generate --preset {spec.partition(':')[2]})"))
            continue
        if parse_dataset_spec(spec) is not None:
            out.append(HouseSetFiles(name, spec, [], f"the dataset {spec} (split it into house files with adaptenv "
                                                     "houses export)"))
            continue
        path = find_path(run.path, spec)
        files = sorted(path.glob("*.json")) if path is not None and path.is_dir() else [path] if path else []
        out.append(HouseSetFiles(name, spec, files, "" if files else f"{spec} was not found from here"))
    return out


@dataclass
class HeldoutFiles:
    """One held-out set's per-house table and failure renders, from the latest iteration that wrote them."""

    name: str
    iteration: int
    rows: list[dict[str, str]]
    failures: Path | None


def heldout_files(run: RunData) -> list[HeldoutFiles]:
    """Per held-out set, the latest ``iter_XXXX/heldout/<set>/houses.csv`` (and failures.png) found."""
    out = []
    for name in run.sets:
        for r in reversed(run.iterations):
            d = run.path / f"iter_{r.iteration:04d}" / HELDOUT_DIR / name
            if (d / "houses.csv").is_file():
                with (d / "houses.csv").open(encoding="utf-8", newline="") as f:
                    rows = list(csv.DictReader(f))
                failures = d / "failures.png"
                out.append(HeldoutFiles(name, r.iteration, rows, failures if failures.is_file() else None))
                break
    return out


# --------------------------------------------------------------------------- experiments

def load_experiment(path: Path) -> ExperimentData:
    """Every run of an experiment folder, and p-values from the runner's summary.json if it has any."""
    path = Path(path)
    runs = {m: [load_run(d) for d in dirs] for m, dirs in experiment_runs(path).items()}
    exp = ExperimentData(path, runs)
    exp.files = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in DATA_SUFFIXES)
    exp.files += sorted(p for m in runs for p in (path / m).iterdir() if p.is_file() and p.suffix.lower() in DATA_SUFFIXES)
    exp.summary = _read_json(path / SUMMARY, "no significance column", exp.warnings)
    if exp.summary is not None:
        exp.pvalues = find_pvalues(exp.summary, exp.methods, exp.sets)
        if isinstance(exp.summary, dict):
            exp.baseline = _text(exp.summary.get("baseline"))
            exp.reference = _text(exp.summary.get("reference"))
            for key in ("test", "significance_test"):
                if isinstance(exp.summary.get(key), str):
                    exp.test = exp.summary[key]
    final = _read_json(path / FINAL_SUMMARY, "no final evaluation shown", exp.warnings)
    if isinstance(final, dict) and isinstance(final.get("methods"), dict):
        exp.final = final
    elif final is not None:
        exp.warnings.append(f"{FINAL_SUMMARY} has no 'methods' table; no final evaluation shown")
    return exp


def _read_json(path: Path, consequence: str, warnings: list[str]) -> Any:
    """A JSON file's content; None when it is missing, or unreadable (then a warning ending in ``consequence``)."""
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, OSError) as exc:
        warnings.append(f"{path.name} is unreadable ({_first_line(exc)}); {consequence}")
        return None


def _text(x: Any) -> str | None:
    return x if isinstance(x, str) else None


def is_number(x: Any) -> bool:
    """A finite int or float (not a bool): what a figure in a summary file must be."""
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def find_pvalues(doc: Any, methods: list[str], sets: list[str]) -> dict[tuple[str, str, str], float]:
    """Every p-value in a summary document, keyed (method, set, metric); metric '' when not stated.

    A number counts as a p-value when its key, or a key above it, is ``p``/``p_value``/``pvalue``
    (plural too) or ``tests``. Method, set and metric come from ``method``/``set``/``metric`` fields
    of the enclosing objects, or from keys on the way down that equal a method name, a set name, or
    ``success``/``spl``, alone or joined by ':' (the experiment runner's ``"success:unseen"``).
    Values that cannot be placed on a method and a set are ignored (so are nulls), and so are
    p-values of other metrics (``"success_gain:unseen"``).
    """
    out: dict[tuple[str, str, str], float] = {}
    known_m, known_s = set(methods), set(sets)

    def walk(node: Any, ctx: dict[str, str], is_p: bool) -> None:
        if isinstance(node, dict):
            ctx = dict(ctx)
            for key, field_names in (("method", ("method",)), ("set", ("set", "heldout", "split", "eval_set")),
                                     ("metric", ("metric",))):
                for f in field_names:
                    if isinstance(node.get(f), str):
                        ctx[key] = node[f]
            for k, v in node.items():
                sub = dict(ctx)
                k = str(k)
                for part in k.split(":"):
                    if part in known_m:
                        sub["method"] = part
                    elif part in known_s:
                        sub["set"] = part
                    elif part.lower() in METRICS or ":" in k:  # "success_gain:unseen" names another metric
                        sub["metric"] = part.lower()
                walk(v, sub, is_p or k.lower() in _P_KEYS)
        elif isinstance(node, list):
            for v in node:
                walk(v, ctx, is_p)
        elif is_p and is_number(node) and ctx.get("method") in known_m and ctx.get("set") in known_s:
            metric = ctx.get("metric", "").lower()
            if metric in METRICS or not metric:
                out[(ctx["method"], ctx["set"], metric)] = float(node)

    walk(doc, {}, False)
    return out


@dataclass(frozen=True)
class Stat:
    """Mean and standard error over seeds (``se`` None with a single seed)."""

    mean: float
    se: float | None
    n: int


def mean_se(values: list[float]) -> Stat | None:
    """Mean and standard error of the mean (sample std / sqrt(n)); None for no values."""
    vals = [v for v in values if v is not None and math.isfinite(v)]
    if not vals:
        return None
    n = len(vals)
    mean = sum(vals) / n
    if n < 2:
        return Stat(mean, None, n)
    var = sum((v - mean) ** 2 for v in vals) / (n - 1)
    return Stat(mean, math.sqrt(var / n), n)


def last_with(run: RunData, set_name: str) -> IterationRecord | None:
    """The latest iteration that evaluated ``set_name``."""
    return next((r for r in reversed(run.iterations) if set_name in r.heldout), None)


def final_stat(runs: list[RunData], set_name: str, metric: str) -> Stat | None:
    """Mean +- SE over seeds of each run's latest figure on one held-out set."""
    vals = [getattr(r.heldout[set_name], metric) for run in runs if (r := last_with(run, set_name))]
    return mean_se(vals)


def curve(runs: list[RunData], set_name: str, metric: str) -> list[tuple[int, float, Stat]]:
    """Per iteration: (iteration, mean env steps, metric mean +- SE) over the seeds that reached it."""
    by_t: dict[int, list[IterationRecord]] = {}
    for run in runs:
        for r in run.iterations:
            if set_name in r.heldout:
                by_t.setdefault(r.iteration, []).append(r)
    out = []
    for t in sorted(by_t):
        recs = by_t[t]
        stat = mean_se([getattr(r.heldout[set_name], metric) for r in recs])
        if stat is not None:
            out.append((t, sum(r.env_steps for r in recs) / len(recs), stat))
    return out
