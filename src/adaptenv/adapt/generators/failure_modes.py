"""G aimed at failure modes: each edit answers the failure family F's diagnosis found most often.

:class:`FailureModeGenerator` is the built-in G (same validated single-object moves, the same
expert check, realism term and pi_t rollout checks) with objectives and candidate moves chosen by
failure family (:mod:`adaptenv.adapt.diagnosis`), one family per step, round robin over the
diagnosis's dominant families:

- ``search`` (never saw the target): :func:`hiddenness`, the mean of (1 - the share of route
  points that see a target) and how far along the shortest route the target is first seen, plus
  half the :func:`search_space` (reachable rooms without a target; only door edits change it).
  Moves: tall objects onto the sight lines between the route and the target; tall furniture of the
  target's room toward its doorways (hiding the view through them; validation keeps doorways
  passable); with ``relocate_targets`` (opt-in; the only edit kinds that move a target) the target
  instance itself moved inside its own room toward far corners and behind tall objects
  (``target_late``), or relocated to a far room of a type where it plausibly stands
  (``target_room``). Every move goes through the plausibility rules of
  :mod:`adaptenv.adapt.plausibility`.
- ``premature_end`` (ended too far or without sight): :func:`distractor_pressure`, objects of a
  size similar to the target's near the route. Moves: such objects toward and along the route.
- ``looping``: :func:`room_symmetry` of the rooms the route crosses plus the route length
  (blocked shortcuts). Moves: an object to the mirror image of a similar one in its room; objects
  across the shortest route.
- ``stuck``: narrower passages and clutter (the built-in objectives).
- ``timeout``: a longer route and less target visibility.

With ``door_edits`` (opt-in) the ``search``, ``looping`` and ``timeout`` families also try opening or shutting
each interior door that has a leaf (``close_door`` / ``open_door``): a shut door forces a detour or cuts rooms
off, an opened one adds rooms to search. A door edit goes through its own check
(:meth:`~adaptenv.adapt.validation.EditValidator.propose_door`): the episode's target stays reachable, the
start stays free and an opened doorway's approach stays clear.

Every step records its family and intent in the edit (``Edit.intent``) and in the step
(``StepRecord.failure_mode``). Verification: the family's objective must move in the harder
direction (checked), and pi_t's rollout on the candidate (the checking episodes) is classified by
F: ``StepRecord.produced_failure`` says whether pi_t failed there with the aimed family.
Candidates that produce it rank first, then lower pi_t SPL.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import ndimage

from adaptenv.adapt.analysis import Analysis, analyze_trajectory
from adaptenv.adapt.diagnosis import MODE_FAMILY, ModeFamily, SceneDiagnosis
from adaptenv.adapt.generators.base import (
    GenerationContext,
    GenerationResult,
    StepRecord,
)
from adaptenv.adapt.generators.builtin import POOL, BuiltinGenerator, Candidate, along_wall
from adaptenv.adapt.objectives import (
    CLEARANCE_CAP,
    MAX_VISIBILITY_POINTS,
    OBJECTIVE_KINDS,
    ObjectiveValues,
    RouteSpec,
    gain,
    route_points,
    shortest_route,
    visibility_fraction,
)
from adaptenv.adapt.realism import RealismReference
from adaptenv.adapt.validation import EditValidator
from adaptenv.agents.rollout import checking_episodes, mean_spl, run_in_worlds, total_steps
from adaptenv.scene.assets import load_catalog
from adaptenv.scene.geometry import SceneGeometry
from adaptenv.scene.house import House, is_interior_leaf_door, is_shut
from adaptenv.sim.spec import AGENT_RADIUS, MAX_RANGE
from adaptenv.sim.task import Episode, visible_points
from adaptenv.sim.world import NavWorld, compile_world

#: Objects within this distance (m) of the route count as distractors (weight falls linearly to 0).
DISTRACTOR_RANGE = 2.0
#: Footprint areas within this factor of the target's count as "similar size".
SIZE_FACTOR = 2.0
#: Mirror mismatches are capped at this distance (m) in :func:`room_symmetry`.
SYMMETRY_CAP = 2.0
#: Route length (m) that counts as much as the whole symmetry range in the looping objective.
LOOP_LENGTH_SCALE = 10.0
#: Families tried, in order, when the diagnosis found no failure (held-out failures are mostly searches).
DEFAULT_PLAN: tuple[ModeFamily, ...] = ("search", "premature_end")
#: Weight of :func:`search_space` in the search objective (beside :func:`hiddenness`, which lies in [0, 1]).
SEARCH_SPACE_WEIGHT = 0.5
#: Families whose candidates include door edits (with ``door_edits``).
DOOR_FAMILIES = ("search", "looping", "timeout")

INTENTS: dict[str, str] = {
    "sight_line": "occlude the target's sight line from the route",
    "doorway_view": "move tall furniture to hide the view through the target room's doorway",
    "target_late": "move the target inside its room where it is seen late",
    "target_room": "relocate the target to a far room of a type where it plausibly stands",
    "distractor": "bring a similar-size distractor near the route",
    "mirror": "make the room near-symmetric so places look alike",
    "block_shortcut": "block a shortcut of the shortest route",
    "close_door": "shut a door so the agent must find another way",
    "open_door": "open a shut door so there are more rooms to search",
    "generic": "built-in move near the route",
}


# --------------------------------------------------------------------------- objectives (higher = harder)

def first_sight_fraction(world: NavWorld, target_type: str, start: tuple[float, float]) -> float:
    """How far along the shortest route (0..1) a target instance first comes into sight (1: never)."""
    pts = shortest_route(world, target_type, start)
    if len(pts) == 0:
        return 1.0
    if len(pts) > MAX_VISIBILITY_POINTS:
        pts = pts[np.linspace(0, len(pts) - 1, MAX_VISIBILITY_POINTS).round().astype(int)]
    for k, (x, z) in enumerate(pts):
        if visible_points(world, float(x), float(z), 0.0, target_type, max_distance=MAX_RANGE, fov_deg=360.0).any():
            return k / max(len(pts) - 1, 1)
    return 1.0


def hiddenness(world: NavWorld, route: RouteSpec) -> float:
    """Search objective in [0, 1]: mean of (1 - visibility from the route points) and the first-sight fraction."""
    vis = visibility_fraction(world, route.target_type, route_points(world, route))
    return 0.5 * (1.0 - vis) + 0.5 * first_sight_fraction(world, route.target_type, route.start)


def search_space(world: NavWorld, route: RouteSpec) -> float:
    """Share of the house's rooms the agent can reach from the start that hold no target instance (0..1): the
    rooms it may have to search in vain. Object moves never change it (validation keeps every room reachable);
    opening a shut door can raise it, shutting one can lower it."""
    grid = world.grid
    nav = grid.navigable(AGENT_RADIUS)
    row, col = grid.to_cell(*route.start)
    if not (grid.in_bounds(row, col) and nav[int(row), int(col)]):
        return 0.0
    labels, _ = ndimage.label(nav)
    reached = set(np.unique(grid.room[labels == labels[int(row), int(col)]]).tolist()) - {-1}
    holding = {grid.room_ids.index(r) for t in world.instances_of(route.target_type)
               if (r := world.geometry.room_of_point(*t.center)) is not None}
    return len(reached - holding) / max(len(grid.room_ids), 1)


def _similar_size(fp_area: float, target_area: float) -> bool:
    return target_area > 0 and 1.0 / SIZE_FACTOR <= fp_area / target_area <= SIZE_FACTOR


def distractor_pressure(world: NavWorld, route: RouteSpec) -> float:
    """Premature-end objective: sum over non-target objects of a size similar to the target's of
    ``max(0, 1 - d / DISTRACTOR_RANGE)``, d their distance to the nearest route point."""
    fps = world.geometry.footprints
    tgt = [f.size[0] * f.size[1] for f in fps if f.object_type == route.target_type]
    pts = route_points(world, route)
    if not tgt or len(pts) == 0:
        return 0.0
    area = float(np.mean(tgt))
    total = 0.0
    for f in fps:
        if f.object_type == route.target_type or not _similar_size(f.size[0] * f.size[1], area):
            continue
        d = float(np.min(np.hypot(pts[:, 0] - f.center[0], pts[:, 1] - f.center[1])))
        total += max(0.0, 1.0 - d / DISTRACTOR_RANGE)
    return total


def _mirror(center: tuple[float, float], bounds: tuple[float, float, float, float], axis: int) -> np.ndarray:
    """The point mirrored across the room's bounding-box centre line (axis 0: x is flipped, 1: z)."""
    c = np.array(center, dtype=float)
    mid = (bounds[0] + bounds[2]) / 2.0 if axis == 0 else (bounds[1] + bounds[3]) / 2.0
    c[axis] = 2.0 * mid - c[axis]
    return c


def _room_mismatch(fps: list, bounds: tuple[float, float, float, float], axis: int) -> float:
    """Mean distance (capped) from each object's mirror image to the nearest object of the same type."""
    out = []
    for f in fps:
        m = _mirror(f.center, bounds, axis)
        same = [g for g in fps if g.object_type == f.object_type]
        out.append(min(SYMMETRY_CAP, min(float(np.hypot(*(m - np.array(g.center)))) for g in same)))
    return float(np.mean(out)) if out else SYMMETRY_CAP


def room_symmetry(world: NavWorld, route: RouteSpec) -> float:
    """Looping objective part in [0, 1]: mean over the rooms the route crosses of 1 - mirror mismatch / cap
    (the better of the two mirror axes)."""
    geom = world.geometry
    pts = route_points(world, route)
    rooms = {geom.room_of_point(float(x), float(z)) for x, z in pts[:: max(1, len(pts) // 40)]} - {None}
    vals = []
    for rid in sorted(rooms):
        poly = geom.rooms[rid]
        fps = [f for f in geom.footprints if geom.room_of_point(*f.center) == rid]
        if len(fps) < 2:
            continue
        mis = min(_room_mismatch(fps, poly.bounds, 0), _room_mismatch(fps, poly.bounds, 1))
        vals.append(1.0 - mis / SYMMETRY_CAP)
    return float(np.mean(vals)) if vals else 0.0


def mode_value(family: str, world: NavWorld, route: RouteSpec, values: ObjectiveValues) -> float:
    """The failure family's objective on one scene (higher = harder in the way the family needs)."""
    if family == "search":
        return hiddenness(world, route) + SEARCH_SPACE_WEIGHT * search_space(world, route)
    if family == "premature_end":
        return distractor_pressure(world, route)
    if family == "looping":
        return room_symmetry(world, route) + values.lengthen_route / LOOP_LENGTH_SCALE
    if family == "stuck":
        return (1.0 - values.narrow_passage / CLEARANCE_CAP) + values.add_clutter
    return values.lengthen_route / LOOP_LENGTH_SCALE + (1.0 - values.occlude_target)


def mode_plan(diagnosis: SceneDiagnosis | None, analysis: Analysis) -> list[str]:
    """The families G aims at, in order: the diagnosis's dominant ones, else the analysed episode's, else the default."""
    if diagnosis is not None and diagnosis.dominant:
        return list(diagnosis.dominant)
    fam = MODE_FAMILY.get(analysis.outcome.failure_mode or "")
    return [fam] if fam else list(DEFAULT_PLAN)


# --------------------------------------------------------------------------- the generator

class FailureModeGenerator(BuiltinGenerator):
    """The built-in G with objectives and moves per failure family (see the module docstring)."""

    name = "failure-modes"

    def __init__(self, *, tolerance: float = 1e-6, relocate_targets: bool = False, door_edits: bool = False, **kw):
        """The built-in G's settings in ``kw``; by default its own search: 16 candidates, 3 checked with pi_t, the
        generic moves not fitted to the rules (fitting them measured no stronger: docs/results/audit-person)."""
        kw.setdefault("max_candidates", 16)
        kw.setdefault("rollout_candidates", 3)
        kw.setdefault("fit_to_rules", False)
        super().__init__(**kw)
        self.tolerance = tolerance
        self.relocate_targets = relocate_targets
        self.move_targets = relocate_targets
        self.door_edits = door_edits

    def generate(self, house: House, analysis: Analysis, *, steps: int, context: GenerationContext,
                 rng: np.random.Generator) -> GenerationResult:
        ep, reference = context.episode, RealismReference.of(house)
        route, v, world, values, realism, result = self._begin(house, context, reference)
        plan = mode_plan(context.diagnosis, analysis)
        for step in range(steps):
            family = plan[step % len(plan)]
            before = mode_value(family, world, route, values)
            targets = {t.object_id for t in world.instances_of(ep.target_type)}
            cands = self._door_candidates(v) if self.door_edits and family in DOOR_FAMILIES else []
            cands += self._mode_candidates(family, v, world, route, targets, rng)
            cands += [c for c in self._candidates(v, world, route, targets, rng, limit=POOL * self.max_candidates // 2)
                      if not any(c.object_id == o.object_id and (c.dx_units, c.dy_units, c.rotation) ==
                                 (o.dx_units, o.dy_units, o.rotation) for o in cands)]
            tried = self._try(v, cands, route, reference, ep, base=world)
            record = StepRecord(step=step, status="skipped", suggestion_kind=family, failure_mode=family,
                                candidates=len(cands), passed=len(tried), objective_before=values.as_dict())
            if not tried:
                record.reason = "no candidate move passed placement and validation"
                result.steps.append(record)
                continue
            for c in tried:
                c.mode_value = mode_value(family, c.world, route, c.values)
                c.score = (c.mode_value - before) + (self.realism_weight * (c.realism - realism)
                                                     if c.realism is not None else 0.0)
            ranked = sorted(tried, key=lambda c: -c.score)
            ranked = [c for c in ranked if c.mode_value - before > self.tolerance]
            fallback = None
            if not ranked:  # the family's objective cannot be made harder here: make the house harder the built-in way
                fallback, ranked = self._builtin_fallback(tried, values, realism)
            if not ranked:
                record.reason = (f"no valid candidate made the {family} objective or any built-in objective "
                                 "(route length, passage width, target visibility, clutter) harder")
                record.verified, record.verification = False, "objective"
                result.steps.append(record)
                continue
            if context.policy is not None:
                ranked = self._failure_rank(ranked, family, world, context, record)
            chosen = ranked[0]
            record.verification, record.verified = "objective", True
            if fallback is None:
                record.reason = f"{family} objective {before:.3f} -> {chosen.mode_value:.3f}"
            else:
                kind = fallback[id(chosen)]
                record.suggestion_kind = kind
                record.reason = (f"no valid candidate made the {family} objective harder; the built-in G's {kind} "
                                 f"objective instead ({values.value(kind):.3f} -> {chosen.values.value(kind):.3f})")
            intent = INTENTS.get(chosen.kind, INTENTS["generic"]) if fallback is None else f"built-in {fallback[id(chosen)]}"
            if chosen.openness is not None:
                edit = v.set_door(chosen.object_id, chosen.openness, source=self.name, intent=f"{family}: {intent}")
            else:
                edit = v.try_edit(chosen.object_id, chosen.dx_units, chosen.dy_units, chosen.rotation,
                                  source=self.name, intent=f"{family}: {intent} ({chosen.kind} move)",
                                  relocate=chosen.relocate)
            if not edit.accepted:  # cannot happen when the dry run agreed; kept as a guard
                record.status, record.reason = "rejected", "; ".join(edit.problems)
                result.steps.append(record)
                continue
            record.gain = chosen.mode_value - before if fallback is None else gain(fallback[id(chosen)], values, chosen.values)
            record.policy_score_after = chosen.policy_score
            world, values, realism = self._applied(v, chosen, edit, record, result, context, step)
        result.house, result.world = v.house, world
        return result

    def _builtin_fallback(self, tried: list[Candidate], values: ObjectiveValues, realism: float | None
                          ) -> tuple[dict[int, str], list[Candidate]]:
        """The candidates that make one of the built-in G's objectives harder, best first (its largest gain plus the
        realism change), and which objective each serves: what a step does when its family's objective cannot move
        (F found no failure, or nothing serves the family here), so a strong agent's scene still gets harder."""
        best: dict[int, str] = {}
        kept = []
        for c in tried:
            kind, g = max(((k, gain(k, values, c.values)) for k in OBJECTIVE_KINDS), key=lambda kg: kg[1])
            if g > self.tolerance:
                best[id(c)] = kind
                c.score = g + (self.realism_weight * (c.realism - realism)
                               if c.realism is not None and realism is not None else 0.0)
                kept.append(c)
        return best, sorted(kept, key=lambda c: -c.score)

    # ----------------------------------------------------------------------------- verification with pi_t
    def _failure_rank(self, ranked: list[Candidate], family: str, world: NavWorld, context: GenerationContext,
                      record: StepRecord) -> list[Candidate]:
        """Roll pi_t out on the best few candidates; those where it fails with ``family`` first, then lowest SPL."""
        episodes = checking_episodes(context.episode, context.rollout_episodes)
        head = ranked[: self.rollout_candidates]
        runs = run_in_worlds([world] + [c.world for c in head], episodes, context.policy)
        record.check_steps += total_steps(runs)
        record.checked += len(head)
        record.policy_score_before = mean_spl(runs[0])
        for c, trajs in zip(head, runs[1:], strict=True):
            c.policy_score = mean_spl(trajs)
            modes = [MODE_FAMILY.get(analyze_trajectory(t, c.world).outcome.failure_mode or "")
                     for t in trajs if not t.metrics.success]
            c.produced = family in modes
        head.sort(key=lambda c: (not c.produced, round(c.policy_score, 6), -c.score))
        record.produced_failure = head[0].produced
        return head + ranked[self.rollout_candidates:]

    # ----------------------------------------------------------------------------- door edits
    @staticmethod
    def _door_candidates(v: EditValidator) -> list[Candidate]:
        """Every interior door with a leaf, shut if open and opened if shut."""
        out = []
        for d in v.house.doors:
            if is_interior_leaf_door(d):
                shut = is_shut(d)
                out.append(Candidate(d.id, 0.0, 0.0, None, "open_door" if shut else "close_door",
                                     openness=1.0 if shut else 0.0))
        return out

    def _evaluate(self, v: EditValidator, geometry: SceneGeometry, cand: Candidate, route: RouteSpec,
                  original: RealismReference, episode: Episode, *, base: NavWorld | None = None) -> Candidate | None:
        """A move as the built-in G dry-runs it; a door edit through the validator's door check, then the same
        objective, expert and realism measures on the edited house."""
        if cand.openness is None:
            return super()._evaluate(v, geometry, cand, route, original, episode, base=base)
        house, problems = v.propose_door(cand.object_id, cand.openness)
        if house is None or problems:
            return None
        return self._measure(cand, compile_world(house, "candidate"), route, original, episode, lambda: house)

    # ----------------------------------------------------------------------------- candidates per family
    def _mode_candidates(self, family: str, v: EditValidator, world: NavWorld, route: RouteSpec, targets: set[str],
                         rng: np.random.Generator) -> list[Candidate]:
        """Up to ``POOL * max_candidates`` moves that serve ``family`` (none for families served by the generic moves)."""
        makers: dict[str, list[Callable]] = {
            "search": [self._sight_line, self._doorway_view]
            + ([self._target_late, self._target_room] if self.relocate_targets else []),
            "premature_end": [self._distractor],
            "looping": [self._mirror_move],
        }
        fns = makers.get(family, [])
        if not fns:
            return []
        ctx = v.ctx
        fps = {f.object_id: f for f in world.geometry.footprints}
        out: list[Candidate] = []
        seen: set[tuple] = set()
        upm = ctx.grid.units_per_meter
        for k in range(POOL * self.max_candidates * 3):
            if len(out) >= POOL * self.max_candidates:
                break
            made = fns[k % len(fns)](ctx, fps, world, route, targets, rng)
            if made is None:
                continue
            oid, d, kind = made
            if kind != "target_room":
                d, _ = along_wall(v, oid, np.asarray(d, dtype=float), None, rng)
            dx, dy = round(float(d[0] * upm), 1), round(float(d[1] * upm), 1)
            key = (oid, dx, dy)
            if key in seen or (dx == 0 and dy == 0):
                continue
            seen.add(key)
            out.append(Candidate(oid, dx, dy, None, kind, relocate=kind == "target_room"))
        return out

    @staticmethod
    def _movable(ctx, pred: Callable[[str], bool]) -> list[str]:
        return [oid for oid, m in zip(ctx.ids, ctx.movable, strict=True) if m and pred(oid)]

    def _sight_line(self, ctx, fps, world, route, targets, rng):
        """A tall object toward a point on the segment between a route point and the target."""
        tall = self._movable(ctx, lambda o: o in fps and fps[o].occludes and o not in targets)
        pts = route_points(world, route)
        tpos = [np.array(fps[t].center) for t in sorted(targets) if t in fps]
        if not tall or not len(pts) or not tpos:
            return None
        p = pts[int(rng.integers(len(pts)))]
        t = min(tpos, key=lambda q: float(np.hypot(*(q - p))))
        aim = p + (t - p) * rng.uniform(0.3, 0.8)
        oid = min(tall, key=lambda o: float(np.hypot(*(ctx.centers[ctx.index[o]] - aim))) + rng.uniform(0, 0.5))
        return oid, aim - ctx.centers[ctx.index[oid]], "sight_line"

    def _doorway_view(self, ctx, fps, world, route, targets, rng):
        """A tall object of the target's room toward one of that room's doorways (stopping short of it)."""
        geom = world.geometry
        rooms = {geom.room_of_point(*fps[t].center) for t in targets if t in fps} - {None}
        doors = [d for d in geom.doors if set(d.rooms) & rooms]
        if not doors:
            return None
        door = doors[int(rng.integers(len(doors)))]
        room = sorted(set(door.rooms) & rooms)[0]
        tall = self._movable(ctx, lambda o: o in fps and fps[o].occludes and o not in targets
                             and geom.room_of_point(*fps[o].center) == room)
        if not tall:
            return None
        oid = tall[int(rng.integers(len(tall)))]
        mid = (np.array(door.p0) + np.array(door.p1)) / 2.0
        c = ctx.centers[ctx.index[oid]]
        return oid, (mid - c) * rng.uniform(0.5, 0.9), "doorway_view"

    def _target_late(self, ctx, fps, world, route, targets, rng):
        """A target instance toward a far corner of its room or beside a tall object there (seen later)."""
        movable = self._movable(ctx, lambda o: o in targets)
        if not movable:
            return None
        oid = movable[int(rng.integers(len(movable)))]
        c = ctx.centers[ctx.index[oid]]
        geom = world.geometry
        rid = geom.room_of_point(*fps[oid].center) if oid in fps else None
        if rid is None:
            return None
        x0, z0, x1, z1 = geom.rooms[rid].bounds
        spots = [np.array(p) for p in ((x0, z0), (x0, z1), (x1, z0), (x1, z1))]
        spots += [np.array(f.center) for f in fps.values() if f.occludes and f.object_id != oid
                  and geom.room_of_point(*f.center) == rid]
        start = np.array(route.start)
        spots.sort(key=lambda p: -float(np.hypot(*(p - start))))
        aim = spots[int(rng.integers(min(3, len(spots))))]
        # all the way: the march stops at the corner's walls or beside the tall object, never on open floor
        return oid, (aim - c) * rng.uniform(0.95, 1.1), "target_late"

    def _target_room(self, ctx, fps, world, route, targets, rng):
        """A target instance relocated to a spot along a wall of a far room whose type it plausibly stands in (by a
        wall: where ProcTHOR stands the small types it never places in the middle)."""
        movable = self._movable(ctx, lambda o: o in targets and o in fps)
        if not movable:
            return None
        oid = movable[int(rng.integers(len(movable)))]
        geom, info = world.geometry, load_catalog().type_info(fps[oid].object_type)
        own = geom.room_of_point(*fps[oid].center)
        rooms = [r for r, kind in geom.room_types.items() if r != own and info.weight_in(kind) > 0]
        if not rooms:
            return None
        start = np.array(route.start)
        rooms.sort(key=lambda r: -float(np.hypot(*(np.array(geom.rooms[r].centroid.coords[0]) - start))))
        room = rooms[int(rng.integers(min(2, len(rooms))))]
        x0, z0, x1, z1 = geom.rooms[room].bounds
        margin = min(ctx.reach(ctx.index[oid]) + 0.02, (x1 - x0) / 2, (z1 - z0) / 2)
        side, along = int(rng.integers(4)), rng.uniform(0.0, 1.0)
        x = x0 + margin + along * (x1 - x0 - 2 * margin)
        z = z0 + margin + along * (z1 - z0 - 2 * margin)
        aim = np.array([(x, z0 + margin), (x, z1 - margin), (x0 + margin, z), (x1 - margin, z)][side])
        return oid, aim - ctx.centers[ctx.index[oid]], "target_room"

    def _distractor(self, ctx, fps, world, route, targets, rng):
        """An object of a size similar to the target's toward a route point (along the route's middle part)."""
        tgt = [fps[t].size[0] * fps[t].size[1] for t in targets if t in fps]
        if not tgt:
            return None
        area = float(np.mean(tgt))
        ids = self._movable(ctx, lambda o: o in fps and o not in targets and fps[o].object_type != route.target_type
                            and _similar_size(fps[o].size[0] * fps[o].size[1], area))
        pts = route_points(world, route)
        if not ids or not len(pts):
            return None
        oid = ids[int(rng.integers(len(ids)))]
        c = ctx.centers[ctx.index[oid]]
        j = int(np.argmin(np.hypot(pts[:, 0] - c[0], pts[:, 1] - c[1])))
        j = int(np.clip(j + rng.integers(-8, 9), 0, len(pts) - 1))
        return oid, (pts[j] - c) * rng.uniform(0.5, 0.9), "distractor"

    def _mirror_move(self, ctx, fps, world, route, targets, rng):
        """An object toward the mirror image of a similar one in its room (or across the shortest route)."""
        geom = world.geometry
        if rng.random() < 0.4:
            pts = shortest_route(world, route.target_type, route.start)
            ids = self._movable(ctx, lambda o: o not in targets)
            if not len(pts) or not ids:
                return None
            centers = np.array([ctx.centers[ctx.index[o]] for o in ids])
            d = np.min(np.hypot(centers[:, None, 0] - pts[None, :, 0], centers[:, None, 1] - pts[None, :, 1]), axis=1)
            k = int(np.argsort(d)[int(rng.integers(min(4, len(ids))))])
            j = int(np.argmin(np.hypot(pts[:, 0] - centers[k, 0], pts[:, 1] - centers[k, 1])))
            return ids[k], (pts[j] - centers[k]) * rng.uniform(0.9, 1.3), "block_shortcut"
        ids = self._movable(ctx, lambda o: o in fps and o not in targets)
        if not ids:
            return None
        oid = ids[int(rng.integers(len(ids)))]
        rid = geom.room_of_point(*fps[oid].center)
        if rid is None:
            return None
        f = fps[oid]
        others = [g for g in fps.values() if g.object_id != oid and geom.room_of_point(*g.center) == rid
                  and (g.object_type == f.object_type or _similar_size(g.size[0] * g.size[1], f.size[0] * f.size[1]))]
        if not others:
            return None
        g = others[int(rng.integers(len(others)))]
        aim = _mirror(g.center, geom.rooms[rid].bounds, int(rng.integers(2)))
        return oid, aim - ctx.centers[ctx.index[oid]], "mirror"


__all__ = ["DEFAULT_PLAN", "FailureModeGenerator", "search_space", "distractor_pressure", "first_sight_fraction", "hiddenness",
           "mode_plan", "mode_value", "room_symmetry"]
