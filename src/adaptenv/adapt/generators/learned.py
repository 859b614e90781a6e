"""The learned G: a small network scores candidate edits in one forward pass; of the best few that pass the checks,
the one whose measured route objectives gain most is made.

Per step (offline, deterministic for a given rng):

1. Draw candidate edits without rollouts, as the built-in G does (its moves toward, across and along the
   route; ``random_share`` of them random moves, as the random G draws them, default none:
   :func:`~adaptenv.adapt.generators.edit_features.enumerate_candidates`).
2. Score all of them in one forward pass of the scorer (:class:`Scorer`, a small MLP over
   :data:`~adaptenv.adapt.generators.edit_features.FEATURE_NAMES`): it predicts whether the edit survives
   placement, validation, the plausibility rules and the expert check, and either how much the agent's
   success and SPL drop after it (a scorer of target ``agent``) or how much each of the built-in G's
   route objectives gains (target ``objectives``, weighted per step as the built-in G weighs the
   analysis' suggestions); the score is the first times the (weighted) sum of the others.
3. Try them best first through collision-aware placement, validation with the plausibility rules
   (:meth:`~adaptenv.adapt.validation.EditValidator.propose`) and the shortest-path expert, and commit
   the first that passes. No rollout of the agent is made. With a scorer of target ``agent`` an object
   is edited at most once per generation (a second move of the same object can undo the first, and
   that score cannot tell); ranked by objective gains, a move that undoes an earlier one loses what it
   gained, so objects may be moved again.
4. With ``checks`` K > 0 and a policy in the context, the first K that pass (distinct objects) are
   instead rolled out with the agent in one batch (the episode's start and target, a few headings) and
   the one it succeeds on least often, then with the lowest mean SPL, is made: the network only chooses
   which K edits the agent is shown.
5. With ``objectives`` K > 0 (the default, :data:`OBJECTIVES`, unless ``checks`` is given), the first K
   that pass are instead measured on the built-in G's route objectives in their edited worlds (no
   rollout: a distance field and a few line-of-sight walks each) and the one with the largest gain,
   weighted as the built-in G weighs the analysis' suggestions, is made. ``objectives=0`` is the
   one-pass G of step 3.

The scorer is trained by ``adaptenv gdata train`` on rows of ``adaptenv gdata collect``; the package ships
one (``agents/data/learned-g.pt``, its card ``learned-g.json``). Its file is a ``torch.save`` dictionary
``{"format", "features", "config", "state_dict", "mean", "std", "meta"}``; :func:`load_scorer` refuses any
other file in one line.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from adaptenv.adapt.analysis import Analysis
from adaptenv.adapt.generators._trial import moved_geometry
from adaptenv.adapt.generators.base import (
    GenerationContext,
    GenerationResult,
    StepRecord,
    keep_render,
    render_scene,
)
from adaptenv.adapt.generators.builtin import MIN_MOVE, Candidate, fit_rules, suggestion_order
from adaptenv.adapt.generators.edit_features import (
    FEATURE_NAMES,
    Scene,
    candidate_features,
    enumerate_candidates,
)
from adaptenv.adapt.objectives import (
    OBJECTIVE_KINDS,
    ObjectiveValues,
    RouteSpec,
    measure,
    suggestion_weights,
    weighted_gain,
)
from adaptenv.adapt.validation import EditValidator, Proposal, world_fits
from adaptenv.agents.rollout import checking_episodes, mean_spl, run_in_worlds, total_steps
from adaptenv.errors import ConfigError
from adaptenv.scene.house import House
from adaptenv.sim.geodesic import reuse_region
from adaptenv.sim.rollout import expert_policy, run_episode
from adaptenv.sim.task import Episode
from adaptenv.sim.world import NavWorld, compile_world

FORMAT = "adaptenv-learned-g/1"
SHIPPED = "learned-g"
"""The shipped scorer's file stem in ``adaptenv/agents/data`` (beside the shipped agents)."""
TARGETS: dict[str, tuple[str, ...]] = {
    "agent": ("accept", "success_drop", "spl_drop"),
    "objectives": ("accept", *(f"gain_{k}" for k in OBJECTIVE_KINDS)),
}
"""What a scorer of each target predicts per candidate: the logit that it passes every check, then the agent's drops
in success and SPL (``agent``) or the gain of each route objective (``objectives``)."""
#: Candidate edits drawn and scored per step.
CANDIDATES = 64
#: The best-scored edits that pass every check whose route objectives are measured per step, by default.
OBJECTIVES = 4


@dataclass(frozen=True)
class ScorerConfig:
    """The scorer's shape: inputs (the feature count), hidden width and hidden layers."""

    n_features: int = len(FEATURE_NAMES)
    hidden: int = 64
    layers: int = 2
    target: str = "agent"
    """What it predicts beside acceptance: a key of :data:`TARGETS`."""


def build_net(cfg: ScorerConfig):
    """The MLP: ``layers`` hidden ReLU layers of width ``hidden``, then one output per name of its target."""
    import torch.nn as nn

    mods, width = [], cfg.n_features
    for _ in range(cfg.layers):
        mods += [nn.Linear(width, cfg.hidden), nn.ReLU()]
        width = cfg.hidden
    return nn.Sequential(*mods, nn.Linear(width, len(TARGETS[cfg.target])))


def expected_gain(out: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """The score of each candidate from the net's outputs: P(passes every check) times the sum of the predicted
    drops or gains, each times its entry of ``weights`` (one per output, or one row per candidate; default 1 each)."""
    w = 1.0 if weights is None else np.asarray(weights, dtype=np.float64)
    return (1.0 / (1.0 + np.exp(-out[:, 0]))) * (out[:, 1:] * w).sum(axis=1)


def objective_weights(weights: dict[str, float]) -> np.ndarray:
    """A weight per route objective (:func:`~adaptenv.adapt.objectives.suggestion_weights`) as a vector in the
    order of a scorer of target ``objectives``."""
    return np.array([float(weights.get(k, 0.0)) for k in OBJECTIVE_KINDS])


@dataclass
class Scorer:
    """A loaded scorer: the net (eval mode), the feature normalisation, its card and where it came from."""

    net: Any
    mean: np.ndarray
    std: np.ndarray
    meta: dict[str, Any]
    path: Path | None = None
    target: str = "agent"
    """What it predicts beside acceptance (a key of :data:`TARGETS`)."""

    def outputs(self, features: np.ndarray) -> np.ndarray:
        """(N, outputs) raw outputs for (N, F) features, in one forward pass."""
        import torch

        x = torch.as_tensor((np.asarray(features, dtype=np.float32) - self.mean) / self.std)
        with torch.no_grad():
            return self.net(x).numpy().astype(np.float64)

    def score(self, features: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """(N,) expected gain of each candidate (higher: try first); ``weights``: one per predicted drop or gain."""
        if len(features) == 0:
            return np.zeros(0)
        return expected_gain(self.outputs(features), weights)


def shipped_path() -> Path:
    """Where the shipped scorer lives inside the installed package."""
    return Path(str(resources.files("adaptenv.agents") / "data" / f"{SHIPPED}.pt"))


def save_scorer(path: str | Path, net, cfg: ScorerConfig, mean: np.ndarray, std: np.ndarray,
                meta: dict[str, Any]) -> Path:
    """Write a scorer atomically (float32 on CPU) with its normalisation and card."""
    import torch

    from adaptenv.agents.checkpoint import atomic_torch_save, non_finite_weight

    if (bad := non_finite_weight(net)) is not None:
        raise ConfigError(f"{path}: not written, the weight {bad} holds NaN or infinite values; train again with a "
                          "lower learning rate")
    return atomic_torch_save({
        "format": FORMAT, "features": list(FEATURE_NAMES), "config": asdict(cfg),
        "state_dict": {k: v.detach().to("cpu", torch.float32).clone() for k, v in net.state_dict().items()},
        "mean": torch.as_tensor(mean, dtype=torch.float32), "std": torch.as_tensor(std, dtype=torch.float32),
        "meta": dict(meta)}, path)


def load_scorer(path: str | Path | None = None) -> Scorer:
    """Read a scorer written by :func:`save_scorer` (default: the shipped one); any problem is one ConfigError."""
    import torch

    from adaptenv.agents.checkpoint import load_tensors

    p = Path(path) if path is not None else shipped_path()
    fix = "train one with `adaptenv gdata train DATA -o FILE.pt`"
    if not p.is_file():
        raise ConfigError(f"{p}: no such learned-G checkpoint; {fix}")
    try:
        doc = load_tensors(p)
    except Exception as exc:  # torch raises many types for corrupt files
        raise ConfigError(f"{p}: not a readable torch checkpoint ({type(exc).__name__}); {fix}") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ConfigError(f"{p}: not a learned-G checkpoint (expected format {FORMAT!r}); {fix}")
    if doc.get("features") != list(FEATURE_NAMES):
        raise ConfigError(f"{p}: scores other candidate features than this version of adaptenv computes; {fix}")
    try:
        cfg = ScorerConfig(**doc["config"])
        if (cfg.n_features != len(FEATURE_NAMES) or cfg.target not in TARGETS
                or not (1 <= cfg.hidden <= 4096 and 0 <= cfg.layers <= 8)):
            raise ValueError("shape")
        net = build_net(cfg)
        net.load_state_dict(doc["state_dict"])
        mean = np.asarray(doc["mean"].numpy(), dtype=np.float32).reshape(len(FEATURE_NAMES))
        std = np.asarray(doc["std"].numpy(), dtype=np.float32).reshape(len(FEATURE_NAMES))
    except Exception as exc:
        raise ConfigError(f"{p}: its config, weights or normalisation do not fit a learned-G scorer "
                          f"({type(exc).__name__}); {fix}") from None
    finite = all(bool(torch.isfinite(t).all()) for t in net.state_dict().values())
    if not finite or not np.isfinite(mean).all() or not (np.isfinite(std).all() and (std > 0).all()):
        raise ConfigError(f"{p}: holds NaN, infinite or zero-scale values; {fix}")
    net.eval()
    meta = doc.get("meta") if isinstance(doc.get("meta"), dict) else {}
    return Scorer(net, mean, std, meta, p, cfg.target)


class _LazyFit:
    """``lazy_fit``: a route move fitted to the plausibility rules when its turn comes (written back into the candidate
    list); None when no fraction of it fits or it fits to a move already fitted this step."""

    def __init__(self, v: EditValidator):
        self.v, self.upm = v, v.ctx.grid.units_per_meter
        self.current = {f.object_id: f for f in v.geometry.footprints}
        self.seen: set[tuple] = set()

    def __call__(self, cands: list[Candidate], k: int) -> Candidate | None:
        c = cands[k]
        if c.kind == "random":  # random moves are never fitted
            return c
        d = fit_rules(self.v, self.current, c.object_id, np.array([c.dx_units, c.dy_units]) / self.upm, c.rotation,
                      shrink=not c.relocate)
        if d is None:
            return None
        dx, dy = round(float(d[0] * self.upm), 1), round(float(d[1] * self.upm), 1)
        if (key := (c.object_id, dx, dy, c.rotation)) in self.seen:
            return None
        self.seen.add(key)
        cands[k] = replace(c, dx_units=dx, dy_units=dy)
        return cands[k]


class LearnedGenerator:
    """G that scores candidate edits with a trained network and makes, of the best few that pass the checks, the one
    with the largest measured route-objective gain (``objectives``; 0: the best-scored one)."""

    name = "learned"

    def __init__(self, *, checkpoint: str | Path | None = None, candidates: int = CANDIDATES,
                 require_expert: bool = True, checks: int = 0, objectives: int | None = None,
                 scorer: Scorer | None = None, random_share: float = 0.0, lazy_fit: bool = False):
        """``checks``: with a policy in the context, roll the agent out on the best this many edits that pass every
        check and make the hardest for it (0: no rollout, the best-scored edit is made). ``objectives``: measure the
        route objectives of the best this many instead and make the one with the largest weighted gain (default
        :data:`OBJECTIVES`, or 0 with ``checks``; 0: the best-scored edit is made). ``random_share``: the share of
        candidates drawn as random moves rather than the built-in G's route moves (the data drew half). ``lazy_fit``:
        score the route moves as drawn and fit each to the plausibility rules only when its turn comes, in score order
        (:func:`~adaptenv.adapt.generators.builtin.fit_rules`), instead of fitting every one before scoring."""
        objectives = (0 if checks else OBJECTIVES) if objectives is None else objectives
        if not 0.0 <= float(random_share) <= 1.0:
            raise ConfigError(f"random_share {random_share}: must be from 0 to 1")
        for name, k in (("checks", checks), ("objectives", objectives)):
            if not 0 <= int(k) <= candidates:
                raise ConfigError(f"{name} {k}: must be a whole number from 0 to the candidates per step ({candidates})")
        if checks and objectives:
            raise ConfigError("checks and objectives: give at most one of them a value above 0")
        self.scorer = scorer or load_scorer(checkpoint)
        self.candidates = candidates
        self.require_expert = require_expert
        self.checks = int(checks)
        self.objectives = int(objectives)
        self.random_share = float(random_share)
        self.lazy_fit = bool(lazy_fit)
        self.repeat = self.objectives > 0 or self.scorer.target == "objectives"
        """Whether an object may be edited again in a later step: when edits are ranked by route-objective gains (a move
        that undoes an earlier one loses what it gained), not by the agent's drops."""
        self._expects = "gain" if self.scorer.target == "objectives" else "drop"
        self._expert = expert_policy()

    def generate(self, house: House, analysis: Analysis, *, steps: int, context: GenerationContext,
                 rng: np.random.Generator) -> GenerationResult:
        ep = context.episode
        route = RouteSpec.from_episode(ep.target_type, ep.start, context.trajectory)
        v = EditValidator(house, episode_targets=[ep.target_type], start=ep.start[:2], world=context.world,
                          placement_model=context.placement_model)
        result = GenerationResult(house=v.house, steps=[], edit_log=v.log, generator=self.name)
        want = self.checks if self.checks and context.policy is not None else max(1, self.objectives)
        suggestions = sorted(analysis.suggestions, key=lambda s: -s.priority)
        edited: set[str] = set()
        world = context.world if world_fits(context.world, v.geometry) else None  # of v.house; None: compile it
        for step in range(steps):
            if world is None:
                world = compile_world(v.house, "candidate")
            scene = Scene.of(v, world, route)
            values = measure(world, route) if self.objectives else None
            cands = [c for c in enumerate_candidates(v, world, route, rng, self.candidates, scene=scene,
                                                      random_share=self.random_share, fit=not self.lazy_fit)
                     if self.repeat or c.object_id not in edited]
            fitted = _LazyFit(v) if self.lazy_fit else None
            weights = self._weights(step, suggestions)
            scores = self.scorer.score(candidate_features(v, scene, cands, analysis),
                                       objective_weights(weights) if self.scorer.target == "objectives" and weights else None)
            record = StepRecord(step=step, status="skipped", candidates=len(cands))
            passed: list[tuple[int, int, Proposal, NavWorld | None]] = []
            for tried, k in enumerate(np.argsort(-scores, kind="stable"), start=1):
                c = cands[int(k)] if fitted is None else fitted(cands, int(k))
                if c is None:
                    continue
                if self.checks and any(cands[j].object_id == c.object_id for _, j, _, _ in passed):
                    continue
                if (found := self._passes(v, c, ep, want > 1, world)) is not None:
                    passed.append((tried, int(k), *found))
                    if len(passed) >= want:
                        break
            if not passed:
                record.reason = ("no candidate passed placement, validation, the plausibility rules and the expert "
                                 "check" if cands else "no movable object left to edit")
                result.steps.append(record)
                continue
            if len(passed) == 1:  # world: the chosen edit's world (None when none was compiled), the next step's
                tried, k, p, world = passed[0]
            elif self.checks:
                tried, k, p, world = self._check(passed, context, record)
            else:
                tried, k, p, world = self._by_objectives(passed, route, values, weights)
            c = cands[k]
            edit = v.commit(p, source=self.name,
                            intent=f"learned: {c.kind} move, expected {self._expects} {scores[k]:+.3f} (rank {tried})")
            edited.add(c.object_id)
            if not world_fits(world, v.geometry):  # the chosen edit's world is the next step's when it is exact
                world = None
            record.status, record.edit, record.attempts = "applied", edit, tried
            record.reason = (f"the best-scored of {len(cands)} candidates that passed every check (tried {tried})"
                             if len(passed) == 1 else
                             f"the hardest for the agent of the {len(passed)} best-scored candidates that passed "
                             f"every check (rank {tried} of {len(cands)})" if self.checks else
                             f"the largest objective gain of the {len(passed)} best-scored candidates that passed "
                             f"every check (rank {tried} of {len(cands)})")
            if context.render:
                record.render = keep_render(result, render_scene(v.house, context, highlight={edit.object_id: "gold"}),
                                            context, step)
            result.steps.append(record)
        result.house, result.world = v.house, world
        return result

    def _passes(self, v: EditValidator, c: Candidate, ep: Episode, keep_world: bool,
                base: NavWorld) -> tuple[Proposal, NavWorld | None] | None:
        """The proposal of ``c`` (and, with ``keep_world``, its edited world) when it passes placement, validation,
        the plausibility rules and (``require_expert``) the expert; None otherwise. ``base``: the world of ``v.house``,
        whose success region an edit far from the target keeps."""
        p = v.propose(c.object_id, c.dx_units, c.dy_units, c.rotation, relocate=c.relocate)
        res = p.result
        if not p.valid or not res.changed or (not res.rotation_applied and math.hypot(*res.achieved) < MIN_MOVE):
            return None
        cw = None
        if self.require_expert or keep_world:
            cw = compile_world(v.house, "candidate", geometry=moved_geometry(v.geometry, res))
            reuse_region(cw, base, ep.target_type)
            if self.require_expert and not run_episode(cw, ep, self._expert, record=False).metrics.success:
                return None
        return p, cw

    @staticmethod
    def _weights(step: int, suggestions: list) -> dict[str, float]:
        """The step's weight per route objective, as the built-in G weighs them: its round-robin suggestion at 1,
        the others by priority (empty when the analysis suggests nothing)."""
        order = suggestion_order(step, suggestions)
        return suggestion_weights(order[0].kind, {s.kind: s.priority for s in suggestions}) if order else {}

    @staticmethod
    def _by_objectives(passed: list, route: RouteSpec, before: ObjectiveValues | None,
                       weights: dict[str, float]) -> tuple:
        """The passed candidate with the largest weighted gain in the route objectives (the best scored on ties)."""
        if not weights or before is None:
            return passed[0]
        gains = [weighted_gain(weights, before, measure(cw, route)) for *_, cw in passed]
        return passed[int(np.argmax(gains))]

    def _check(self, passed: list, context: GenerationContext, record: StepRecord) -> tuple:
        """The passed candidate the policy succeeds on least often, then with the lowest mean SPL, then the best
        scored (one batch of rollouts over every passed candidate's world)."""
        episodes = checking_episodes(context.episode, context.rollout_episodes)
        batch = run_in_worlds([w for *_, w in passed], episodes, context.policy)
        record.check_steps += total_steps(batch)
        record.checked += len(passed)
        keys = [(sum(bool(t.metrics.success) for t in trajs), round(mean_spl(trajs), 6), n)
                for n, trajs in enumerate(batch)]
        best = min(keys)
        record.policy_score_after = best[1]
        return passed[best[2]]


__all__ = ["CANDIDATES", "FORMAT", "OBJECTIVES", "TARGETS", "LearnedGenerator", "Scorer", "ScorerConfig", "build_net",
           "expected_gain", "load_scorer", "objective_weights", "save_scorer", "shipped_path"]
