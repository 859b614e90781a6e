"""What a closed-loop run writes to disk: typed records and the run folder layout.

The loop writes, the report reads; both go through these models, so the layout lives here only::

    RUN_DIR/
      run.json                      RunInfo: method, seed, config, command, skipped (unusable) houses
      iterations.jsonl              one IterationRecord per finished iteration (append-only)
      iterations.csv                the same figures, flat, for spreadsheets
      iter_0001/
        heldout/<set>/houses.csv    pi_{t+1}'s held-out results per house
        gallery/<scene>/            before.png, after.png, analysis.json, edits.json (adapted scenes),
                                    and when recorded both houses and both trajectories
        scenes/<scene>.json         training scenes e_{t+1} produced this iteration
        policy.pt                   pi_{t+1}
      state.json                    resume point (written last, atomically)

An experiment folder holds one run folder per (method, seed): ``EXP_DIR/<method>/seed_<s>/``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Any

from pydantic import BaseModel, Field, ValidationError, field_validator

from adaptenv.configfile import field_path
from adaptenv.curriculum.buffer import level_id_problem
from adaptenv.errors import ConfigError
from adaptenv.files import atomic_write_text
from adaptenv.scene.house import House, load_house, save_house
from adaptenv.sim.world import NavWorld, compile_world

RUN_INFO = "run.json"
ITERATIONS = "iterations.jsonl"
ITERATIONS_CSV = "iterations.csv"
STATE = "state.json"
HELDOUT_DIR = "heldout"
"""``iter_XXXX/heldout/<set>/``: per-house results of that iteration's held-out evaluation, in the
layout ``adaptenv evaluate`` writes (houses.csv; failures.png when failed episodes were recorded)."""


def iteration_dir(run_dir: Path, t: int) -> Path:
    """Folder of iteration ``t`` (1-based)."""
    return Path(run_dir) / f"iter_{t:04d}"


class SetMetrics(BaseModel):
    """Mean figures of a policy on one house set."""

    success: float
    spl: float
    collisions: float
    episodes: int
    success_se: float | None = 0.0
    """Standard error of ``success``; None when undefined (a single episode)."""
    spl_se: float | None = 0.0

    @field_validator("success_se", "spl_se", mode="before")
    @classmethod
    def _undefined_is_none(cls, v: object) -> object:
        """NaN (one episode: no standard error) is stored and read back as None."""
        return None if isinstance(v, float) and not math.isfinite(v) else v


class GalleryItem(BaseModel):
    """One adapted scene of an iteration, with paths relative to the run folder.

    With both houses and both trajectories recorded, the report draws the pair itself
    (:func:`adaptenv.render.compare.render_before_after`) and states what changed; the PNGs are
    then only a fallback.
    """

    scene: str
    before_png: str | None = None
    after_png: str | None = None
    analysis_json: str | None = None
    edits_json: str | None = None
    summary: str = ""
    before_house_json: str | None = None
    """e_t, the house pi_t was rolled out in."""
    after_house_json: str | None = None
    """e_{t+1}, the edited house."""
    before_trajectory_json: str | None = None
    """pi_t's episode in e_t (the one F analysed)."""
    after_trajectory_json: str | None = None
    """pi_t's own episode in e_{t+1}, same start and target."""

    @field_validator("scene")
    @classmethod
    def _plain_scene(cls, v: str) -> str:
        """The scene is a level of this run: a plain name, never a path out of the run folder."""
        if (problem := level_id_problem(v)) is not None:
            raise ValueError(problem)
        return v

    @field_validator("before_png", "after_png", "analysis_json", "edits_json", "before_house_json",
                     "after_house_json", "before_trajectory_json", "after_trajectory_json")
    @classmethod
    def _inside_run(cls, v: str | None) -> str | None:
        """Each file is the run's own: a relative path inside the run folder."""
        if v is not None and (PurePosixPath(v).is_absolute() or PureWindowsPath(v).anchor or "\0" in v
                              or ".." in PurePosixPath(v.replace("\\", "/")).parts):
            raise ValueError(f"path {v!r} is not a file inside the run folder (a relative path, no '..')")
        return v


class IterationRecord(BaseModel):
    """Figures of one finished iteration t (policy pi_t evaluated, e_{t+1} generated, pi_{t+1} trained)."""

    iteration: int
    env_steps: int
    """Environment steps used so far (scoring and diagnosis rollouts, G's checks, training frames), cumulative."""
    grad_updates: int
    """Gradient updates so far, cumulative."""
    edits: int
    """Scene edits applied so far, cumulative."""
    train: SetMetrics | None = None
    """pi_t on the current training scenes."""
    heldout: dict[str, SetMetrics] = Field(default_factory=dict)
    """pi_{t+1} on each held-out set (e.g. 'rearranged', 'unseen')."""
    gallery: list[GalleryItem] = Field(default_factory=list)
    wall_time_s: float = 0.0
    stage_seconds: dict[str, float] = Field(default_factory=dict)
    """Wall time of this iteration's stages: rollouts, scenes (buffer and generation), finetune, evaluate."""
    llm_usage: dict[str, Any] | None = None
    """LLM tokens, calls, retries, cache hits (and cost when priced) of this iteration, per role (ours-llm)."""


class SkippedHouses(BaseModel):
    """The houses of one house set (``--houses`` or a held-out spec) that could not be used and were skipped."""

    count: int = 0
    houses: dict[str, str] = Field(default_factory=dict)
    """House name -> why it cannot be used (one sentence)."""


class RunInfo(BaseModel):
    """Which method and seed a run is, the config it ran with, and the houses its sets skipped."""

    method: str
    seed: int
    config: dict[str, Any] = Field(default_factory=dict)
    command: str = ""
    skipped_houses: dict[str, SkippedHouses] = Field(default_factory=dict)
    """Per house-set spec (training houses and held-out sets), the unusable houses left out of it."""
    weights: dict[str, str] | None = None
    """pi_0's weights: the ``--policy`` name, its file and sha256 (None for a run written before they were kept)."""
    finetune_precision: str | None = None
    """The arithmetic fine-tuning's gradient steps used on the machine that ran it (``auto`` resolved: fp32 or bf16;
    None for a run written before it was kept)."""


def read_iterations(run_dir: Path) -> list[IterationRecord]:
    """Every finished iteration of a run, in order (empty when none)."""
    p = Path(run_dir) / ITERATIONS
    if not p.exists():
        return []
    try:
        lines = p.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: cannot read the iteration log ({exc}); restore it, or run again in a new folder") from None
    records = []
    for n, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            records.append(IterationRecord.model_validate_json(line))
        except ValidationError as exc:
            err = exc.errors()[0]
            where = field_path(tuple(err.get("loc", ()))) or "the line"
            raise ConfigError(f"{p}: line {n} is not an iteration record the loop wrote (at {where}: {err['msg']}); "
                              "restore the file, or run again in a new folder") from None
    return records


def write_iterations(run_dir: Path, records: list[IterationRecord]) -> None:
    """Rewrite the iteration log (JSON lines and CSV) atomically."""
    run_dir = Path(run_dir)
    atomic_write_text(run_dir / ITERATIONS, "".join(r.model_dump_json() + "\n" for r in records))
    atomic_write_text(run_dir / ITERATIONS_CSV, _csv(records))


def _csv(records: list[IterationRecord]) -> str:
    sets = sorted({k for r in records for k in r.heldout})
    cols = ["iteration", "env_steps", "grad_updates", "edits", "train_success", "train_spl"]
    for s in sets:
        cols += [f"{s}_success", f"{s}_spl", f"{s}_collisions"]
    lines = [",".join(cols)]
    for r in records:
        row: list[Any] = [r.iteration, r.env_steps, r.grad_updates, r.edits,
                          r.train.success if r.train else "", r.train.spl if r.train else ""]
        for s in sets:
            m = r.heldout.get(s)
            row += [m.success, m.spl, m.collisions] if m else ["", "", ""]
        lines.append(",".join(f"{v:.6g}" if isinstance(v, float) else str(v) for v in row))
    return "\n".join(lines) + "\n"


#: Subfolder of a scene store holding each scene's ``task_targets`` (when it has any).
TASKS = "tasks"


class SceneStore:
    """Scenes of a run by name, on disk (RUN_DIR/scenes/NAME.json) with an in-memory cache."""

    def __init__(self, root: Path):
        self.root = root
        self.root.mkdir(parents=True, exist_ok=True)
        self._houses: dict[str, House] = {}
        self._worlds: dict[str, NavWorld] = {}

    def _file(self, name: str) -> Path:
        """Scene ``name``'s house file, inside the store (ConfigError for a name that is not a plain one)."""
        if (problem := level_id_problem(name)) is not None:
            raise ConfigError(f"{self.root}: {problem}; restore the run's state, or run again in a new folder")
        return self.root / f"{name}.json"

    def put(self, name: str, house: House, task_targets: tuple[str, ...] = ()) -> str:
        """Save ``house`` as scene ``name`` (and the target types its training episodes ask for, if any); returns the name."""
        path = self._file(name)
        save_house(house, path)
        if task_targets:  # beside, not among, the house files (a scenes folder stays a valid --houses folder)
            (self.root / TASKS).mkdir(exist_ok=True)
            atomic_write_text(self.root / TASKS / f"{name}.json", json.dumps({"task_targets": list(task_targets)}))
        self._houses[name] = house
        self._worlds.pop(name, None)
        return name

    def house(self, name: str) -> House:
        if name not in self._houses:
            self._houses[name] = load_house(self._file(name), validate=False)
        return self._houses[name]

    def world(self, name: str) -> NavWorld:
        """The scene compiled for the simulator, with the target types saved by :meth:`put`."""
        if name not in self._worlds:
            world = compile_world(self.house(name), name)
            task = self.root / TASKS / f"{name}.json"
            if task.is_file():
                world.task_targets = tuple(json.loads(task.read_text(encoding="utf-8"))["task_targets"])
            self._worlds[name] = world
        return self._worlds[name]
