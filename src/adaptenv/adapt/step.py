"""One adaptation step, ``e_{t+1} = G(e_t, F(tau))`` with pi_t in G's context: the only copy of it.

:func:`adapt_scene` is what ``adaptenv adapt``, the closed loop's generation job, ``adaptenv bench
adapt`` and the demo all run::

    result = adapt_scene(house, episode, policy=pi_t, analyzer=BuiltinAnalyzer(),
                         generator=make_generator("builtin"), steps=5, rng=np.random.default_rng(0))

It rolls pi_t out (unless the caller already has that trajectory), analyses the episode (F), lets
G edit the house one object at a time while checking candidates against pi_t (the paper's
``argmin_{e'} R(pi_t, e')``) and verifying each edit, validates the final house as a whole, and
rolls pi_t out again in the edited house on the same episode. :func:`summarize` adds the figures a
person reads (objectives, realism, the plausibility audit's counts, expert check, whether the scene got
harder for pi_t: :func:`verdict`) and :func:`write_outputs` writes them.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from adaptenv.adapt.analysis import Analysis, Analyzer
from adaptenv.adapt.diagnosis import SceneDiagnosis, diagnose_scene
from adaptenv.adapt.edits import edit_counts
from adaptenv.adapt.generators import (
    GenerationContext,
    GenerationResult,
    Generator,
    house_object_types,
)
from adaptenv.adapt.llm.accounting import scene_usage
from adaptenv.adapt.llm.usage import Prices
from adaptenv.adapt.objectives import RouteSpec, measure, realism_score
from adaptenv.adapt.plausibility import audit
from adaptenv.adapt.validation import validate_scene, world_fits
from adaptenv.agents.policy import ExpertPolicy, Policy, as_policy
from adaptenv.agents.rollout import rollout
from adaptenv.files import atomic_write_text
from adaptenv.render.compare import render_before_after
from adaptenv.render.topdown import save_render
from adaptenv.scene.geometry import SceneGeometry
from adaptenv.scene.house import House, save_house
from adaptenv.scene.validate import validate_house
from adaptenv.sim.geodesic import is_solvable
from adaptenv.sim.task import Episode
from adaptenv.sim.trajectory import Trajectory
from adaptenv.sim.world import NavWorld, compile_world


@dataclass
class AdaptResult:
    """What one adaptation step produced: e_{t+1}, F's analysis, G's edit log and both rollouts of pi_t."""

    house: House
    """The edited house e_{t+1} (check :attr:`valid` before training on it)."""
    original: House
    episode: Episode
    analysis: Analysis
    generation: GenerationResult
    """G's steps: each edit's intent (suggestion), status, verified flag and achieved move; token usage."""
    before: Trajectory
    """pi_t's episode in the original house (what F analysed)."""
    after: Trajectory
    """pi_t's episode in the edited house, same start and target."""
    problems: list[str] = field(default_factory=list)
    """Final validation of the whole edited house (empty when valid)."""
    world: NavWorld | None = None
    """The compiled edited house (reused by callers that roll out again)."""
    diagnosis: SceneDiagnosis | None = None
    """F's multi-episode diagnosis of the original house (when ``adapt_scene`` was given ``episodes``)."""
    diagnosis_after: SceneDiagnosis | None = None
    """The same episodes diagnosed again in the edited house (its regret scores the child)."""
    original_world: NavWorld | None = None
    """The compiled original house e_t (reused by :func:`summarize` instead of compiling it again)."""

    @property
    def valid(self) -> bool:
        return not self.problems

    @property
    def edits_applied(self) -> int:
        return len(self.generation.applied)

    @property
    def edits_verified(self) -> int:
        return sum(1 for s in self.generation.steps if s.status == "applied" and s.verified)


def adapt_scene(house: House, episode: Episode, *, policy: Policy, analyzer: Analyzer, generator: Generator,
                steps: int, rng: np.random.Generator, before: Trajectory | None = None, name: str = "house",
                rollout_episodes: int = 3, render: bool = False, render_dir: Path | None = None,
                episodes: list[Episode] | None = None) -> AdaptResult:
    """Adapt ``house`` to ``policy`` on ``episode``: rollout -> F -> G (with pi_t) -> final validation -> rollout.

    Args:
        house: the environment e_t (not modified).
        episode: the task F and G work on (target type, start pose, seed).
        policy: pi_t; a batched :class:`~adaptenv.agents.policy.Policy` or a per-step callable.
        analyzer: F (``BuiltinAnalyzer`` or ``LLMAnalyzer``).
        generator: G (``make_generator("builtin" | "llm" | "random")``).
        steps: single-object edits to make.
        rng: G's random stream (the built-in G is deterministic and ignores it).
        before: pi_t's trajectory on ``episode`` in ``house`` when the caller already has it.
        rollout_episodes: episodes (same start and target, spread headings) per check of a candidate edit.
        render: re-render after every edit (the LLM generator always does); ``render_dir`` keeps them.
        episodes: several episodes for F's multi-episode diagnosis
            (:func:`~adaptenv.adapt.diagnosis.diagnose_scene`); the worst of them then replaces
            ``episode`` and ``before``, G sees the diagnosis, and the edited house is diagnosed again.
    """
    policy = as_policy(policy)
    world = compile_world(house, name)
    diagnosed = None
    if episodes:
        diagnosed = diagnose_scene(world, list(episodes), policy, analyzer=analyzer)
        episode, before, analysis = diagnosed.worst_episode, diagnosed.worst_trajectory, diagnosed.analysis
    else:
        if before is None:
            before = rollout(world, episode, policy)
        analysis = analyzer.analyze(before, world)
    context = GenerationContext(episode=episode, trajectory=before, policy=policy,
                                rollout_episodes=rollout_episodes, render=render, out_dir=render_dir,
                                diagnosis=diagnosed.diagnosis if diagnosed else None, world=world)
    generation = generator.generate(house, analysis, steps=steps, context=context, rng=rng)
    new = generation.house
    new_world = generation.world  # trusted only when it is the world of the house generation returned
    new_world = (replace(new_world, name=name) if world_fits(new_world, SceneGeometry.from_house(new))
                 and new_world.start == new.agent_pose() else compile_world(new, name))
    problems = [str(p) for p in validate_scene(new, episode_targets=[episode.target_type], start=episode.start[:2],
                                               original=house, world=new_world, original_world=world)]
    problems += [p.message for p in validate_house(new)]
    if diagnosed is None:
        after = rollout(new_world, episode, policy)
        return AdaptResult(new, house, episode, analysis, generation, before, after, problems,
                           world=new_world, original_world=world)
    again = diagnose_scene(new_world, diagnosed.episodes, policy)  # built-in F: the regret needs no model call
    return AdaptResult(new, house, episode, analysis, generation, before, again.trajectories[diagnosed.diagnosis.worst],
                       problems, world=new_world, diagnosis=diagnosed.diagnosis, diagnosis_after=again.diagnosis,
                       original_world=world)


def summarize(result: AdaptResult, *, analyzer: Analyzer, seed: int | None = None) -> dict[str, Any]:
    """The figures a person reads about one step: agent before/after, objectives, realism, expert check, LLM use."""
    ep = result.episode
    world = result.original_world or compile_world(result.original, "before")
    new_world = result.world or compile_world(result.house, "after")
    expert = rollout(new_world, ep, ExpertPolicy())
    route = RouteSpec.from_episode(ep.target_type, ep.start, result.before)
    gen = result.generation
    return {
        "house": result.before.house, "policy": result.before.policy, "analyzer": analyzer.name, "generator": gen.generator, "seed": seed,
        "episode": {"target_type": ep.target_type, "start": list(ep.start), "seed": ep.seed},
        "steps_requested": len(gen.steps), "edits_applied": result.edits_applied,
        "edits_verified": result.edits_verified, "edit_counts": typed_edit_counts(result),
        "agent_before": _agent(result.before), "agent_after": _agent(result.after),
        "verdict": verdict(_agent(result.before), _agent(result.after)),
        "objective_before": measure(world, route).as_dict(), "objective_after": measure(new_world, route).as_dict(),
        "realism_before": realism_score(result.original, result.original),
        "realism_after": realism_score(result.house, result.original),
        "plausibility": audit(result.original, result.house).counts(),
        "expert_solvable": bool(is_solvable(new_world, ep)), "expert_success_after": bool(expert.metrics.success),
        "valid": result.valid, "problems": result.problems, "stopped": gen.stopped,
        "usage": scene_usage(result.analysis, gen).to_dict(gen.prices or _backend_prices(analyzer), calls=False),
        "llm": gen.llm or _backend_info(analyzer),
        **({"diagnosis": result.diagnosis.model_dump(mode="json"),
            "diagnosis_after": result.diagnosis_after.model_dump(mode="json")} if result.diagnosis else {}),
    }


def missed_edit_reasons(log: Mapping[str, Any]) -> Counter[str]:
    """Why steps of a generation log (``edits.json``: a generator's ``steps``, or random edits' ``edits``) made no
    edit, counted by reason (a step without one by its status)."""
    if "steps" in log:
        return Counter(s.get("reason") or s.get("status", "skipped") for s in log["steps"] if s.get("status") != "applied")
    return Counter("; ".join(e.get("problems") or []) or "the move changed nothing" for e in log.get("edits", [])
                   if not (e.get("accepted") and e.get("changed", True)))


def edits_line(requested: int, applied: int, reasons: Mapping[str, int], *, scenes: int = 1, refused: int = 0,
               no_failure: tuple[int, int] = (0, 0), stopped: Sequence[str] = ()) -> str:
    """One line on what G made: ``applied`` of ``requested`` edits (in ``scenes`` scenes), and where fewer, why: the
    steps' reasons with their counts, the scenes whose edited house the final validation ``refused``; and
    ``no_failure`` = (scenes, episodes) in which F found no failure (G then made the house harder without one); why G
    ``stopped`` early (LLM unavailable, budget used up), where it did."""
    where = f" in {scenes} scene{'s' * (scenes != 1)}" if scenes != 1 else ""
    line = f"G made {applied} of {requested} edit{'s' * (requested != 1)}{where}"
    why = [f"{r} ({n} step{'s' * (n != 1)})" for r, n in sorted(reasons.items(), key=lambda kv: -kv[1])]
    why += [f"G stopped early: {x}" for x in dict.fromkeys(x for x in stopped if x)]
    if refused:
        why.append(f"the final validation refused the edited house ({refused} scene{'s' * (refused != 1)}; its edits "
                   "were dropped)")
    if applied < requested and why:
        line += "; fewer because: " + "; ".join(why)
    elif applied < requested:
        line += "; fewer because G stopped early"
    n_scenes, n_episodes = no_failure
    if n_scenes:
        of = f" of {n_scenes} scene{'s' * (n_scenes != 1)}" if scenes != 1 else ""
        line += (f"; F found no failure in {n_episodes} episode{'s' * (n_episodes != 1)}{of} (the agent succeeded: "
                 "G made the house harder without a failure to aim at)")
    return line


def result_edits_line(result: AdaptResult, requested: int) -> str:
    """:func:`edits_line` of one adaptation step asked for ``requested`` edits."""
    log = {"steps": [st.model_dump(mode="json") for st in result.generation.steps]}
    if result.diagnosis is not None:
        no_failure = (1, len(result.diagnosis.episodes)) if not result.diagnosis.failures else (0, 0)
    else:
        no_failure = (1, 1) if result.before.metrics.success else (0, 0)
    return edits_line(requested, result.edits_applied if result.valid else 0, missed_edit_reasons(log),
                      refused=int(not result.valid), no_failure=no_failure, stopped=[result.generation.stopped])


def house_types(*houses: House) -> dict[str, str | None]:
    """Object id -> object type over the objects, children and doors of ``houses``."""
    out: dict[str, str | None] = {}
    for h in houses:
        out.update(house_object_types(h))
    return out


def changed_objects(result: AdaptResult) -> list[str]:
    """Ids of the objects (and doors) the applied edits changed on net, in edit order: an object moved back
    where it stood is not among them."""
    counts = edit_counts(result.generation.applied, result.original, result.house)
    return [o["id"] for o in counts["objects"] if o["changed"]]


def typed_edit_counts(result: AdaptResult) -> dict[str, Any]:
    """:func:`~adaptenv.adapt.edits.edit_counts` of the applied edits, each object with its type."""
    counts = edit_counts(result.generation.applied, result.original, result.house)
    types = house_types(result.original)
    counts["objects"] = [{"id": o["id"], "type": types.get(o["id"]), **{k: v for k, v in o.items() if k != "id"}}
                         for o in counts["objects"]]
    return counts


def verdict(before: dict[str, Any], after: dict[str, Any], *, tol: float = 1e-3) -> str:
    """``harder``, ``easier`` or ``unchanged`` for the agent, from two episodes' ``success`` and ``spl``: success
    decides when it changed, else SPL when it moved by more than ``tol``."""
    if bool(after["success"]) != bool(before["success"]):
        return "harder" if before["success"] else "easier"
    d = float(after["spl"]) - float(before["spl"])
    return "unchanged" if abs(d) <= tol else "harder" if d < 0 else "easier"


def _backend_info(part: Analyzer) -> dict[str, Any] | None:
    """Provider, API, model, base URL, prompt set and temperature of an LLM-backed F (never the key)."""
    backend = getattr(part, "backend", None)
    return backend.describe() if backend is not None else None


def _backend_prices(part: Analyzer) -> Prices | None:
    """Token prices of an LLM-backed F (None for the built-in)."""
    backend = getattr(part, "backend", None)
    return backend.config.prices() if backend is not None else None


def _agent(traj: Trajectory) -> dict[str, Any]:
    m = traj.metrics
    return {"success": m.success, "spl": m.spl, "steps": m.episode_length}


def write_outputs(result: AdaptResult, summary: dict[str, Any], out: Path) -> dict[str, Path]:
    """Write the adapted house, before/after renders (pi_t's own episode in each house), analysis, edit log,
    trajectories and summary into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    files = {"house": save_house(result.house, out / "house.json")}
    pair = render_before_after(result.original, result.house, result.before, result.after, changed_objects(result))
    files["before_png"] = save_render(pair.before, out / "before.png")
    files["after_png"] = save_render(pair.after, out / "after.png")
    files["before_after_png"] = save_render(pair.side_by_side(), out / "before_after.png")
    files["analysis"] = _write_json(out / "analysis.json", result.analysis.model_dump(mode="json"))
    files["edits"] = _write_json(out / "edits.json", result.generation.to_json_dict())
    files["trajectory_before"] = result.before.save(out / "trajectory_before.json")
    files["trajectory_after"] = result.after.save(out / "trajectory_after.json")
    files["summary"] = _write_json(out / "summary.json", summary)
    return files


def _write_json(path: Path, doc: Any) -> Path:
    atomic_write_text(path, json.dumps(doc, indent=1, default=_json_default))
    return path


def _json_default(x: Any) -> Any:
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, Path):
        return str(x)
    raise TypeError(f"not JSON serializable: {type(x).__name__}")


