"""The LLM generator G (the paper's procedure): one tool call per single-object edit, then verification.

Per step:

1. Render the current scene (normalized grid, the analysed trajectory) and send it with a prompt
   carrying F's analysis, the suggestion to focus on this step (round-robin by priority), the
   rules and every movable object with its grid position and rotation.
2. The model answers through the paper's ``propose_move_instruction`` tool (schema field for
   field, :func:`adaptenv.adapt.llm.move_tool`). Answers are validated and clamped
   (:func:`~adaptenv.adapt.llm.parse_move_instruction`); an unknown id, a malformed answer or
   invalid JSON is sent back with the error and asked again, at most ``max_attempts`` times,
   after which the step is skipped with the reason logged. ``rotation`` is read as the object's
   new absolute yaw in degrees (0 = front faces up on the map, 90 = right).
3. The move goes through collision-aware placement and validation (a rejected move leaves the
   scene unchanged and is logged), and the scene is re-rendered.
4. Verification (the paper's experiment): the model sees the new render, its intent, what it
   requested and what placement achieved, and answers through ``verify_move``. On "revise" (or a
   rejected move) the step is redone from the scene before it with the revised move, at most
   ``max_revisions`` times. Transport failures after the backend's retries end the run early
   with the edits made so far; a bad answer never raises.
"""

from __future__ import annotations

import logging

import numpy as np

from adaptenv.adapt.analysis import Analysis, Suggestion
from adaptenv.adapt.edits import Edit, EditLog
from adaptenv.adapt.generators import (
    GenerationContext,
    GenerationResult,
    StepRecord,
    keep_render,
    png_bytes,
    render_scene,
)
from adaptenv.adapt.objectives import OBJECTIVE_KINDS, RouteSpec, gain, measure
from adaptenv.adapt.validation import EditValidator
from adaptenv.adapt.verification import Check, ask_llm, revise_until_verified
from adaptenv.scene.house import House
from adaptenv.sim.world import compile_world

log = logging.getLogger(__name__)

SYSTEM_PROMPT = (
    "You are a level designer for a household navigation robot. You edit apartment floor plans one "
    "object at a time, through function calls, so that they become more demanding for the robot while "
    "staying realistic homes.")

STEP_PROMPT = """The robot was just evaluated in this apartment. Analysis of its episode:
{analysis}

Goal: make the apartment more challenging for object navigation in the way the analysis asks.
This step, focus on suggestion [{sid}] {skind}: {sdesc}

Pick ONE movable object and propose ONE move for it with the propose_move_instruction function.
The image is the current top-down plan: the robot's path runs from yellow to orange, the target
instances are orange crosses, object ids are written next to the furniture.

Rules:
- Positions use a normalized 100x100 grid over the apartment: x from 0 (left) to 100 (right),
  y from 0 (bottom) to 100 (top). x_units and y_units say how far to move, with x_direction
  left/right and y_direction up/down.
- rotation is the object's NEW absolute heading in degrees: 0 = its front faces up on the plan,
  90 = right, 180 = down, 270 = left. Repeat the current rotation to only move the object.
- Keep every object inside the walls of its own room.
- Never block a doorway completely; passages and doorway clearances may become narrower.
- Avoid overlapping other objects: a move that would collide stops at the last free position.
- Keep the layout realistic: furniture where it could plausibly stand in a home.

Movable objects (id: type at grid x, y, rotation):
{objects}"""

VERIFY_PROMPT = """This is the apartment after your move ({oid} is highlighted in gold).
Intended effect: {intent}
You requested: {requested}.
Placement achieved: {achieved}.
Does the rendered change have the effect you intended? Answer with verify_move: matches_intent
true if it does; otherwise false, with the reason and a revised_move that would achieve it. A
revised move replaces this one and is applied to the apartment as it was before this move."""

REVISE_PROMPT = "{reason} Propose a revised move with propose_move_instruction; it replaces the previous one."


def _rotation(step: int, suggestions: list[Suggestion]) -> Suggestion | None:
    usable = [s for s in sorted(suggestions, key=lambda s: -s.priority) if s.kind in OBJECTIVE_KINDS]
    return usable[step % len(usable)] if usable else None


def object_list(v: EditValidator) -> tuple[list[str], str]:
    """Movable ids and the prompt's object lines (grid position of the footprint centre, yaw)."""
    ctx = v.ctx
    ids, lines = [], []
    for k, (oid, typ, movable) in enumerate(zip(ctx.ids, ctx.types, ctx.movable, strict=True)):
        if not movable:
            continue
        gx, gy = ctx.grid.point(float(ctx.centers[k, 0]), float(ctx.centers[k, 1]))
        ids.append(oid)
        lines.append(f"- {oid}: {typ} at x={gx:.1f}, y={gy:.1f}, rotation={float(ctx.yaws[k]) % 360:.0f}")
    return ids, "\n".join(lines)


def describe_request(move) -> str:
    return (f"{move.object_id} {move.x_direction} {move.x_units:g} units, {move.y_direction} {move.y_units:g} units, "
            f"rotation {move.rotation:g}")


def describe_achieved(edit: Edit) -> str:
    if not edit.accepted:
        return "rejected by validation (" + "; ".join(edit.problems) + "); the apartment is unchanged"
    stop = {"reached": "it reached the requested position",
            "blocked_by_object": f"it stopped early, blocked by {edit.blocked_by}",
            "blocked_by_wall": f"it stopped early at the wall {edit.blocked_by}",
            "left_room": "it stopped at the edge of its room",
            "rotation_blocked": f"the rotation was blocked by {edit.blocked_by}; it kept its heading"}.get(
                edit.stop_reason, edit.stop_reason)
    return (f"moved {edit.achieved_dx_units:+.1f} units along x and {edit.achieved_dy_units:+.1f} along y, "
            f"rotation {edit.yaw_before:.0f} -> {edit.yaw_after:.0f}; {stop}")


class LLMGenerator:
    """G on a vision-language model through an :class:`~adaptenv.adapt.llm.LLMBackend` (see module docstring)."""

    name = "llm"

    def __init__(self, backend, *, max_attempts: int = 3, max_revisions: int = 2, verify: bool = True):
        self.backend = backend
        self.max_attempts = max_attempts
        self.max_revisions = max_revisions
        self.verify = verify

    # ----------------------------------------------------------------------------- model calls
    def _ask_move(self, messages: list, ids: list[str]):
        """(a validated move or None, attempts used, reason when None); ``messages`` grows with the exchange."""
        from adaptenv.adapt.llm import Message, ModelAnswerError, move_tool, parse_move_instruction

        tool = move_tool(ids)
        last = ""
        for attempt in range(1, self.max_attempts + 1):
            try:
                call = self.backend.call_tool(SYSTEM_PROMPT, messages, None, tool)
                move = parse_move_instruction(call.arguments, ids)
            except ModelAnswerError as exc:
                last = str(exc)
                log.info("move answer %d rejected: %s", attempt, exc)
                messages += [Message.assistant(exc.raw or "(no answer)"), Message.user(exc.feedback)]
                continue
            messages.append(Message.assistant(call.raw_arguments))
            return move, attempt, ""
        return None, self.max_attempts, f"no valid move after {self.max_attempts} answers (last: {last})"

    # ----------------------------------------------------------------------------- the loop
    def generate(self, house: House, analysis: Analysis, *, steps: int, context: GenerationContext,
                 rng: np.random.Generator) -> GenerationResult:
        from adaptenv.adapt.llm import LLMUnavailableError

        ep = context.episode
        targets, start = [ep.target_type], ep.start[:2]
        v = EditValidator(house, episode_targets=targets, start=start)
        edit_log = EditLog()
        route = RouteSpec.from_episode(ep.target_type, ep.start, context.trajectory)
        values = measure(compile_world(v.house, "llm"), route)
        result = GenerationResult(house=v.house, steps=[], edit_log=edit_log, generator=self.name,
                                  objective_trace=[values.as_dict()])
        with self.backend.track() as counter:
            for step in range(steps):
                try:
                    v, values = self._step(step, v, house, analysis, context, route, values, result, edit_log)
                except LLMUnavailableError as exc:
                    result.steps.append(StepRecord(step=step, status="skipped", reason=f"LLM unavailable: {exc}"))
                    log.warning("stopping after %d steps: %s", step, exc)
                    break
            result.usage = counter.snapshot()
        result.house = v.house
        return result

    def _step(self, step: int, v: EditValidator, original: House, analysis: Analysis, context: GenerationContext,
              route: RouteSpec, values, result: GenerationResult, edit_log: EditLog):
        """One edit with its revisions; returns the (possibly rebuilt) validator and the new objective values."""
        from adaptenv.adapt.llm import Message

        sug = _rotation(step, analysis.suggestions)
        record = StepRecord(step=step, status="skipped", suggestion_id=sug.id if sug else None,
                            suggestion_kind=sug.kind if sug else None, objective_before=values.as_dict())
        ids, lines = object_list(v)
        if not ids:
            record.reason = "the scene has no movable object"
            result.steps.append(record)
            return v, values
        intent = f"[{sug.id}] {sug.kind}: {sug.description}" if sug else "make the apartment more challenging"
        prompt = STEP_PROMPT.format(analysis=analysis.to_text(), sid=sug.id if sug else "-",
                                    skind=sug.kind if sug else "any", sdesc=sug.description if sug else intent,
                                    objects=lines)
        messages = [Message.user(prompt, png_bytes(render_scene(v.house, context)))]
        move, attempts, why = self._ask_move(messages, ids)
        record.attempts = attempts
        if move is None:
            record.reason = why
            result.steps.append(record)
            return v, values
        snapshot = v.house.model_copy(deep=True)
        state = {"v": v, "fresh": True, "image": None, "unverified": False}

        def apply(mv) -> Edit:
            if not state["fresh"]:  # a revision replaces the previous attempt: restart from the snapshot
                state["v"] = EditValidator(snapshot, episode_targets=[context.episode.target_type],
                                           start=context.episode.start[:2], original=original)
            state["fresh"] = False
            dx, dy = mv.signed_displacement()
            edit = state["v"].try_edit(mv.object_id, dx, dy, mv.rotation, source=self.name, intent=intent)
            edit_log.append(edit)
            state["image"] = render_scene(state["v"].house, context, highlight={mv.object_id: "gold"})
            return edit

        def check(mv, edit: Edit) -> Check:
            if not edit.accepted:
                return Check(False, "Your move was " + describe_achieved(edit) + ".")
            if not self.verify:
                return Check(True, "not verified")
            messages.append(Message.user(VERIFY_PROMPT.format(oid=mv.object_id, intent=intent,
                                                              requested=describe_request(mv),
                                                              achieved=describe_achieved(edit)),
                                         png_bytes(state["image"])))
            answer, note = ask_llm(self.backend, SYSTEM_PROMPT, messages, ids, max_attempts=self.max_attempts)
            if answer is None:
                state["unverified"] = True
                return Check(True, f"verification skipped: {note}")
            state["unverified"] = False
            messages.append(Message.assistant(answer.model_dump_json()))
            return Check(answer.matches_intent, answer.reason, revised=answer.revised_move)

        def revise(mv, edit: Edit, chk: Check):
            if chk.revised is not None:
                return chk.revised
            messages.append(Message.user(REVISE_PROMPT.format(reason=chk.reason)))
            nxt, n, why = self._ask_move(messages, ids)
            record.attempts += n
            if nxt is None:
                record.reason = why
            return nxt

        verdict = revise_until_verified(move, apply, check, revise, max_revisions=self.max_revisions,
                                        method="llm" if self.verify else "none")
        v, edit = state["v"], verdict.result
        record.edit, record.revisions = edit, verdict.revisions
        record.verification = verdict.method
        checked = self.verify and edit.accepted and not state["unverified"]
        record.verified = verdict.check.passed if checked else None
        record.reason = record.reason or verdict.check.reason
        if not edit.accepted:
            record.status = "rejected"
            result.steps.append(record)
            return v, values
        record.status = "applied"
        after = measure(compile_world(v.house, "llm"), route)
        record.objective_after = after.as_dict()
        record.gain = gain(sug.kind, values, after) if sug else None
        result.objective_trace.append(after.as_dict())
        record.render = keep_render(result, state["image"], context, step)
        result.steps.append(record)
        return v, after
