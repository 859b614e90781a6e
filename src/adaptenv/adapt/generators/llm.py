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
3. The move goes through collision-aware placement and validation, the plausibility rules of
   :mod:`adaptenv.adapt.plausibility` included (a rejected move leaves the scene unchanged and is
   logged; the re-ask names the refusing rule and its reason), and the scene is re-rendered.
4. Verification (the paper's experiment): the model sees the new render, its intent, what it
   requested and what placement achieved, and answers through ``verify_move``. On "revise" (or a
   rejected move) the step is redone from the scene before it with the revised move, at most
   ``max_revisions`` times. A move that changes neither position nor heading is a failed step:
   it is re-asked once, then the step is recorded as ``no-op`` (never applied or verified).

Honest accounting: an edit is in the returned house exactly when its step says ``applied``.
Transport failures after the backend's retries, or a used-up token/cost budget, end the run early
with the edits of the finished steps; an edit of the unfinished step is undone (its entry in the
edit log is marked ``undone``). A bad answer never raises. Clamped answers (units above 100,
rotations outside [0, 360)) are applied as clamped and the clamp is written into the edit's intent.

With ``door_edits`` (and adaptenv's prompts) the step prompt also lists the interior doors with a leaf,
open or shut, and the model may answer with ``set_door_openness`` instead (one door opened or shut,
through :meth:`~adaptenv.adapt.validation.EditValidator.set_door`'s check, verified the same way).

The episode's target objects are not in the move tool's enum (as with the built-in G) unless
``allow_target_moves``. With ``prompts="paper"`` the paper's appendix prompt is sent verbatim
(:data:`adaptenv.adapt.llm.prompts.PAPER_G_PROMPT`), without a system message or object list.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from adaptenv.adapt.analysis import Analysis, Suggestion
from adaptenv.adapt.edits import Edit, EditLog
from adaptenv.adapt.generators.base import (
    GenerationContext,
    GenerationResult,
    StepRecord,
    keep_render,
    png_bytes,
    render_scene,
)
from adaptenv.adapt.llm.errors import BudgetExceeded, LLMUnavailableError, ModelAnswerError
from adaptenv.adapt.llm.messages import Message
from adaptenv.adapt.llm.prompts import PAPER_G_PROMPT
from adaptenv.adapt.llm.tools import (
    DOOR_TOOL_NAME,
    DoorInstruction,
    MoveInstruction,
    door_tool,
    move_tool,
    parse_door_instruction,
    parse_move_instruction,
)
from adaptenv.adapt.objectives import OBJECTIVE_KINDS, RouteSpec, gain, measure
from adaptenv.adapt.validation import EditValidator
from adaptenv.adapt.verification import Check, ask_llm, revise_until_verified
from adaptenv.scene.house import House, is_interior_leaf_door, is_shut
from adaptenv.sim.world import compile_world

if TYPE_CHECKING:
    from adaptenv.adapt.llm.backend import LLMBackend

log = logging.getLogger(__name__)

#: Transport failures and budgets that end a generation early (the unfinished step is undone).
STOPPING_ERRORS = (LLMUnavailableError, BudgetExceeded)

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
- Keep the layout realistic: furniture where it could plausibly stand in a home. Moves that break
  one of these are refused, with the rule's name: wall furniture (beds, sofas, dressers, fridges,
  ...) keeps its back to a wall (edge_off_wall); nothing moves into the 1 m in front of a doorway
  (door_approach); chairs stay at their table, a floor lamp at its armchair, a sofa at its TV
  (group_split); small objects stay by a wall or furniture (open_floor); seats keep facing the TV
  and chairs their table (facing_broken); nothing runs past the end of the wall it stands along
  (wall_overhang) or into an open connection between two rooms (in_opening); a table, desk or
  armchair does not move away from its chairs or lamp (group_left_behind); tall furniture does not
  stand in front of a window (blocks_window).

Movable objects (id: type at grid x, y, rotation):
{objects}{doors}"""

DOORS_PROMPT = """

Instead of moving an object you may open or shut ONE of these interior doors with the
set_door_openness function (a shut door is a wall to the robot; the target must stay reachable):
{doors}"""

VERIFY_PROMPT = """This is the apartment after your move ({oid} is highlighted in gold).
Intended effect: {intent}
You requested: {requested}.
Placement achieved: {achieved}.
Does the rendered change have the effect you intended? Answer with verify_move: matches_intent
true if it does; otherwise false, with the reason and a revised_move that would achieve it. A
revised move replaces this one and is applied to the apartment as it was before this move."""

REVISE_PROMPT = "{reason} Propose a revised move with propose_move_instruction; it replaces the previous one."
REVISE_DOOR_PROMPT = ("{reason} Propose a revised edit with propose_move_instruction or set_door_openness; it "
                      "replaces the previous one.")

NOOP_FEEDBACK = ("Your move changed nothing: the object kept its position and heading ({achieved}). Propose a "
                 "move that changes its position or its heading.")


def _rotation(step: int, suggestions: list[Suggestion]) -> Suggestion | None:
    usable = [s for s in sorted(suggestions, key=lambda s: -s.priority) if s.kind in OBJECTIVE_KINDS]
    return usable[step % len(usable)] if usable else None


def object_list(v: EditValidator, exclude_types: frozenset[str] = frozenset()) -> tuple[list[str], str]:
    """Movable ids (without objects of ``exclude_types``) and the prompt's object lines (grid centre, yaw)."""
    ctx = v.ctx
    ids, lines = [], []
    for k, (oid, typ, movable) in enumerate(zip(ctx.ids, ctx.types, ctx.movable, strict=True)):
        if not movable or typ in exclude_types:
            continue
        gx, gy = ctx.grid.point(float(ctx.centers[k, 0]), float(ctx.centers[k, 1]))
        ids.append(oid)
        lines.append(f"- {oid}: {typ} at x={gx:.1f}, y={gy:.1f}, rotation={float(ctx.yaws[k]) % 360:.0f}")
    return ids, "\n".join(lines)


def door_list(v: EditValidator) -> tuple[list[str], str]:
    """Interior doors with a leaf and the prompt's door lines (rooms joined, open or shut)."""
    ids, lines = [], []
    for d in v.house.doors:
        if is_interior_leaf_door(d):
            ids.append(d.id)
            lines.append(f"- {d.id}: between {d.room0} and {d.room1}, {'shut' if is_shut(d) else 'open'}")
    return ids, "\n".join(lines)


def describe_request(move: MoveInstruction | DoorInstruction) -> str:
    if isinstance(move, DoorInstruction):
        return f"{'open' if move.open else 'shut'} door {move.door_id}"
    return (f"{move.object_id} {move.x_direction} {move.x_units:g} units, {move.y_direction} {move.y_units:g} units, "
            f"rotation {move.rotation:g}")


def describe_achieved(edit: Edit) -> str:
    if not edit.accepted:
        return "rejected by validation (" + "; ".join(edit.problems) + "); the apartment is unchanged"
    if edit.is_door:
        state = {True: "open", False: "shut"}
        was = edit.openness_before is None or edit.openness_before > 0
        return f"door {edit.object_id} is now {state[edit.openness > 0]} (it was {state[was]})"
    stop = {"reached": "it reached the requested position",
            "blocked_by_object": f"it stopped early, blocked by {edit.blocked_by}",
            "blocked_by_wall": f"it stopped early at the wall {edit.blocked_by}",
            "left_room": "it stopped at the edge of its room",
            "rotation_blocked": f"the rotation was blocked by {edit.blocked_by}; it kept its heading"}.get(
                edit.stop_reason, edit.stop_reason)
    return (f"moved {edit.achieved_dx_units:+.1f} units along x and {edit.achieved_dy_units:+.1f} along y, "
            f"rotation {edit.yaw_before:.0f} -> {edit.yaw_after:.0f}; {stop}")


class LLMGenerator:
    """G on a vision-language model through an :class:`~adaptenv.adapt.llm.LLMBackend` (see module docstring).

    ``prompts`` and ``allow_target_moves`` default to the backend's config; ``progress`` receives one
    line per finished step (status, object, running token and cost totals) and per skipped step.
    """

    name = "llm"

    def __init__(self, backend: LLMBackend, *, max_attempts: int = 3, max_revisions: int = 2, verify: bool = True,
                 prompts: str | None = None, allow_target_moves: bool | None = None,
                 progress: Callable[[str], None] | None = None, door_edits: bool = False):
        self.backend = backend
        self.door_edits = door_edits
        self.max_attempts = max_attempts
        self.max_revisions = max_revisions
        self.verify = verify
        cfg = getattr(backend, "config", None)
        self.prompts = prompts or getattr(cfg, "prompts", "adaptenv")
        self.allow_target_moves = (bool(getattr(cfg, "allow_target_moves", False)) if allow_target_moves is None
                                   else allow_target_moves)
        self.progress = progress

    @property
    def system(self) -> str:
        """The system message (none with the paper's prompts)."""
        return "" if self.prompts == "paper" else SYSTEM_PROMPT

    def _say(self, text: str) -> None:
        (self.progress or log.info)(text)

    # ----------------------------------------------------------------------------- model calls
    def _ask_move(self, messages: list[Message], ids: list[str], doors: list[str] | None = None
                  ) -> tuple[MoveInstruction | DoorInstruction | None, int, str]:
        """(a validated move, or door edit when ``doors`` are offered, or None; attempts used; reason when None);
        ``messages`` grows with the exchange."""
        tools = [move_tool(ids), door_tool(doors)] if doors else move_tool(ids)
        last = ""
        for attempt in range(1, self.max_attempts + 1):
            try:
                call = self.backend.call_tool(self.system, messages, None, tools, role="G")
                move = (parse_door_instruction(call.arguments, doors) if doors and call.name == DOOR_TOOL_NAME
                        else parse_move_instruction(call.arguments, ids))
            except ModelAnswerError as exc:
                last = str(exc)
                log.info("move answer %d rejected: %s", attempt, exc)
                messages += [Message.assistant(exc.raw or "(no answer)"), Message.user(exc.feedback)]
                continue
            messages.append(Message.assistant(call.raw_arguments))
            return move, attempt, ""
        return None, self.max_attempts, f"no valid move after {self.max_attempts} answers (last: {last})"

    def _prompt(self, analysis: Analysis, sug: Suggestion | None, intent: str, lines: str, doors: str = "") -> str:
        """G's user message for one step (the paper's verbatim, or adaptenv's with the object and door lists)."""
        if self.prompts == "paper":
            return PAPER_G_PROMPT.format(analysis=analysis.to_text())
        return STEP_PROMPT.format(analysis=analysis.to_text(), sid=sug.id if sug else "-",
                                  skind=sug.kind if sug else "any", sdesc=sug.description if sug else intent,
                                  objects=lines, doors=DOORS_PROMPT.format(doors=doors) if doors else "")

    # ----------------------------------------------------------------------------- the loop
    def generate(self, house: House, analysis: Analysis, *, steps: int, context: GenerationContext,
                 rng: np.random.Generator) -> GenerationResult:
        ep = context.episode
        targets, start = [ep.target_type], ep.start[:2]
        v = EditValidator(house, episode_targets=targets, start=start, move_targets=self.allow_target_moves,
                          placement_model=context.placement_model)
        edit_log = EditLog()
        route = RouteSpec.from_episode(ep.target_type, ep.start, context.trajectory)
        values = measure(compile_world(v.house, "llm"), route)
        cfg = getattr(self.backend, "config", None)
        describe = getattr(self.backend, "describe", None)
        result = GenerationResult(house=v.house, steps=[], edit_log=edit_log, generator=self.name,
                                  objective_trace=[values.as_dict()],
                                  prices=cfg.prices() if cfg is not None else None,
                                  llm=describe() if describe is not None else None)
        with self.backend.track() as counter:
            result.usage = counter
            for step in range(steps):
                v, values = self._step(step, v, house, analysis, context, route, values, result, edit_log)
                rec = result.steps[-1]
                what = f" {rec.edit.object_id}" if rec.edit is not None and rec.status != "skipped" else ""
                why = f": {rec.reason}" if rec.status in ("skipped", "rejected", "no-op") and rec.reason else ""
                self._say(f"G step {step + 1}/{steps}: {rec.status}{what}{why} | tokens so far: "
                          f"{counter.line(result.prices)}")
                if result.stopped:
                    self._say(f"G stopped after {step} finished step(s): {result.stopped}")
                    break
        result.house = v.house
        return result

    def _step(self, step: int, v: EditValidator, original: House, analysis: Analysis, context: GenerationContext,
              route: RouteSpec, values, result: GenerationResult, edit_log: EditLog):
        """One edit with its revisions; returns the (possibly rebuilt) validator and the new objective values.

        On a stopping error (LLM unavailable, budget used up) the step's edit is undone, the step is
        recorded as skipped and ``result.stopped`` says why.
        """
        sug = _rotation(step, analysis.suggestions)
        record = StepRecord(step=step, status="skipped", suggestion_id=sug.id if sug else None,
                            suggestion_kind=sug.kind if sug else None, objective_before=values.as_dict())
        result.steps.append(record)
        exclude = frozenset() if self.allow_target_moves else frozenset({context.episode.target_type})
        ids, lines = object_list(v, exclude)
        if not ids:
            record.reason = "the scene has no movable object" + ("" if self.allow_target_moves else
                                                                 " besides the episode's targets")
            return v, values
        intent = f"[{sug.id}] {sug.kind}: {sug.description}" if sug else "make the apartment more challenging"
        door_ids, door_lines = door_list(v) if self.door_edits and self.prompts != "paper" else ([], "")
        messages = [Message.user(self._prompt(analysis, sug, intent, lines, door_lines),
                                 png_bytes(render_scene(v.house, context)))]
        snapshot = v.house.model_copy(deep=True)
        state = {"v": v, "image": None, "unverified": False, "noops": 0, "log_at": None}

        def restart() -> bool:
            """Undo this step's edit if one is in the scene (log entry marked undone, scene rebuilt from the
            snapshot); True when something was undone."""
            k = state["log_at"]
            if k is None:
                return False
            edit_log.edits[k] = edit_log.edits[k].model_copy(update={"undone": True})
            state["v"] = EditValidator(snapshot, episode_targets=[context.episode.target_type],
                                       start=context.episode.start[:2], original=original,
                                       move_targets=self.allow_target_moves, placement_model=context.placement_model)
            state["log_at"] = None
            return True

        def apply(mv: MoveInstruction | DoorInstruction) -> Edit:
            restart()  # a revision replaces the previous attempt: restart from the snapshot
            if isinstance(mv, DoorInstruction):
                edit = state["v"].set_door(mv.door_id, 1.0 if mv.open else 0.0, source=self.name, intent=intent)
            else:
                dx, dy = mv.signed_displacement()
                note = f" [clamped: {', '.join(mv.clamped)}]" if mv.clamped else ""
                edit = state["v"].try_edit(mv.object_id, dx, dy, mv.rotation, source=self.name, intent=intent + note)
            state["log_at"] = len(edit_log.edits) if edit.changed else None
            edit_log.append(edit)
            state["image"] = render_scene(state["v"].house, context, highlight={edit.object_id: "gold"})
            return edit

        def check(mv: MoveInstruction | DoorInstruction, edit: Edit) -> Check:
            if not edit.accepted:
                return Check(False, "Your move was " + describe_achieved(edit) + ".")
            if not edit.changed:
                state["noops"] += 1
                return Check(False, NOOP_FEEDBACK.format(achieved=describe_achieved(edit)))
            if not self.verify:
                return Check(True, "not verified")
            messages.append(Message.user(VERIFY_PROMPT.format(oid=edit.object_id, intent=intent,
                                                              requested=describe_request(mv),
                                                              achieved=describe_achieved(edit)),
                                         png_bytes(state["image"])))
            answer, note = ask_llm(self.backend, self.system, messages, ids, max_attempts=self.max_attempts)
            if answer is None:
                state["unverified"] = True
                return Check(True, f"verification skipped: {note}")
            state["unverified"] = False
            messages.append(Message.assistant(answer.model_dump_json(exclude={"revised_move": {"clamped"}})))
            return Check(answer.matches_intent, answer.reason, revised=answer.revised_move)

        def revise(mv: MoveInstruction | DoorInstruction, edit: Edit, chk: Check
                   ) -> MoveInstruction | DoorInstruction | None:
            if state["noops"] >= 2:  # a no-op is re-asked once, then the step is given up
                return None
            if chk.revised is not None:
                return chk.revised
            messages.append(Message.user((REVISE_DOOR_PROMPT if door_ids else REVISE_PROMPT).format(reason=chk.reason)))
            nxt, n, why = self._ask_move(messages, ids, door_ids)
            record.attempts += n
            if nxt is None:
                record.reason = why
            return nxt

        try:
            move, attempts, why = self._ask_move(messages, ids, door_ids)
            record.attempts = attempts
            if move is None:
                record.reason = why
                return v, values
            verdict = revise_until_verified(move, apply, check, revise, max_revisions=self.max_revisions,
                                            method="llm" if self.verify else "none")
        except STOPPING_ERRORS as exc:
            undone = restart()
            kind = "budget used up" if isinstance(exc, BudgetExceeded) else "LLM unavailable"
            record.reason = f"{kind}: {exc}" + ("; this step's edit was undone" if undone else "")
            result.stopped = record.reason
            return state["v"], values
        v, edit = state["v"], verdict.result
        record.edit, record.revisions = edit, verdict.revisions
        record.verification = verdict.method
        if not edit.accepted:
            record.status, record.reason = "rejected", record.reason or verdict.check.reason
            return v, values
        if not edit.changed:
            record.status, record.verified = "no-op", None
            record.reason = record.reason or "the move changed neither position nor heading (asked twice)"
            return v, values
        checked = self.verify and not state["unverified"]
        record.verified = verdict.check.passed if checked else None
        record.reason = record.reason or verdict.check.reason
        record.status = "applied"
        after = measure(compile_world(v.house, "llm"), route)
        record.objective_after = after.as_dict()
        record.gain = gain(sug.kind, values, after) if sug else None
        result.objective_trace.append(after.as_dict())
        record.render = keep_render(result, state["image"], context, step)
        return v, after
