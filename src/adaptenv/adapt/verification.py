"""Verification of G's edits: did the change have the intended effect, and if not, revise (bounded).

Two checks, one revision loop:

- the built-in check (:func:`check_objective`): the objective behind the step's suggestion
  (:mod:`adaptenv.adapt.objectives`) moved in the intended direction by more than a tolerance;
- the LLM check (:func:`ask_llm`): the model sees the new render with its intent and the move that
  was actually achieved, and answers through ``verify_tool`` (``matches_intent``, ``reason``,
  optionally ``revised_move``), as in the paper's verification experiment.

:func:`revise_until_verified` runs propose -> apply -> check -> revise with at most
``max_revisions`` revisions; generators record the returned :class:`Verdict` (passed or not, and
how many revisions it took) in each step's log entry.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, Literal, TypeVar

from adaptenv.adapt.llm import (
    LLMBackend,
    Message,
    ModelAnswerError,
    Verification,
    parse_verification,
    verify_tool,
)
from adaptenv.adapt.objectives import ObjectiveValues, gain

log = logging.getLogger(__name__)

P = TypeVar("P")
R = TypeVar("R")

#: An objective must improve by more than this (in :func:`objectives.gain` units) to pass.
OBJECTIVE_TOLERANCE = 1e-6
#: Default bound on revisions after the first attempt.
MAX_REVISIONS = 2

Method = Literal["objective", "llm", "none"]


@dataclass(frozen=True)
class Check:
    """One verification answer: passed or not, why, the objective delta (built-in) and a revision (LLM)."""

    passed: bool
    reason: str
    delta: float | None = None
    revised: object | None = None
    """A revised proposal suggested by the checker itself (the LLM's ``revised_move``), if any."""


@dataclass(frozen=True)
class Verdict(Generic[R]):
    """The outcome of the revision loop: the last applied result, its check and the revisions used."""

    result: R
    check: Check
    revisions: int
    method: Method


def check_objective(kind: str, before: ObjectiveValues, after: ObjectiveValues,
                    tolerance: float = OBJECTIVE_TOLERANCE) -> Check:
    """Built-in check: the targeted objective moved in the intended direction (gain > tolerance)."""
    g = gain(kind, before, after)
    a, b = before.value(kind), after.value(kind)
    if not math.isfinite(g):
        return Check(False, f"{kind}: the route became unreachable", None)
    ok = g > tolerance
    verb = "improved" if ok else "did not improve"
    return Check(ok, f"{kind} {verb}: {a:.3f} -> {b:.3f} (gain {g:+.3f})", g)


def revise_until_verified(first: P, apply: Callable[[P], R], check: Callable[[P, R], Check],
                          revise: Callable[[P, R, Check], P | None], *, max_revisions: int = MAX_REVISIONS,
                          method: Method = "objective") -> Verdict[R]:
    """Apply ``first``, check it, and revise at most ``max_revisions`` times until a check passes.

    ``revise`` returns the next proposal (or None to stop); it is also where a generator undoes a
    rejected attempt. The last applied result is returned whether or not it passed.
    """
    proposal = first
    revisions = 0
    while True:
        result = apply(proposal)
        verdict = check(proposal, result)
        if verdict.passed or revisions >= max_revisions:
            return Verdict(result, verdict, revisions, method)
        nxt = revise(proposal, result, verdict)
        if nxt is None:
            return Verdict(result, verdict, revisions, method)
        proposal = nxt
        revisions += 1


def ask_llm(backend: LLMBackend, system: str, messages: list[Message], allowed_ids: list[str], *,
            max_attempts: int = 3) -> tuple[Verification | None, str]:
    """The LLM check: call ``verify_tool`` (with revisions allowed), re-asking after invalid answers.

    Returns (the parsed verification or None after ``max_attempts`` invalid answers, a note for
    the log). ``messages`` is extended in place with rejected answers and their feedback.
    """
    tool = verify_tool(allowed_ids)
    last = ""
    for attempt in range(max_attempts):
        try:
            call = backend.call_tool(system, messages, None, tool, role="verify")
            return parse_verification(call.arguments, allowed_ids), ""
        except ModelAnswerError as exc:
            last = str(exc)
            log.info("verification answer %d rejected: %s", attempt + 1, exc)
            messages += [Message.assistant(exc.raw or "(no answer)"), Message.user(exc.feedback)]
    return None, f"no valid verification answer in {max_attempts} attempts (last: {last})"
