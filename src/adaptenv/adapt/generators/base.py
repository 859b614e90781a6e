"""What every generator shares: the :class:`Generator` interface, its context and result records.

The generator modules (``builtin``, ``llm``, ``random_perturbation``, ``failure_modes``) build on
this module; :mod:`adaptenv.adapt.generators` re-exports its names with :func:`make_generator`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Protocol, runtime_checkable

import numpy as np
from pydantic import BaseModel, Field

from adaptenv.adapt.edits import Edit, EditLog
from adaptenv.adapt.llm.usage import Prices, Usage
from adaptenv.adapt.placement import PlacementContext
from adaptenv.adapt.placement_model import PlacementModel
from adaptenv.render.topdown import png_bytes, render_house, save_render
from adaptenv.scene.assets import object_types

if TYPE_CHECKING:
    from PIL import Image

    from adaptenv.adapt.analysis import Analysis
    from adaptenv.adapt.diagnosis import SceneDiagnosis
    from adaptenv.agents.policy import Policy
    from adaptenv.scene.house import House
    from adaptenv.sim.task import Episode
    from adaptenv.sim.trajectory import Trajectory
    from adaptenv.sim.world import NavWorld

StepStatus = Literal["applied", "rejected", "skipped", "no-op"]
"""``applied``: the step's edit is in the house. ``rejected``: validation refused it. ``skipped``: no
edit was made (no usable answer, or the step was aborted and its edit undone). ``no-op``: placement
accepted a move that changed neither position nor heading (never counted as applied or verified)."""
GENERATORS = ("builtin", "llm", "random", "failure-modes", "learned")


class StepRecord(BaseModel):
    """One generation step: what was targeted, what was applied, and whether verification passed."""

    step: int
    status: StepStatus
    suggestion_id: str | None = None
    suggestion_kind: str | None = None
    edit: Edit | None = None
    """The edit kept for this step (None when skipped)."""
    reason: str = ""
    """Why a step was skipped or rejected, or the verifier's reason."""
    verified: bool | None = None
    """Whether verification passed (None: not verified)."""
    verification: str = "none"
    """How it was verified: ``objective``, ``llm`` or ``none``."""
    revisions: int = 0
    """Revisions taken after the first attempt."""
    attempts: int = 1
    """Proposals requested for this step (LLM answers, including invalid ones)."""
    candidates: int = 0
    """Candidate moves drawn (built-in)."""
    passed: int = 0
    """Candidates that passed their dry run (placement, validation, the expert's check) and were scored (built-in)."""
    checked: int = 0
    """Candidates pi_t's rollouts checked (built-in, with a policy)."""
    objective_before: dict[str, float | None] = Field(default_factory=dict)
    objective_after: dict[str, float | None] = Field(default_factory=dict)
    gain: float | None = None
    """Gain of the targeted objective (positive = harder as intended)."""
    policy_score_before: float | None = None
    policy_score_after: float | None = None
    """Mean SPL of the policy on the checking episodes before/after the edit (when checked)."""
    check_steps: int = 0
    """pi_t's environment steps in this step's rollout checks (counted in the loop's env-step budget)."""
    render: str | None = None
    """File of the render after this step, when written."""
    failure_mode: str | None = None
    """The failure family the step aimed at (``failure-modes`` generator), e.g. ``search``."""
    produced_failure: bool | None = None
    """Whether pi_t's rollout on the chosen edit failed with that family (None: not checked)."""


@dataclass
class GenerationContext:
    """What a generator knows besides the house and the analysis: the episode and (optionally) the agent."""

    episode: Episode
    trajectory: Trajectory | None = None
    """The rollout F analysed; its route feeds the objectives and is drawn on the renders."""
    policy: Policy | None = None
    """pi_t: the built-in G checks its best candidate edits with its rollouts; None skips the check."""
    rollout_episodes: int = 3
    """Episodes per rollout check (the same start and target, different initial headings)."""
    render: bool = True
    """Re-render after every edit (the LLM generator always does)."""
    render_size: int = 768
    out_dir: Path | None = None
    """When set, renders are written here as ``step-XX.png``."""
    diagnosis: SceneDiagnosis | None = None
    """F's multi-episode diagnosis of the scene, when there is one (the ``failure-modes`` G aims at its families)."""
    world: NavWorld | None = None
    """The compiled world of the house being edited, when the caller has it (``compile_world(house)``): generators
    start from it instead of compiling the house again."""
    placement_model: PlacementModel | None = None
    """The reference of the plausibility rule ``unlike_reference`` (:mod:`adaptenv.adapt.placement_model`): None
    for the shipped one; ``PlacementModel({})`` has no range, so that rule refuses nothing."""


@dataclass
class GenerationResult:
    """Everything a generation run produced."""

    house: House
    steps: list[StepRecord]
    edit_log: EditLog
    generator: str
    renders: list[Image.Image] = field(default_factory=list)
    render_paths: list[Path] = field(default_factory=list)
    usage: Usage = field(default_factory=Usage)
    """LLM calls of this generation (empty for the offline generators)."""
    prices: Prices | None = None
    """Token prices for cost estimates in the written log (None: no cost shown)."""
    llm: dict[str, Any] | None = None
    """Provider, API, model, base URL, prompt set and temperature of the LLM used (never the key)."""
    stopped: str = ""
    """Why generation ended before ``steps`` steps (LLM unavailable, budget used up), else empty."""
    objective_trace: list[dict[str, float | None]] = field(default_factory=list)
    """Objective values before the first step and after every step."""
    world: NavWorld | None = None
    """The compiled world of ``house`` as generation left it, when the generator has it (None: compile it)."""

    @property
    def applied(self) -> list[Edit]:
        return [s.edit for s in self.steps if s.status == "applied" and s.edit is not None]

    def to_json_dict(self) -> dict[str, Any]:
        """The log written next to a run: steps, every tried edit (its object's type beside its id, as
        ProcTHOR-100K ids such as ``6|1|3`` do not name it), usage, objective trace."""
        types = house_object_types(self.house)
        steps = [s.model_dump(mode="json") for s in self.steps]
        edits = self.edit_log.model_dump(mode="json")["edits"]
        for edit in [s["edit"] for s in steps if s.get("edit")] + edits:
            edit["object_type"] = types.get(edit["object_id"])
        return {"generator": self.generator, "llm": self.llm, "stopped": self.stopped, "steps": steps,
                "edit_log": edits, "usage": self.usage.to_dict(self.prices), "objective_trace": self.objective_trace}


def house_object_types(house: House) -> dict[str, str | None]:
    """Object id -> object type of a house's objects, children and doors (None for an unknown asset)."""
    return object_types([*(o for o, _ in house.iter_objects()), *house.doors])


@runtime_checkable
class Generator(Protocol):
    """The paper's G: ``(house, analysis) -> edited house`` in ``steps`` single-object edits."""

    name: str

    def generate(self, house: House, analysis: Analysis, *, steps: int, context: GenerationContext,
                 rng: np.random.Generator) -> GenerationResult:
        """Edit a copy of ``house``; never modifies the input."""
        ...


def render_scene(house: House, context: GenerationContext, *, highlight: dict[str, str] | None = None,
                 title: str | None = None) -> Image.Image:
    """The top-down render with the normalized grid and the analysed trajectory (if any)."""
    return render_house(house, trajectory=context.trajectory, grid=True, size=context.render_size,
                        highlight=highlight, title=title)


def keep_render(result: GenerationResult, image: Image.Image, context: GenerationContext, step: int) -> str | None:
    """Store a render in the result (and on disk when ``context.out_dir`` is set); returns the file name."""
    result.renders.append(image)
    if context.out_dir is None:
        return None
    path = save_render(image, Path(context.out_dir) / f"step-{step:02d}.png")
    result.render_paths.append(path)
    return str(path)


def movable_ids(house: House) -> list[str]:
    """Ids of the top-level floor objects placement may move (the LLM's allowed ids)."""
    ctx = PlacementContext.from_house(house)
    return [oid for oid, m in zip(ctx.ids, ctx.movable, strict=True) if m]


__all__ = ["GENERATORS", "GenerationContext", "GenerationResult", "Generator", "StepRecord", "StepStatus",
           "keep_render", "movable_ids", "png_bytes", "render_scene"]
