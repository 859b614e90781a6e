"""The generator G: turn an analysis into k single-object edits of a house, one interface, three kinds.

Every generator implements :class:`Generator`::

    result = generator.generate(house, analysis, steps=5, context=ctx, rng=np.random.default_rng(0))

and returns a :class:`GenerationResult`: the edited house, one :class:`StepRecord` per step (the
edit, verification outcome, revisions, objective before/after), the full
:class:`~adaptenv.adapt.edits.EditLog` (rejected tries included), the renders after each edit,
token usage (LLM) and the objective trace.

- ``builtin`` (:class:`~adaptenv.adapt.generators.builtin.BuiltinGenerator`, default, offline,
  deterministic): suggestions become objectives, candidate moves are searched and scored.
- ``llm`` (:class:`~adaptenv.adapt.generators.llm.LLMGenerator`): the paper's procedure, one tool
  call per edit, with verification.
- ``random`` (:class:`~adaptenv.adapt.generators.random_perturbation.RandomPerturbation`): every
  movable object displaced and rotated at random (the paper's comparison point).
- ``learned`` (:class:`~adaptenv.adapt.generators.learned.LearnedGenerator`, offline): a trained network
  scores candidate edits in one forward pass; of the best that pass the checks, the one with the largest
  measured route-objective gain is made (no agent rollout).

Moves are on the normalized 100x100 grid (+x right, +y up); ``rotation`` is the object's new
absolute yaw in degrees (0 faces up on the map, 90 faces right).
"""

from __future__ import annotations

from typing import Any

from adaptenv.adapt.generators.base import (
    GENERATORS,
    GenerationContext,
    GenerationResult,
    Generator,
    StepRecord,
    StepStatus,
    house_object_types,
    keep_render,
    movable_ids,
    png_bytes,
    render_scene,
)
from adaptenv.adapt.generators.builtin import BuiltinGenerator
from adaptenv.adapt.generators.failure_modes import FailureModeGenerator
from adaptenv.adapt.generators.learned import LearnedGenerator
from adaptenv.adapt.generators.llm import LLMGenerator
from adaptenv.adapt.generators.random_perturbation import RandomPerturbation
from adaptenv.errors import ConfigError


def make_generator(name: str = "builtin", **kw: Any) -> Generator:
    """Build a generator by name: ``builtin`` (default), ``llm`` (needs ``backend=``), ``random``, ``failure-modes``
    or ``learned`` (``checkpoint=`` a scorer file; default the shipped one)."""
    if name == "builtin":
        return BuiltinGenerator(**kw)
    if name == "llm":
        return LLMGenerator(**kw)
    if name == "random":
        return RandomPerturbation(**kw)
    if name == "failure-modes":
        return FailureModeGenerator(**kw)
    if name == "learned":
        return LearnedGenerator(**kw)
    raise ConfigError(f"unknown generator {name!r}; use one of {', '.join(GENERATORS)}")


__all__ = ["GENERATORS", "GenerationContext", "GenerationResult", "Generator", "StepRecord", "StepStatus",
           "house_object_types", "keep_render", "make_generator", "movable_ids", "png_bytes", "render_scene"]
