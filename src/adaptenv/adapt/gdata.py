"""Data for a learned G: every candidate edit the built-in and random G would try, and its measured effect.

For each house and each of a few episodes (tasks) in it, :func:`collect_task` rolls the agent out,
runs F (the built-in analyzer), draws candidate edits without rollouts
(:func:`~adaptenv.adapt.generators.edit_features.enumerate_candidates`), dry-runs each through
collision-aware placement and validation (with the plausibility rules), and rolls the agent out on
the same ``episodes`` paired episodes (the task's start and target, headings spread evenly) in the
house before and after every candidate that validation accepted and the shortest-path expert still
solves (``episodes=0``: no rollout after F's). Those candidates also carry the built-in G's route
objectives before and after the edit (:func:`~adaptenv.adapt.objectives.measure`: no rollout, and no
sampling noise). One :class:`dict` row per candidate; :data:`SCHEMA` names the format, and docs/adapt.md
("Data for a learned G") lists its fields.

:class:`Dataset` is the folder ``adaptenv gdata collect`` writes: ``edits.jsonl.gz`` (the rows, one
gzip member per house, appended), ``houses.jsonl`` (one line per finished house) and ``meta.json``
(the settings and the feature names). A run continues where it stopped: finished houses are skipped,
and rows of a house that did not finish are dropped (the file is rewritten to a temporary name and
renamed over it).
"""

from __future__ import annotations

import gzip
import hashlib
import json
import os
import time
import zlib
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from adaptenv.adapt.analysis import Analysis, BuiltinAnalyzer
from adaptenv.adapt.generators._trial import moved_geometry
from adaptenv.adapt.generators.base import house_object_types
from adaptenv.adapt.generators.edit_features import (
    FEATURE_NAMES,
    RANDOM_SHARE,
    Scene,
    candidate_features,
    enumerate_candidates,
)
from adaptenv.adapt.objectives import RouteSpec, measure
from adaptenv.adapt.validation import EditValidator
from adaptenv.agents.policy import Policy, as_policy
from adaptenv.agents.rollout import checking_episodes, draw_episode, rollout, run_in_worlds
from adaptenv.errors import ConfigError
from adaptenv.files import atomic_path, atomic_write_text, open_append
from adaptenv.scene.house import House
from adaptenv.sim.rollout import expert_policy, run_episode
from adaptenv.sim.world import compile_world

SCHEMA = "adaptenv-gdata/1"
ROWS, HOUSES, META = "edits.jsonl.gz", "houses.jsonl", "meta.json"


@dataclass(frozen=True)
class CollectConfig:
    """How much to collect per house: tasks (F's episodes), candidates per task, paired episodes per edit (0: the
    route objectives only, no agent rollout per edit), and the share of the candidates drawn as random moves."""

    tasks: int = 2
    candidates: int = 24
    episodes: int = 3
    seed: int = 0
    random_share: float = RANDOM_SHARE


def house_sha256(house: House) -> str:
    """The SHA-256 of a house's JSON (how a row's house reference is checked when the house is rebuilt)."""
    return hashlib.sha256(house.model_dump_json().encode("utf-8")).hexdigest()


def house_seed(seed: int, name: str) -> list[int]:
    """The seed words of one house's draws: the run's seed and the house's name (not its place in the set)."""
    return [int(seed), zlib.crc32(name.encode("utf-8"))]


def compact_analysis(a: Analysis) -> dict[str, Any]:
    """F's analysis as a row stores it: outcome, the worst severity per concern kind, priority per suggestion kind."""
    concerns: dict[str, float] = {}
    for c in a.concerns:
        concerns[c.kind] = max(concerns.get(c.kind, 0.0), round(float(c.severity), 4))
    suggestions: dict[str, float] = {}
    for s in a.suggestions:
        suggestions[s.kind] = max(suggestions.get(s.kind, 0.0), round(float(s.priority), 4))
    o = a.outcome
    return {"success": o.success, "failure_mode": o.failure_mode, "spl": o.spl, "steps": o.steps,
            "concerns": concerns, "suggestions": suggestions}


def _split(problems) -> tuple[list[str], list[str]]:
    """(validation problem kinds, plausibility rules broken) of a proposal's problems."""
    kinds, rules = [], []
    for p in problems:
        if p.kind == "implausible":
            rules.append(p.rule)
        else:
            kinds.append(p.kind)
    return kinds, rules


def _mean(trajs, field: str) -> float:
    return round(float(np.mean([float(getattr(t.metrics, field)) for t in trajs])), 6)


def collect_task(house: House, ref: dict[str, Any], task: int, policy: Policy, cfg: CollectConfig,
                 rng: np.random.Generator) -> list[dict[str, Any]]:
    """The rows of one task in one house: every candidate edit with its placement, validation, audit and effect."""
    world = compile_world(house, ref["name"])
    ep = draw_episode(world, rng)
    before = rollout(world, ep, policy)
    analysis = BuiltinAnalyzer().analyze(before, world)
    v = EditValidator(house, episode_targets=[ep.target_type], start=ep.start[:2])
    route = RouteSpec.from_episode(ep.target_type, ep.start, before)
    scene = Scene.of(v, world, route)
    cands = enumerate_candidates(v, world, route, rng, cfg.candidates, scene=scene, random_share=cfg.random_share)
    feats = candidate_features(v, scene, cands, analysis)
    types, expert = house_object_types(house), expert_policy()
    objectives_before = measure(world, route).as_dict()
    rows, worlds, measured = [], [], []
    for k, c in enumerate(cands):
        p = v.propose(c.object_id, c.dx_units, c.dy_units, c.rotation, relocate=c.relocate)
        res = p.result
        kinds, rules = _split(p.problems)
        accepted = not kinds and res.changed
        solved = None
        if accepted:
            cw = compile_world(v.house, "candidate", geometry=moved_geometry(v.geometry, res))
            solved = bool(run_episode(cw, ep, expert, record=False).metrics.success)
            if solved:
                worlds.append(cw)
                measured.append(k)
        rows.append({
            "schema": SCHEMA, "house": ref, "task": task, "candidate": k,
            "episode": {"target_type": ep.target_type, "start": [round(float(s), 6) for s in ep.start],
                        "seed": ep.seed},
            "policy": getattr(policy, "name", type(policy).__name__), "analysis": compact_analysis(analysis),
            "edit": {"object_id": c.object_id, "object_type": types.get(c.object_id), "dx_units": c.dx_units,
                     "dy_units": c.dy_units, "rotation": c.rotation, "relocate": c.relocate, "kind": c.kind,
                     "generator": "random" if c.kind == "random" else "builtin"},
            "placement": {"changed": bool(res.changed), "stop_reason": res.stop_reason, "blocked_by": res.blocked_by,
                          "achieved_dx_units": round(float(res.achieved_units[0]), 4),
                          "achieved_dy_units": round(float(res.achieved_units[1]), 4),
                          "yaw_before": round(float(res.yaw_before), 3), "yaw_after": round(float(res.yaw_after), 3)},
            "accepted": accepted, "problems": kinds, "plausibility": rules, "plausible": not rules,
            "expert_success": solved, "effect": None,
            "objectives": {"before": objectives_before, "after": measure(cw, route).as_dict()} if solved else None,
            "features": [round(float(x), 5) for x in feats[k]],
        })
    if cfg.episodes == 0:
        return rows
    episodes = checking_episodes(ep, cfg.episodes)
    runs = run_in_worlds([world, *worlds], episodes, policy)
    base = {"episodes": len(episodes), "success_before": _mean(runs[0], "success"), "spl_before": _mean(runs[0], "spl")}
    for k, trajs in zip(measured, runs[1:], strict=True):
        eff = {**base, "success_after": _mean(trajs, "success"), "spl_after": _mean(trajs, "spl")}
        eff["success_drop"] = round(eff["success_before"] - eff["success_after"], 6)
        eff["spl_drop"] = round(eff["spl_before"] - eff["spl_after"], 6)
        rows[k]["effect"] = eff
    return rows


def collect_house(house: House, ref: dict[str, Any], policy: Policy, cfg: CollectConfig) -> list[dict[str, Any]]:
    """Every task's rows for one house (its draws are seeded by the run's seed and the house's name)."""
    policy = as_policy(policy)
    rng = np.random.default_rng(house_seed(cfg.seed, ref["name"]))
    return [row for t in range(cfg.tasks) for row in collect_task(house, ref, t, policy, cfg, rng)]


# --------------------------------------------------------------------------- the dataset folder
class Dataset:
    """The folder of one collection: rows (``edits.jsonl.gz``), finished houses (``houses.jsonl``), ``meta.json``."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)

    @property
    def rows_path(self) -> Path:
        return self.folder / ROWS

    def meta(self) -> dict[str, Any] | None:
        """The run's settings, or None for a new folder."""
        p = self.folder / META
        return json.loads(p.read_text(encoding="utf-8")) if p.is_file() else None

    def start(self, settings: dict[str, Any], command: str = "") -> set[str]:
        """Begin or continue a run with ``settings``: returns the keys of the houses already finished.

        A folder begun with other settings is refused; rows of houses that did not finish are dropped. ``command``
        (the command line that began it) is kept in ``meta.json``."""
        self.folder.mkdir(parents=True, exist_ok=True)
        old = self.meta()
        if old is not None and isinstance(old.get("collect"), dict):  # a setting added later: begun with its default
            old["collect"] = {**asdict(CollectConfig()), **old["collect"]}
        settings = {**settings, "schema": SCHEMA, "features": list(FEATURE_NAMES)}
        if old is not None and {k: old.get(k) for k in settings} != settings:
            diff = next(k for k in settings if old.get(k) != settings[k])
            raise ConfigError(f"{self.folder}: a collection with other settings ({diff}: {old.get(diff)!r}, now "
                              f"{settings[diff]!r}); pass the same settings to continue it, or a new -o")
        if old is None:
            atomic_write_text(self.folder / META, json.dumps({**settings, "command": command}, indent=1) + "\n")
        done = self.finished()
        self._drop_unfinished(done)
        return set(done)

    def finished(self) -> dict[str, dict[str, Any]]:
        """House key -> its line in ``houses.jsonl`` (a torn last line is ignored)."""
        p, out = self.folder / HOUSES, {}
        if p.is_file():
            for line in p.read_text(encoding="utf-8").splitlines():
                try:
                    doc = json.loads(line)
                except ValueError:
                    continue
                out[doc["key"]] = doc
        return out

    def _drop_unfinished(self, done: dict[str, dict[str, Any]]) -> None:
        """Rewrite the rows without those of unfinished houses (and a torn last member), when there are any."""
        if not self.rows_path.is_file():
            return
        rows, clean = [], True
        for row in iter_rows(self.rows_path, tolerant=True, status=(flag := [])):
            if house_key(row["house"]) in done:
                rows.append(row)
            else:
                clean = False
        if clean and not flag:
            return
        with atomic_path(self.rows_path) as tmp, gzip.open(tmp, "wt", encoding="utf-8") as f:
            f.writelines(json.dumps(r) + "\n" for r in rows)

    def append(self, key: str, rows: list[dict[str, Any]], seconds: float) -> None:
        """Add one finished house: its rows as one gzip member, then its line in ``houses.jsonl``."""
        data = gzip.compress("".join(json.dumps(r) + "\n" for r in rows).encode("utf-8"), mtime=0)
        with open_append(self.rows_path, binary=True) as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        line = {"key": key, "rows": len(rows), "accepted": sum(r["accepted"] for r in rows),
                "measured": sum(r["effect"] is not None for r in rows), "seconds": round(seconds, 2)}
        with open_append(self.folder / HOUSES) as f:
            f.write(json.dumps(line) + "\n")


def house_key(ref: dict[str, Any]) -> str:
    """The key of a house reference: its set spec and name."""
    return f"{ref['spec']}#{ref['name']}"


def iter_rows(path: Path, *, tolerant: bool = False, status: list | None = None) -> Iterator[dict[str, Any]]:
    """The rows of an ``edits.jsonl.gz``; with ``tolerant`` a torn end (an interrupted append) ends the rows and is
    noted in ``status``."""
    try:
        with gzip.open(path, "rt", encoding="utf-8") as f:
            for line in f:
                if line.endswith("\n"):
                    yield json.loads(line)
                elif tolerant and status is not None:
                    status.append("torn")
    except (EOFError, gzip.BadGzipFile, zlib.error, ValueError) as exc:
        if not tolerant:
            raise ConfigError(f"{path}: not a readable {ROWS} ({type(exc).__name__}); collect it again with "
                              "`adaptenv gdata collect`") from None
        if status is not None:
            status.append("torn")


def load_rows(folder: Path) -> list[dict[str, Any]]:
    """Every row of a collection folder (or an ``edits.jsonl.gz`` file); one-line errors for anything else."""
    p = Path(folder)
    path = p / ROWS if p.is_dir() else p
    if not path.is_file():
        raise ConfigError(f"{p}: no {ROWS} there; collect one with `adaptenv gdata collect -o {p}`")
    return list(iter_rows(path))


def run_settings(policy: Policy, cfg: CollectConfig) -> dict[str, Any]:
    """What a collection folder is begun with and must be continued with: the settings and the agent's name."""
    return {"collect": asdict(cfg), "policy": getattr(policy, "name", type(policy).__name__)}


def collect(houses: list[tuple[House, dict[str, Any]]], policy: Policy, cfg: CollectConfig, folder: Path, *,
            progress=None, command: str = "") -> dict[str, Any]:
    """Collect every house not finished yet into ``folder`` (resuming a run); returns counts of the whole dataset."""
    ds = Dataset(folder)
    done = ds.start(run_settings(policy, cfg), command)
    policy = as_policy(policy)
    for house, ref in houses:
        key = house_key(ref)
        if key not in done:
            t0 = time.perf_counter()
            ds.append(key, collect_house(house, ref, policy, cfg), time.perf_counter() - t0)
        if progress is not None:
            progress(key)
    fin = ds.finished()
    return {"houses": len(fin), "rows": sum(d["rows"] for d in fin.values()),
            "accepted": sum(d["accepted"] for d in fin.values()), "measured": sum(d["measured"] for d in fin.values())}


__all__ = ["SCHEMA", "CollectConfig", "Dataset", "collect", "collect_house", "collect_task", "house_key", "house_sha256",
           "iter_rows", "load_rows", "run_settings"]
