"""The built-in G: suggestions become objectives; candidate moves are searched, scored and verified.

Per step (offline, deterministic for a given rng):

1. Target one suggestion of the analysis (round-robin over suggestions sorted by priority).
2. Draw candidate moves of movable objects near the route (the agent's and the current shortest
   one) or near the target: displacements toward / across the route, sideways along it, toward
   the target, and turns by +-90 or 180 degrees, all on the normalized grid; objects that must keep
   their back to a wall slide along it (:func:`along_wall`) or are set against the parallel wall
   nearest to where the move aimed (:func:`to_wall`, a relocation inside their room) instead. The targets
   themselves are never moved, so the episode stays comparable (the validator refuses it:
   ``target_moved``). Each move is fitted to the plausibility rules before its dry run
   (:func:`fit_rules`: shortened until its end pose breaks none, or not drawn).
3. Dry-run them in order (up to ``POOL`` times ``max_candidates`` drawn, until ``max_candidates``
   pass) through collision-aware placement and incremental validation
   (:meth:`~adaptenv.adapt.validation.EditValidator.propose`, which also applies the plausibility
   rules of :mod:`adaptenv.adapt.plausibility`); score valid ones by the targeted
   objective's gain, plus a smaller weight on the other suggestions' gains, plus
   ``realism_weight`` times the change in realism (:mod:`adaptenv.adapt.realism`). Candidates on
   which the shortest-path expert no longer solves the episode are dropped (``require_expert``):
   the raster says the route exists, but the agent's continuous motion may not fit through it.
4. With a policy in the context, roll it out on the best candidates of ``rollout_candidates``
   distinct objects (the same start and target, a few headings) and prefer the one on which it
   succeeds least often, then with the lowest mean SPL: the paper's argmin over R subject to validity.
5. Verification: the targeted objective must move in the intended direction; otherwise revise
   by taking the next candidate (at most ``max_revisions`` times).
6. Commit the chosen proposal with ``EditValidator.commit``, re-render.

Cost: one ``compile_world`` plus one distance field and a few line-of-sight walks per candidate
(about 7 ms on a 5-room house); ``max_candidates`` bounds it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from adaptenv.adapt.analysis import Analysis, Suggestion
from adaptenv.adapt.edits import Edit
from adaptenv.adapt.generators._trial import edited_copy, moved_geometry
from adaptenv.adapt.generators.base import (
    GenerationContext,
    GenerationResult,
    StepRecord,
    keep_render,
    render_scene,
)
from adaptenv.adapt.objectives import (
    OBJECTIVE_KINDS,
    OTHER_WEIGHT,
    ObjectiveValues,
    RouteSpec,
    gain,
    measure,
    realism_score,
    route_points,
    suggestion_weights,
    weighted_gain,
)
from adaptenv.adapt.plausibility import OVERHANG, breaks_rules
from adaptenv.adapt.realism import RealismReference
from adaptenv.adapt.validation import EditValidator, Proposal, world_fits
from adaptenv.adapt.verification import Check, check_objective, revise_until_verified
from adaptenv.agents.rollout import checking_episodes, mean_spl, run_in_worlds, total_steps
from adaptenv.scene.geometry import Footprint, SceneGeometry, heading
from adaptenv.scene.house import House
from adaptenv.sim.geodesic import reuse_region
from adaptenv.sim.rollout import expert_policy, run_episode
from adaptenv.sim.task import Episode
from adaptenv.sim.world import NavWorld, compile_world

#: Objects whose footprint centre is within this distance (m) of a route point count as "near the route".
NEAR_ROUTE = 1.6
#: ... or within this distance (m) of a target instance.
NEAR_TARGET = 2.5
#: When fewer objects are near, the nearest this many are used instead.
MIN_OBJECTS = 4
#: Candidates drawn per step, in multiples of ``max_candidates``: they are dry-run in order until
#: ``max_candidates`` pass (many are refused by the plausibility rules).
POOL = 3
#: Minimal achieved translation (m) for a move without rotation to count as a change.
MIN_MOVE = 0.05

MOVE_KINDS = ("toward", "across", "sideways", "toward_target", "turn")


@dataclass
class Candidate:
    """One proposal and, once tried, its dry run, the edited world and its scores."""

    object_id: str
    dx_units: float
    dy_units: float
    rotation: float | None
    kind: str
    relocate: bool = False
    """Set the object down at the move's end (possibly in another room) instead of marching."""
    proposal: Proposal | None = None
    world: NavWorld | None = None
    values: ObjectiveValues | None = None
    realism: float | None = None
    score: float = -math.inf
    policy_score: float | None = None
    openness: float | None = None
    """A door edit (``object_id`` is the door's id): the door's new openness; None for a move."""


def along_wall(v: EditValidator, oid: str, d: np.ndarray, rotation: float | None, rng: np.random.Generator
               ) -> tuple[np.ndarray, float | None]:
    """An object that must keep its back to a wall (see :mod:`adaptenv.adapt.plausibility`) slides along it: the
    displacement ``d`` (m) projected on the wall, heading kept; a pure turn becomes a slide of 0.4-1.2 m."""
    if v.plausible is None or oid not in v.plausible.anchored:
        return d, rotation
    h = heading(float(v.ctx.yaws[v.ctx.index[oid]]))
    t = np.array([h[1], -h[0]])
    along = float(np.dot(d, t)) if np.any(d) else float(rng.choice([-1.0, 1.0]) * rng.uniform(0.4, 1.2))
    return t * _within_wall(v, oid, t, along), None


def _within_wall(v: EditValidator, oid: str, t: np.ndarray, along: float) -> float:
    """The longest of ``along`` and its three quarters, half and quarter (m along ``t``) that keeps the object from
    running past the end of its wall (the plausibility rule ``wall_overhang``); ``along`` when none does."""
    ref, i = v.plausible, v.ctx.index[oid]
    limit = max(OVERHANG, ref.overhang.get(oid, 0.0) + 0.05)
    c, yaw = v.ctx.centers[i], float(v.ctx.yaws[i])
    for f in (1.0, 0.75, 0.5, 0.25):
        if ref.walls.overhang(v.footprint_at(i, c + t * along * f, yaw)) <= limit:
            return along * f
    return along


def fit_rules(v: EditValidator, current: dict[str, Footprint], oid: str, d: np.ndarray, rotation: float | None,
              *, shrink: bool = True) -> np.ndarray | None:
    """The longest of the displacement ``d`` (m) and its three quarters, half and quarter whose end pose (turned to
    ``rotation``) breaks no plausibility rule, with the other objects where ``current`` has them; None when none does
    (only ``d`` itself is tried for a turn in place or with ``shrink`` off). The dry run still decides: placement
    may stop short of the end. The end pose checked is the one a candidate asks for, the displacement rounded to a
    tenth of a grid unit (a rule's threshold can lie between the two)."""
    if v.plausible is None:
        return d
    i, upm = v.ctx.index[oid], v.ctx.grid.units_per_meter
    c, yaw = v.ctx.centers[i], float(v.ctx.yaws[i]) if rotation is None else float(rotation)
    for f in (1.0, 0.75, 0.5, 0.25) if shrink and np.any(d) else (1.0,):
        asked = np.round(np.asarray(d, dtype=float) * f * upm, 1) / upm
        if not breaks_rules(v.plausible, v.footprint_at(i, c + asked, yaw), current):
            return d * f
    return None


def to_wall(v: EditValidator, oid: str, aim: np.ndarray) -> tuple[np.ndarray, float] | None:
    """For an object that must keep its back to a wall: the displacement (m) and yaw that set it against the wall
    of its room nearest to ``aim`` that runs parallel to it (turned 180 degrees for the opposite wall); None for
    other objects or when no such wall is near."""
    ref, ctx = v.plausible, v.ctx
    if ref is None or oid not in ref.anchored:
        return None
    i = ctx.index[oid]
    c, yaw = ctx.centers[i], float(ctx.yaws[i])
    h, half_w, half_d = heading(yaw), float(ctx.sizes[i, 0]) / 2.0, float(ctx.sizes[i, 1]) / 2.0
    room = v.geometry.room_of_point(float(c[0]), float(c[1]))
    p0, d = ref.walls.p0, ref.walls.p1 - ref.walls.p0  # every wall at once, each as the one-wall arithmetic
    length = np.hypot(d[:, 0], d[:, 1])
    long_enough = length >= 2.0 * half_w + 0.1
    u = d / np.where(long_enough, length, 1.0)[:, None]
    rel = aim - p0
    n = np.stack([-u[:, 1], u[:, 0]], axis=1)
    n = np.where((n[:, 0] * rel[:, 0] + n[:, 1] * rel[:, 1] < 0)[:, None], -n, n)
    parallel = np.abs(n[:, 0] * h[0] + n[:, 1] * h[1]) >= 0.99
    t = np.clip(rel[:, 0] * u[:, 0] + rel[:, 1] * u[:, 1], half_w + 0.05, length - half_w - 0.05)
    centers = p0 + t[:, None] * u + n * (half_d + 0.03)
    dist = np.hypot(centers[:, 0] - aim[0], centers[:, 1] - aim[1])
    best, best_d = None, np.inf
    for k in np.flatnonzero(long_enough & parallel):
        if dist[k] < best_d and v.geometry.room_of_point(float(centers[k, 0]), float(centers[k, 1])) == room:
            best, best_d = (centers[k] - c, math.degrees(math.atan2(n[k, 0], n[k, 1])) % 360.0), float(dist[k])
    return best


def _distinct_head(ranked: list[Candidate], k: int) -> list[Candidate]:
    """The first ``k`` candidates of ``ranked`` that move distinct objects (the policy checks several objects' moves
    rather than near-copies of one), filled with the next best when fewer objects are there."""
    head: list[Candidate] = []
    for c in ranked:
        if len(head) < k and all(c.object_id != h.object_id for h in head):
            head.append(c)
    for c in ranked:
        if len(head) < k and all(c is not h for h in head):
            head.append(c)
    return head


def suggestion_order(step: int, suggestions: list[Suggestion]) -> list[Suggestion]:
    """Suggestions (one per kind, by priority) starting with the step's round-robin choice."""
    usable, kinds = [], set()
    for s in suggestions:
        if s.kind in OBJECTIVE_KINDS and s.kind not in kinds:
            usable.append(s)
            kinds.add(s.kind)
    if not usable:
        return []
    k = step % len(usable)
    return usable[k:] + usable[:k]


class BuiltinGenerator:
    """Offline G: objective-driven search over validated single-object moves (see module docstring)."""

    name = "builtin"
    move_targets = False
    """Whether the validator lets the episode's target instances move (only edit kinds that relocate the target)."""

    def __init__(self, *, max_candidates: int = 24, realism_weight: float = 0.5, other_weight: float = OTHER_WEIGHT,
                 rollout_candidates: int = 5, max_revisions: int = 2, require_expert: bool = True,
                 fit_to_rules: bool = True):
        """``fit_to_rules``: fit every move to the plausibility rules before its dry run (:func:`fit_rules`; off only
        to measure what the fitting adds: the validator refuses what breaks a rule either way)."""
        self.max_candidates = max_candidates
        self.fit_to_rules = fit_to_rules
        self.require_expert = require_expert
        self._expert = expert_policy()
        self.realism_weight = realism_weight
        self.other_weight = other_weight
        self.rollout_candidates = rollout_candidates
        self.max_revisions = max_revisions

    # ----------------------------------------------------------------------------- the loop
    def generate(self, house: House, analysis: Analysis, *, steps: int, context: GenerationContext,
                 rng: np.random.Generator) -> GenerationResult:
        ep, original = context.episode, RealismReference.of(house)
        route, v, world, values, realism, result = self._begin(house, context, original)
        suggestions = sorted(analysis.suggestions, key=lambda s: -s.priority)
        targets = {t.object_id for t in world.instances_of(ep.target_type)}
        for step in range(steps):
            order = suggestion_order(step, suggestions)
            if not order:
                result.steps.append(StepRecord(step=step, status="skipped",
                                               reason="the analysis has no suggestion with an objective"))
                continue
            cands = self._candidates(v, world, route, targets, rng, limit=POOL * self.max_candidates)
            tried = self._try(v, cands, route, original, ep, base=world)
            rollouts: dict[int, tuple[int, float]] = {}
            record = StepRecord(step=step, status="skipped", suggestion_id=order[0].id,
                                suggestion_kind=order[0].kind, candidates=len(cands), passed=len(tried),
                                objective_before=values.as_dict())
            if not tried:
                record.reason = "no candidate move passed placement and validation"
                result.steps.append(record)
                continue
            chosen, sug = None, order[0]
            for sug in order:  # the step's suggestion first; the others when none of its candidates verifies
                ranked = self._rank(tried, sug, suggestions, values, realism)
                if context.policy is not None:
                    ranked = self._rollout_rank(ranked, world, context, record, rollouts)
                chosen = self._verify(ranked, sug.kind, values, record)
                if chosen is not None:
                    break
            record.suggestion_id, record.suggestion_kind = sug.id, sug.kind
            if chosen is None:
                record.reason = "no valid candidate made any suggested objective harder"
                result.steps.append(record)
                continue
            # The dry run was made on the current scene and found no problem: committing applies it.
            edit = v.commit(chosen.proposal, source=self.name, intent=f"{sug.id} {sug.kind}: {chosen.kind} move")
            if not edit.changed:  # guard: a move that changes nothing is never applied nor verified
                record.status, record.edit, record.verified = "no-op", edit, None
                record.reason = "the chosen move changed neither position nor heading"
                result.steps.append(record)
                continue
            record.gain = gain(sug.kind, values, chosen.values)
            world, values, realism = self._applied(v, chosen, edit, record, result, context, step)
        result.house, result.world = v.house, world
        return result

    def _begin(self, house: House, context: GenerationContext, reference: RealismReference
               ) -> tuple[RouteSpec, EditValidator, NavWorld, ObjectiveValues, float, GenerationResult]:
        """The search's start: the route of pi_t's episode, a validator over ``house`` (the scene so far), its
        compiled world, objective values and realism (against ``reference``, built from ``house``), and a result
        with the first objective trace entry."""
        ep = context.episode
        route = RouteSpec.from_episode(ep.target_type, ep.start, context.trajectory)
        v = EditValidator(house, episode_targets=[ep.target_type], start=ep.start[:2], move_targets=self.move_targets,
                          world=context.world, placement_model=context.placement_model)
        world = context.world if world_fits(context.world, v.geometry) else compile_world(v.house, "candidate")
        values = measure(world, route)
        result = GenerationResult(house=v.house, steps=[], edit_log=v.log, generator=self.name,
                                  objective_trace=[values.as_dict()])
        return route, v, world, values, realism_score(v.house, reference), result

    def _applied(self, v: EditValidator, chosen: Candidate, edit: Edit, record: StepRecord, result: GenerationResult,
                 context: GenerationContext, step: int) -> tuple[NavWorld, ObjectiveValues, float | None]:
        """Record a committed edit (status, objectives, trace, render) and return the new scene's world,
        objective values and realism for the next step."""
        record.status, record.edit, record.objective_after = "applied", edit, chosen.values.as_dict()
        result.objective_trace.append(chosen.values.as_dict())
        if context.render:
            record.render = keep_render(result, render_scene(v.house, context, highlight={edit.object_id: "gold"}),
                                        context, step)
        result.steps.append(record)
        world = chosen.world if world_fits(chosen.world, v.geometry) else compile_world(v.house, "candidate")
        return world, chosen.values, chosen.realism

    # ----------------------------------------------------------------------------- candidates
    def _try(self, v: EditValidator, cands: list[Candidate], route: RouteSpec, original: RealismReference,
             episode: Episode, *, base: NavWorld | None = None) -> list[Candidate]:
        """Dry-run candidates in order until ``max_candidates`` pass (placement, validation, plausibility, expert);
        ``base``: the compiled world of ``v.house``, whose success region a candidate far from the target keeps."""
        geometry = SceneGeometry.from_house(v.house)
        tried: list[Candidate] = []
        for c in cands:
            if len(tried) >= self.max_candidates:
                break
            if self._evaluate(v, geometry, c, route, original, episode, base=base) is not None:
                tried.append(c)
        return tried

    def _candidates(self, v: EditValidator, world: NavWorld, route: RouteSpec, targets: set[str],
                    rng: np.random.Generator, limit: int | None = None) -> list[Candidate]:
        """Up to ``limit`` (default ``max_candidates``) distinct proposals for objects near the route or the target."""
        limit = limit or self.max_candidates
        ctx = v.ctx
        pts = route_points(world, route)
        if len(pts) == 0:
            pts = np.array([route.start])
        tpos = np.array([ctx.centers[ctx.index[t]] for t in sorted(targets) if t in ctx.index]).reshape(-1, 2)
        ids = [oid for oid, m in zip(ctx.ids, ctx.movable, strict=True) if m and oid not in targets]
        if not ids:
            return []
        centers = np.array([ctx.centers[ctx.index[o]] for o in ids])
        d_route = np.min(np.hypot(centers[:, None, 0] - pts[None, :, 0], centers[:, None, 1] - pts[None, :, 1]), axis=1)
        d_target = (np.min(np.hypot(centers[:, None, 0] - tpos[None, :, 0], centers[:, None, 1] - tpos[None, :, 1]),
                           axis=1) if len(tpos) else np.full(len(ids), np.inf))
        near = np.flatnonzero((d_route < NEAR_ROUTE) | (d_target < NEAR_TARGET))
        if len(near) < MIN_OBJECTS:
            near = np.argsort(np.minimum(d_route, d_target))[:MIN_OBJECTS]
        weights = 1.0 / (0.3 + np.minimum(d_route[near], d_target[near]))
        weights /= weights.sum()
        upm = ctx.grid.units_per_meter
        current = {f.object_id: f for f in v.geometry.footprints}
        out: list[Candidate] = []
        seen: set[tuple] = set()
        for _ in range(limit * 3):
            if len(out) >= limit:
                break
            k = int(near[rng.choice(len(near), p=weights)])
            oid = ids[k]
            c = centers[k]
            kind = MOVE_KINDS[int(rng.integers(len(MOVE_KINDS)))]
            j = int(np.argmin(np.hypot(pts[:, 0] - c[0], pts[:, 1] - c[1])))
            to_route = pts[j] - c
            rotation = None
            if kind == "toward":
                d = to_route * rng.uniform(0.5, 1.0)
            elif kind == "across":
                d = to_route * rng.uniform(1.2, 1.8)
            elif kind == "sideways":
                a, b = pts[max(j - 1, 0)], pts[min(j + 1, len(pts) - 1)]
                tangent = (b - a) / max(float(np.hypot(*(b - a))), 1e-9)
                d = tangent * rng.choice([-1.0, 1.0]) * rng.uniform(0.4, 1.2)
            elif kind == "toward_target" and len(tpos):
                t = tpos[int(np.argmin(np.hypot(tpos[:, 0] - c[0], tpos[:, 1] - c[1])))]
                d = (t - c) * rng.uniform(0.3, 0.8)
            else:
                kind = "turn"
                d = np.zeros(2)
                yaw = float(ctx.yaws[ctx.index[oid]])
                rotation = (yaw + float(rng.choice([90.0, 180.0, 270.0]))) % 360.0
            if kind != "turn" and rng.random() < 0.25:
                yaw = float(ctx.yaws[ctx.index[oid]])
                rotation = (yaw + float(rng.choice([90.0, 270.0]))) % 360.0
            relocate = False
            if kind in ("toward", "across", "toward_target") and (w := to_wall(v, oid, c + d)) is not None:
                d, rotation, relocate, kind = w[0], w[1], True, "to_wall"
            else:
                d, rotation = along_wall(v, oid, d, rotation, rng)
            fitted = fit_rules(v, current, oid, d, rotation, shrink=not relocate) if self.fit_to_rules else d
            if fitted is None:
                continue
            d = fitted
            dx, dy = round(float(d[0] * upm), 1), round(float(d[1] * upm), 1)
            key = (oid, dx, dy, rotation)
            if key in seen:
                continue
            seen.add(key)
            out.append(Candidate(oid, dx, dy, rotation, kind, relocate=relocate))
        return out

    def _evaluate(self, v: EditValidator, geometry: SceneGeometry, cand: Candidate, route: RouteSpec,
                  original: RealismReference, episode: Episode, *, base: NavWorld | None = None) -> Candidate | None:
        """Dry-run one proposal; None when placement or validation rejects it, it changes nothing, or
        (with ``require_expert``) the shortest-path expert no longer solves the episode."""
        proposal = v.propose(cand.object_id, cand.dx_units, cand.dy_units, cand.rotation, relocate=cand.relocate)
        res = proposal.result
        if not proposal.valid or not res.changed:
            return None
        if not res.rotation_applied and math.hypot(*res.achieved) < MIN_MOVE:
            return None
        cand.proposal = proposal
        world = compile_world(v.house, "candidate", geometry=moved_geometry(geometry, res))
        if base is not None:
            reuse_region(world, base, episode.target_type)
        return self._measure(cand, world, route, original, episode, lambda: edited_copy(v.house, res, share=True))

    def _measure(self, cand: Candidate, world: NavWorld, route: RouteSpec, original: RealismReference,
                 episode: Episode, edited: Callable[[], House]) -> Candidate | None:
        """A candidate's objectives, expert check and realism in its edited ``world`` (``edited()`` builds its house
        for the realism term); None when the route is gone or the expert no longer solves the episode."""
        cand.world, cand.values = world, measure(world, route)
        if not math.isfinite(cand.values.lengthen_route):
            return None
        if self.require_expert and not run_episode(world, episode, self._expert, record=False).metrics.success:
            return None
        if self.realism_weight > 0:
            cand.realism = realism_score(edited(), original, geometry=world.geometry)
        return cand

    def _rank(self, tried: list[Candidate], sug: Suggestion, suggestions: list[Suggestion], before: ObjectiveValues,
              realism_before: float | None) -> list[Candidate]:
        """Candidates sorted by score for this suggestion: its gain, the others' (weighted), realism change."""
        weights = suggestion_weights(sug.kind, {s.kind: s.priority for s in suggestions}, self.other_weight)
        for c in tried:
            c.score = weighted_gain(weights, before, c.values)
            if c.realism is not None and realism_before is not None:
                c.score += self.realism_weight * (c.realism - realism_before)
            c.policy_score = None
        return sorted(tried, key=lambda c: -c.score)

    def _rollout_rank(self, scored: list[Candidate], world: NavWorld, context: GenerationContext,
                      record: StepRecord, cache: dict[int, tuple[int, float]]) -> list[Candidate]:
        """Re-rank the best few candidates (of distinct objects, :func:`_distinct_head`) by the policy's successes on
        them, then its mean SPL (fewest, lowest first); ``cache``: (successes, mean SPL) by id.

        The scene itself (first time) and the candidates not yet scored are rolled out in one batch."""
        episodes = checking_episodes(context.episode, context.rollout_episodes)
        head = _distinct_head(scored, self.rollout_candidates)
        rest = [c for c in scored if all(c is not h for h in head)]
        todo = [c for c in head if id(c) not in cache]
        first = record.policy_score_before is None
        batch = run_in_worlds(([world] if first else []) + [c.world for c in todo], episodes, context.policy)
        record.check_steps += total_steps(batch)
        record.checked += len(todo)
        runs = iter(batch)
        if first:
            record.policy_score_before = mean_spl(next(runs))
        for c in todo:
            trajs = next(runs)
            cache[id(c)] = (sum(bool(t.metrics.success) for t in trajs), mean_spl(trajs))
        for c in head:
            c.policy_score = cache[id(c)][1]
        head.sort(key=lambda c: (cache[id(c)][0], round(c.policy_score, 6), -c.score))
        return head + rest

    def _verify(self, ranked: list[Candidate], kind: str, before: ObjectiveValues,
                record: StepRecord) -> Candidate | None:
        """First candidate (in rank order, at most ``max_revisions`` revisions) whose targeted objective improved."""
        order = iter(range(len(ranked)))

        def check(i: int, cand: Candidate) -> Check:
            return check_objective(kind, before, cand.values)

        def revise(i: int, cand: Candidate, chk: Check) -> int | None:
            return next(order, None)

        verdict = revise_until_verified(next(order), lambda i: ranked[i], check, revise,
                                        max_revisions=self.max_revisions, method="objective")
        record.verification, record.revisions = "objective", verdict.revisions
        record.verified, record.reason = verdict.check.passed, verdict.check.reason
        if verdict.check.passed:
            chosen = verdict.result
        else:
            return None
        record.policy_score_after = chosen.policy_score
        return chosen


__all__ = ["BuiltinGenerator", "Candidate", "Edit", "suggestion_order"]
