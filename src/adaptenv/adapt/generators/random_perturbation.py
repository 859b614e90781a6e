"""Random perturbation, the paper's comparison point, and random single edits for ACCEL-style baselines.

:class:`RandomPerturbation` ignores the analysis: every movable object (in a random order) gets a
random displacement (uniform direction, length uniform in ``0..max_units`` grid units) and a
random absolute yaw, each through the same collision-aware placement and validation as the other
generators (a rejected move leaves the object where it was), but without the plausibility rules
of :mod:`adaptenv.adapt.plausibility` and with the targets movable: it is the baseline those rules
are measured against. ``steps`` is not used: one pass over all movable objects is one perturbation.

:func:`random_single_edits` makes ``k`` accepted random single-object edits (each validated),
the analogue of ACCEL's k random level edits (random too: no plausibility rules, targets movable); with
``appearance`` > 0 that share of them are appearance edits instead (an asset swapped within its type and split,
or a room's floor or walls given another material: :mod:`adaptenv.adapt.appearance`).
"""

from __future__ import annotations

import numpy as np

from adaptenv.adapt.analysis import Analysis
from adaptenv.adapt.appearance import random_appearance_edit
from adaptenv.adapt.edits import Edit, EditLog
from adaptenv.adapt.generators.base import (
    GenerationContext,
    GenerationResult,
    StepRecord,
    keep_render,
    render_scene,
)
from adaptenv.adapt.validation import EditValidator, Start
from adaptenv.scene.house import House

#: Default largest displacement of one object (grid units).
MAX_UNITS = 15.0


def random_move(rng: np.random.Generator, max_units: float, rotate_p: float = 1.0) -> tuple[float, float, float | None]:
    """(dx, dy, absolute yaw or None): a uniform direction, a length uniform in 0..max_units."""
    angle = float(rng.uniform(0.0, 2.0 * np.pi))
    length = float(rng.uniform(0.0, max_units))
    yaw = float(rng.uniform(0.0, 360.0)) if rng.random() < rotate_p else None
    return length * float(np.cos(angle)), length * float(np.sin(angle)), yaw


def _movable(v: EditValidator) -> list[str]:
    return [oid for oid, m in zip(v.ctx.ids, v.ctx.movable, strict=True) if m]


class RandomPerturbation:
    """Displace and rotate every movable object at random (validated); the paper's baseline."""

    name = "random"

    def __init__(self, *, max_units: float = MAX_UNITS, rotate_p: float = 1.0):
        self.max_units = max_units
        self.rotate_p = rotate_p

    def generate(self, house: House, analysis: Analysis | None, *, steps: int, context: GenerationContext,
                 rng: np.random.Generator) -> GenerationResult:
        ep = context.episode
        v = EditValidator(house, episode_targets=[ep.target_type], start=ep.start[:2], plausibility=False,
                          move_targets=True)
        result = GenerationResult(house=v.house, steps=[], edit_log=v.log, generator=self.name)
        ids = _movable(v)
        for step, k in enumerate(rng.permutation(len(ids))):
            dx, dy, yaw = random_move(rng, self.max_units, self.rotate_p)
            edit = v.try_edit(ids[int(k)], dx, dy, yaw, source=self.name, intent="random perturbation")
            status = "rejected" if not edit.accepted else "applied" if edit.changed else "no-op"
            reason = "; ".join(edit.problems) or ("the move changed neither position nor heading"
                                                  if status == "no-op" else "")
            result.steps.append(StepRecord(step=step, status=status, edit=edit, reason=reason))
        if context.render:
            keep_render(result, render_scene(v.house, context), context, 0)
        result.house = v.house
        return result


def random_single_edits(house: House, k: int, rng: np.random.Generator, *, episode_targets: list[str] | None = None,
                        start: Start | None = None, max_units: float = 30.0, max_tries: int = 20,
                        appearance: float = 0.0) -> tuple[House, EditLog]:
    """``k`` accepted random single-object edits (each validated; up to ``max_tries`` proposals per edit).

    Each proposal is, with probability ``appearance``, an appearance edit (asset swap or material change) instead
    of a move (0, the default, draws exactly the moves it always did). Returns the edited copy and the log of
    every proposal (rejected ones marked). Fewer than ``k`` edits are made only when ``max_tries`` proposals in a
    row are rejected.
    """
    v = EditValidator(house, episode_targets=episode_targets, start=start, plausibility=False, move_targets=True)
    ids = _movable(v)
    if not ids and not appearance:
        return v.house, v.log
    for _ in range(k):
        for _ in range(max_tries):
            edit: Edit | None
            if appearance and (not ids or rng.random() < appearance):
                edit = random_appearance_edit(v, rng, source="random-single", intent="random appearance edit")
            else:
                dx, dy, yaw = random_move(rng, max_units, rotate_p=0.5)
                edit = v.try_edit(ids[int(rng.integers(len(ids)))], dx, dy, yaw, source="random-single",
                                  intent="ACCEL-style random edit")
            if edit is not None and edit.accepted and edit.changed:
                break
    return v.house, v.log
