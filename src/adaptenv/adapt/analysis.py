"""Trajectory analysis F: outcome, concerns and abstract suggestions, as typed data.

The paper's F reads a top-down trajectory image and returns {outcome, concerns, suggestions}.
:class:`Analysis` is that result; :func:`analyze_trajectory` is the built-in, deterministic F that
computes it from the trajectory, the scene geometry and the geodesic distance field;
:class:`LLMAnalyzer` asks a vision-language model about the top-down render and returns the same
type (``source="llm"``). Both satisfy the :class:`Analyzer` protocol. Suggestions say *what* should change
(narrow a passage, occlude the target, lengthen the route, add clutter), never *how*: turning
them into object moves is the generator's job.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np
import shapely
from pydantic import BaseModel, Field

from adaptenv.adapt.llm import LLMBackend, LLMError, Message, ModelAnswerError
from adaptenv.adapt.llm.prompts import PAPER_F_PROMPT
from adaptenv.errors import ConfigError
from adaptenv.render.topdown import png_bytes, render_house
from adaptenv.scene.occupancy import LABEL_DOOR, LABEL_OBJECT0, LABEL_WINDOW
from adaptenv.sim.spec import AGENT_RADIUS, MAX_STEPS, MOVE_STEP
from adaptenv.sim.trajectory import Trajectory, metres
from adaptenv.sim.world import NavWorld

log = logging.getLogger(__name__)

FailureMode = Literal["timeout", "ended_too_far", "ended_without_sight", "stuck", "looping", "never_saw_target"]
ConcernKind = Literal["collision", "close_proximity", "narrow_clearance", "detour", "revisit", "oscillation",
                      "late_sight", "premature_end"]
SuggestionKind = Literal["narrow_passage", "occlude_target", "lengthen_route", "add_clutter"]

#: An agent edge closer than this (m) to an obstacle is "close proximity".
PROXIMITY_MARGIN = 0.10
#: A passage is narrow when the clearance at the agent's centre is below this (m).
NARROW_CLEARANCE = AGENT_RADIUS + 0.25
#: Poses are binned into cells of this size (m) to count revisits.
REVISIT_CELL = 0.4


class GridPoint(BaseModel):
    """A location on the normalized 100x100 grid (x right, y up)."""

    x: float
    y: float


class Outcome(BaseModel):
    """Did the agent succeed, and if not, how did it fail."""

    success: bool
    failure_mode: FailureMode | None = None
    summary: str
    steps: int
    spl: float | None = None


class Concern(BaseModel):
    """A behavioural issue observed during the episode, located in grid coordinates and steps.

    The built-in F gives one concern per kind and object: repeated bouts (say, five separate runs
    of bumping into the same bed) are one concern with ``count`` 5 and each bout in ``occurrences``.
    """

    id: str
    kind: ConcernKind
    severity: float = Field(ge=0.0, le=1.0)
    description: str
    steps: list[int] = Field(default_factory=list)
    """Step indices where it occurred (a range is given by its first and last step)."""
    where: GridPoint | None = None
    objects: list[str] = Field(default_factory=list)
    """Ids of the objects involved (nearest obstacles), if any."""
    count: int = Field(default=1, ge=1)
    """How many separate times it happened."""
    occurrences: list[tuple[int, int]] = Field(default_factory=list)
    """First and last step of each time it happened (empty when not located in steps)."""


#: A suggestion cites at most this many concerns (the most severe of the kinds it answers).
MAX_ADDRESSED = 5


class Suggestion(BaseModel):
    """An abstract change to the environment (what, not how), tied to the concerns it addresses."""

    id: str
    kind: SuggestionKind
    description: str
    addresses: list[str] = Field(default_factory=list)
    """Ids of the concerns this suggestion answers."""
    priority: float = Field(default=0.5, ge=0.0, le=1.0)


class Analysis(BaseModel):
    """The paper's analysis a = F(tau): outcome, concerns and suggestions."""

    task: str
    outcome: Outcome
    concerns: list[Concern] = Field(default_factory=list)
    suggestions: list[Suggestion] = Field(default_factory=list)
    source: str = "builtin"
    usage: dict[str, Any] | None = None
    """Token usage of the LLM calls behind this analysis (``Usage.to_dict``); None for the built-in F."""

    def to_text(self) -> str:
        """A compact plain-text rendering, used in the generator's prompt and in reports."""
        lines = [f"Task: {self.task}", f"Outcome: {'success' if self.outcome.success else 'failure'}"
                 + (f" ({self.outcome.failure_mode})" if self.outcome.failure_mode else "")
                 + f". {self.outcome.summary}", "Concerns:"]
        for c in self.concerns or []:
            where = f" near grid ({c.where.x:.0f}, {c.where.y:.0f})" if c.where else ""
            objs = f"; objects: {', '.join(c.objects)}" if c.objects else ""
            times = f", {c.count} times" if c.count > 1 else ""
            lines.append(f"- [{c.id}] {c.kind} (severity {c.severity:.2f}{times}){where}: {c.description}{objs}")
        if not self.concerns:
            lines.append("- none")
        lines.append("Suggestions:")
        for s in self.suggestions or []:
            lines.append(f"- [{s.id}] {s.kind}: {s.description} (addresses {', '.join(s.addresses) or 'general difficulty'})")
        return "\n".join(lines)


def _nearest_obstacle(world: NavWorld, x: float, z: float) -> str | None:
    """Id of the obstacle nearest to a point: an object id, 'door', 'window' or 'wall'."""
    g = world.grid
    row, col = g.to_cell(x, z)
    if not g.in_bounds(row, col):
        return None
    label = int(g.nearest_label[row, col])
    if label >= LABEL_OBJECT0:
        return g.object_ids[label - LABEL_OBJECT0]
    return {LABEL_DOOR: "door", LABEL_WINDOW: "window"}.get(label, "wall")


def _runs(indices: list[int], gap: int = 3) -> list[list[int]]:
    """Group sorted step indices into runs whose members are at most ``gap`` apart."""
    runs: list[list[int]] = []
    for i in indices:
        if runs and i - runs[-1][-1] <= gap:
            runs[-1].append(i)
        else:
            runs.append([i])
    return runs


def _by_object(world: NavWorld, traj: Trajectory, indices: list[int], gap: int = 3) -> dict[str, list[list[int]]]:
    """Step indices grouped by the obstacle nearest to each step, then into runs (see :func:`_runs`)."""
    groups: dict[str, list[int]] = {}
    for i in indices:
        pose = traj.steps[i].pose
        groups.setdefault(_nearest_obstacle(world, pose.x, pose.z) or "", []).append(i)
    return {obj: _runs(steps, gap) for obj, steps in groups.items()}


def _times(runs: list[list[int]]) -> str:
    """' in 3 bouts (steps 4-9, 20, 31-33)' for several runs, '' for one."""
    if len(runs) < 2:
        return ""
    spans = [f"{r[0]}-{r[-1]}" if r[-1] != r[0] else str(r[0]) for r in runs[:4]]
    more = f", +{len(runs) - 4} more" if len(runs) > 4 else ""
    return f" in {len(runs)} bouts (steps {', '.join(spans)}{more})"


def _clearances(world: NavWorld, traj: Trajectory) -> np.ndarray:
    xs = np.array([s.pose.x for s in traj.steps])
    zs = np.array([s.pose.z for s in traj.steps])
    return world.grid.clearance_at(xs, zs).astype(float)


def _failure_mode(traj: Trajectory, collisions: int, revisit_ratio: float) -> FailureMode:
    m = traj.metrics
    ended = bool(traj.steps) and traj.steps[-1].action == "end"
    if ended:
        near = m is not None and m.final_geodesic is not None and m.final_geodesic <= 0.05
        return "ended_without_sight" if near else "ended_too_far"
    if m is not None and m.first_sight_step is None:
        return "never_saw_target"
    tail = traj.steps[-100:]
    tail_moves = [s for s in tail if s.action in ("m", "b")]
    if tail_moves and sum(not s.moved for s in tail_moves) / len(tail_moves) > 0.4:
        return "stuck"
    if revisit_ratio > 0.5:
        return "looping"
    return "timeout"


#: Recorded and house target positions may differ by this much (m) and still be the same house.
SAME_PLACE = 0.01
#: A recorded pose may stand this far (m) outside every room (doorways, rounding) and still be on the floor.
OFF_FLOOR = 0.5


def trajectory_mismatch(traj: Trajectory, world: NavWorld) -> str | None:
    """Why ``traj`` cannot have been recorded in ``world`` (its targets differ), or None when it fits."""
    inst = world.instances_of(traj.target_type)
    have = {i.object_id: (float(i.center[0]), float(i.center[1])) for i in inst}
    if sorted(have) != sorted(traj.target_ids):
        return (f"its {traj.target_type} instances are {', '.join(traj.target_ids) or 'none'}, the house's are "
                f"{', '.join(sorted(have)) or 'none'}")
    for oid, (x, z) in zip(traj.target_ids, traj.target_positions, strict=False):
        hx, hz = have[oid]
        if math.hypot(hx - x, hz - z) > SAME_PLACE:
            return (f"{oid} stands at ({metres(hx)}, {metres(hz)}) m in the house but at ({metres(x)}, "
                    f"{metres(z)}) m in the trajectory")
    return None


def pose_outside(traj: Trajectory, world: NavWorld) -> str | None:
    """Which pose of ``traj`` lies off the house's floor (its rooms, widened by ``OFF_FLOOR``), or None."""
    poses = [("start", traj.start), *((f"step {i}", s.pose) for i, s in enumerate(traj.steps))]
    if traj.final_pose is not None:
        poses.append(("the final pose", traj.final_pose))
    floor = shapely.unary_union(list(world.geometry.rooms.values())).buffer(OFF_FLOOR)
    xs = np.array([p.x for _, p in poses], dtype=np.float64)
    zs = np.array([p.z for _, p in poses], dtype=np.float64)
    inside = shapely.contains_xy(floor, xs, zs)
    if inside.all():
        return None
    k = int(np.argmin(inside))
    return f"{poses[k][0]} stands at ({metres(xs[k])}, {metres(zs[k])}) m, off the house's floor"


def analyze_trajectory(traj: Trajectory, world: NavWorld) -> Analysis:
    """The built-in F: derive outcome, concerns and suggestions from a recorded episode.

    Deterministic: the same trajectory and world always give the same analysis.
    """
    grid = world.geometry.grid
    m = traj.metrics
    n = len(traj.steps)
    task = f"Find a {traj.target_type} (ObjectNav) in house {traj.house}."

    def gp(x: float, z: float) -> GridPoint:
        gx, gy = grid.point(x, z)
        return GridPoint(x=round(gx, 1), y=round(gy, 1))

    concerns: list[Concern] = []

    def add(kind: ConcernKind, severity: float, text: str, steps: list[int], objects: list[str],
            runs: list[list[int]] | None = None) -> Concern:
        """Record a concern; ``runs`` are its separate bouts (default: ``steps`` is one bout)."""
        runs = runs if runs is not None else ([steps] if steps else [])
        where = None
        if runs:
            longest = max(runs, key=len)
            mid = traj.steps[longest[len(longest) // 2]].pose
            where = gp(mid.x, mid.z)
        first, last = (runs[0][0], runs[-1][-1]) if runs else (None, None)
        c = Concern(id=f"c{len(concerns) + 1}", kind=kind, severity=float(np.clip(severity, 0, 1)), description=text,
                    steps=[first, last] if runs else [], where=where, objects=objects, count=max(1, len(runs)),
                    occurrences=[(r[0], r[-1]) for r in runs])
        concerns.append(c)
        return c

    # Collisions: blocked moves, one concern per obstacle with every bout of bumping into it.
    blocked = [i for i, s in enumerate(traj.steps) if s.action in ("m", "b") and not s.moved]
    for obj, runs in _by_object(world, traj, blocked).items():
        hits = sum(len(r) for r in runs)
        add("collision", min(1.0, 0.3 + 0.1 * hits), f"{hits} blocked move(s) against {obj or 'an obstacle'}"
            f"{_times(runs)}", [], [obj] if obj else [], runs)

    # Proximity and narrow clearances along the path.
    clear = _clearances(world, traj) if n else np.zeros(0)
    close = [i for i in range(n) if clear[i] < AGENT_RADIUS + PROXIMITY_MARGIN]
    for obj, runs in _by_object(world, traj, close).items():
        gap = float(min(clear[r].min() for r in runs) - AGENT_RADIUS)
        add("close_proximity", 1.0 - gap / PROXIMITY_MARGIN, f"the agent's edge came within {max(gap, 0) * 100:.0f} cm "
            f"of {obj or 'an obstacle'}{_times(runs)}", [], [obj] if obj else [], runs)
    narrow = [i for i in range(n) if AGENT_RADIUS + PROXIMITY_MARGIN <= clear[i] < NARROW_CLEARANCE
              and traj.steps[i].action == "m"]
    for obj, runs in _by_object(world, traj, narrow, gap=2).items():
        runs = [r for r in runs if len(r) >= 2]
        if not runs:
            continue
        tightest = min(clear[r].min() for r in runs)
        add("narrow_clearance", 0.3 + 0.05 * max(len(r) for r in runs), f"the route passes a narrow gap "
            f"({tightest:.2f} m clearance) by {obj or 'obstacles'}{_times(runs)}", [], [obj] if obj else [], runs)

    # Detour against the geodesic optimum.
    if m is not None and m.optimal_path_length and m.path_length > 0:
        ratio = m.path_length / max(m.optimal_path_length, MOVE_STEP)
        if ratio > 1.5:
            add("detour", min(1.0, (ratio - 1.0) / 3.0), f"the path ({m.path_length:.1f} m) is {ratio:.1f}x the "
                f"shortest route ({m.optimal_path_length:.1f} m)", [0, n - 1] if n else [], [])

    # Revisits and oscillation.
    cells = [(math.floor(s.pose.x / REVISIT_CELL), math.floor(s.pose.z / REVISIT_CELL)) for s in traj.steps
             if s.action in ("m", "b") and s.moved]
    counts = Counter(cells)
    revisits = sum(c - 1 for c in counts.values() if c > 1)
    revisit_ratio = revisits / max(len(cells), 1)
    if revisits >= 5 and revisit_ratio > 0.25:
        hot, hits = counts.most_common(1)[0]
        steps_hot = [i for i, s in enumerate(traj.steps)
                     if (math.floor(s.pose.x / REVISIT_CELL), math.floor(s.pose.z / REVISIT_CELL)) == hot]
        add("revisit", min(1.0, revisit_ratio), f"{revisits} revisits of places already seen; one spot visited "
            f"{hits} times", steps_hot, [])
    turns = [s.action for s in traj.steps if s.action in ("l", "r", "ls", "rs")]
    flips = sum(1 for a, b in zip(turns, turns[1:], strict=False) if a[0] != b[0])
    if len(turns) > 20 and flips / len(turns) > 0.4:
        add("oscillation", min(1.0, flips / len(turns)), f"the agent alternated left and right turns {flips} times",
            [i for i, s in enumerate(traj.steps) if s.action in ("l", "r", "ls", "rs")], [])

    # When the target was first seen.
    if m is not None and n:
        if m.first_sight_step is None:
            add("late_sight", 1.0, "the agent never had the target in sight", [], list(traj.target_ids))
        elif n > m.first_sight_step > 0.5 * n and m.first_sight_step > 20:  # a step of this episode
            add("late_sight", m.first_sight_step / n, f"the target was first seen at step {m.first_sight_step} of {n}",
                [m.first_sight_step], list(traj.target_ids))
        if not m.success and traj.steps[-1].action == "end":
            add("premature_end", 0.8, "the agent stopped before the target was in view within 2 m", [n - 1], [])

    failure = None if (m is not None and m.success) else _failure_mode(traj, len(blocked), revisit_ratio)
    if m is not None and m.success:
        summary = f"reached the {traj.target_type} in {n} steps (SPL {m.spl:.2f}, {m.collisions} collisions)"
    else:
        summary = f"did not find the {traj.target_type} within {n} steps ({failure})"
    outcome = Outcome(success=bool(m and m.success), failure_mode=failure, summary=summary, steps=n,
                      spl=m.spl if m else None)
    return Analysis(task=task, outcome=outcome, concerns=concerns, suggestions=_suggest(concerns, outcome, traj))


def _suggest(concerns: list[Concern], outcome: Outcome, traj: Trajectory) -> list[Suggestion]:
    """Map concerns to abstract environment changes that train the weakness they reveal."""
    by_kind: dict[str, list[Concern]] = {}
    for c in concerns:
        by_kind.setdefault(c.kind, []).append(c)
    out: list[Suggestion] = []

    def add(kind: SuggestionKind, text: str, kinds: tuple[str, ...], priority: float) -> None:
        cited = sorted((c for k in kinds for c in by_kind.get(k, [])), key=lambda c: (-c.severity, -c.count))
        ids = sorted((c.id for c in cited[:MAX_ADDRESSED]), key=lambda cid: int(cid[1:]))
        out.append(Suggestion(id=f"s{len(out) + 1}", kind=kind, description=text, addresses=ids, priority=priority))

    tight = ("collision", "close_proximity", "narrow_clearance")
    if any(k in by_kind for k in tight):
        add("narrow_passage", "narrow the passages the agent relies on so it must pass close obstacles with care",
            tight, 0.9)
    if outcome.success or "late_sight" not in by_kind:
        add("occlude_target", f"hide the {traj.target_type} from the agent's approach so it must search longer",
            ("late_sight",), 0.7 if outcome.success else 0.5)
    add("lengthen_route", "make the shortest route to the target longer, e.g. by closing the direct way",
        ("detour", "revisit", "oscillation"), 0.6 if outcome.success else 0.4)
    add("add_clutter", "add clutter along the agent's path so free space is less obvious",
        ("collision", "close_proximity", "revisit", "oscillation"), 0.5)
    if outcome.success and outcome.steps < MAX_STEPS // 6:
        for s in out:
            s.priority = min(1.0, s.priority + 0.1)
    return sorted(out, key=lambda s: -s.priority)


# --------------------------------------------------------------------------- analyzers (F)

@runtime_checkable
class Analyzer(Protocol):
    """The paper's F: a recorded episode in a compiled house -> :class:`Analysis`."""

    name: str

    def analyze(self, trajectory: Trajectory, world: NavWorld) -> Analysis:
        """Outcome, concerns and suggestions for one episode."""
        ...


class BuiltinAnalyzer:
    """The offline, deterministic F (:func:`analyze_trajectory`) behind the :class:`Analyzer` protocol."""

    name = "builtin"

    def analyze(self, trajectory: Trajectory, world: NavWorld) -> Analysis:
        return analyze_trajectory(trajectory, world)


class LLMConcern(BaseModel):
    """One concern as the model reports it (grid position may be unknown)."""

    kind: ConcernKind
    severity: float
    description: str
    grid_x: float | None
    grid_y: float | None
    objects: list[str]


class LLMSuggestion(BaseModel):
    """One abstract suggestion as the model reports it; ``addresses`` holds concern numbers (1-based)."""

    kind: SuggestionKind
    description: str
    addresses: list[int]
    priority: float


class LLMOutcome(BaseModel):
    """The paper's success assessment: did the robot succeed, how it failed, in one sentence."""

    success: bool
    failure_mode: FailureMode | None
    summary: str


class LLMAnalysisAnswer(BaseModel):
    """The structured answer F's model must give: the paper's three parts by name, each with adaptenv's fields."""

    outcome: LLMOutcome
    concerns: list[LLMConcern]
    suggestions: list[LLMSuggestion]


ANALYZER_SYSTEM = (
    "You are an expert reviewer of household robot navigation. You look at a top-down floor plan on "
    "which one episode of a robot searching for an object is drawn, and you report what happened so "
    "that a level designer can make the apartment more demanding for this robot.")

ANALYZER_PROMPT = """{task}

How to read the image: north is up. A normalized grid runs from 0 to 100 along both axes (x to the
right, y upward; ticks every 10 units). The robot's path goes from yellow (start) to orange (end);
red x marks are blocked moves (collisions); orange crosses mark every instance of the target
object; furniture is drawn as labelled rectangles with a tick on its front side.

Report three things:
1. outcome: did the robot succeed (stop with the target in view within 2 m)? If not, choose a
   failure_mode from: timeout, ended_too_far, ended_without_sight, stuck, looping, never_saw_target.
   Add a one-sentence summary.
2. concerns: behaviour worth training on, even when the episode succeeded. Each has a kind from:
   collision, close_proximity, narrow_clearance, detour, revisit, oscillation, late_sight,
   premature_end; a severity between 0 and 1; a short description; where it happened (grid_x,
   grid_y, or null if it concerns the whole episode); and the ids of the objects involved, copied
   from the labels in the image.
3. suggestions: what aspect of the apartment should change so the robot has to practise handling
   these concerns. Each has a kind from: narrow_passage, occlude_target, lengthen_route,
   add_clutter; a description of WHAT should change (not how: do not name positions or moves);
   the numbers (1-based) of the concerns it addresses; and a priority between 0 and 1."""


def render_for_analysis(trajectory: Trajectory, world: NavWorld, *, size: int = 768) -> bytes:
    """The PNG F looks at: the top-down map with the normalized grid and the episode drawn on it."""
    return png_bytes(render_house(None, geometry=world.geometry, trajectory=trajectory, grid=True, size=size))


def answer_to_analysis(answer: LLMAnalysisAnswer, task: str, trajectory: Trajectory,
                       known_ids: set[str] | None = None) -> Analysis:
    """Convert the model's structured answer to an :class:`Analysis` (ids c1.., s1..; unknown object ids dropped)."""
    concerns = []
    for k, c in enumerate(answer.concerns, 1):
        where = None
        if c.grid_x is not None and c.grid_y is not None and math.isfinite(c.grid_x) and math.isfinite(c.grid_y):
            where = GridPoint(x=float(np.clip(c.grid_x, 0, 100)), y=float(np.clip(c.grid_y, 0, 100)))
        objs = [o for o in c.objects if known_ids is None or o in known_ids]
        concerns.append(Concern(id=f"c{k}", kind=c.kind, severity=float(np.clip(np.nan_to_num(c.severity), 0, 1)),
                                description=c.description, where=where, objects=objs))
    suggestions = []
    for k, s in enumerate(answer.suggestions, 1):
        refs = [f"c{i}" for i in s.addresses if 1 <= i <= len(concerns)]
        suggestions.append(Suggestion(id=f"s{k}", kind=s.kind, description=s.description, addresses=refs,
                                      priority=float(np.clip(np.nan_to_num(s.priority), 0, 1))))
    suggestions.sort(key=lambda s: -s.priority)
    m = trajectory.metrics
    said = answer.outcome
    outcome = Outcome(success=said.success, failure_mode=None if said.success else said.failure_mode,
                      summary=said.summary, steps=len(trajectory.steps), spl=m.spl if m else None)
    return Analysis(task=task, outcome=outcome, concerns=concerns, suggestions=suggestions, source="llm")


class LLMAnalyzer:
    """F on a vision-language model: the trajectory render plus the task in, a structured analysis out.

    Invalid answers are sent back with the validation error (``max_attempts`` in all); when every
    attempt fails, the built-in analysis is returned (``source="builtin-fallback"``) unless
    ``fallback=False``, in which case the last error is raised. Transport failures and a used-up
    budget are raised, never hidden behind the fallback. ``prompts="paper"`` (default: the
    backend config's) sends the paper's appendix prompt verbatim, without a system message. The
    tokens of every call are in ``Analysis.usage``.

    Example:
        >>> from adaptenv.adapt.llm import LLMConfig, make_backend
        >>> f = LLMAnalyzer(make_backend(LLMConfig(model="gpt-4.1-mini")))  # doctest: +SKIP
        >>> analysis = f.analyze(trajectory, world)  # doctest: +SKIP
    """

    name = "llm"

    def __init__(self, backend: LLMBackend, *, max_attempts: int = 3, image_size: int = 768, fallback: bool = True,
                 prompts: str | None = None):
        self.backend = backend
        self.max_attempts = max_attempts
        self.image_size = image_size
        self.fallback = fallback
        self.prompts = prompts or getattr(getattr(backend, "config", None), "prompts", "adaptenv")
        self.last_error: str | None = None

    def prompt(self, trajectory: Trajectory) -> str:
        """The user prompt: the paper's verbatim, or the task description and what to report."""
        if self.prompts == "paper":
            return PAPER_F_PROMPT
        task = f"Task: the robot had to find a {trajectory.target_type} (object navigation) in this apartment."
        return ANALYZER_PROMPT.format(task=task)

    def analyze(self, trajectory: Trajectory, world: NavWorld) -> Analysis:
        png = render_for_analysis(trajectory, world, size=self.image_size)
        messages = [Message.user(self.prompt(trajectory), png)]
        task = f"Find a {trajectory.target_type} (ObjectNav) in house {trajectory.house}."
        known = {f.object_id for f in world.geometry.footprints}
        system = "" if self.prompts == "paper" else ANALYZER_SYSTEM
        self.last_error = None
        with self.backend.track() as usage:
            for attempt in range(self.max_attempts):
                try:
                    answer = self.backend.parse(system, messages, None, LLMAnalysisAnswer, role="F")
                except ModelAnswerError as exc:
                    self.last_error = str(exc)
                    log.info("analysis answer %d rejected: %s", attempt + 1, exc)
                    messages += [Message.assistant(exc.raw or "(no answer)"), Message.user(exc.feedback)]
                    continue
                out = answer_to_analysis(answer.value, task, trajectory, known)
                out.usage = usage.to_dict()
                return out
        if not self.fallback:
            raise LLMError(f"the analysis model gave no valid answer in {self.max_attempts} attempts "
                           f"(last: {self.last_error})")
        log.warning("falling back to the built-in analysis: %s", self.last_error)
        out = analyze_trajectory(trajectory, world)
        out.source = "builtin-fallback"
        out.usage = usage.to_dict()
        return out


def make_analyzer(name: str = "builtin", **kw) -> Analyzer:
    """``builtin`` (default, offline) or ``llm`` (needs ``backend=`` from ``adapt.llm.make_backend``)."""
    if name == "builtin":
        return BuiltinAnalyzer()
    if name == "llm":
        return LLMAnalyzer(**kw)
    raise ConfigError(f"unknown analyzer {name!r}; use builtin or llm")
