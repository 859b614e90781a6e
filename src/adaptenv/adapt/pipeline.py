"""The adapt loop once: roll out the policy, analyse (F), generate (G), validate, measure, write.

:func:`adapt_house` is ``e_{t+1} = G(e_t, F(tau^{e_t}))`` for one house and one episode::

    result = adapt_house(house, policy=resolve_policy("expert"), analyzer=BuiltinAnalyzer(),
                         generator=make_generator("builtin"), steps=5, seed=0, out_dir="runs/adapt")

Policies may be batched agents (:class:`adaptenv.agents.policy.Policy`: ``initial_state`` and
``act``, run through :func:`adaptenv.agents.evaluate.run_episodes`) or per-step callables
(:class:`adaptenv.sim.rollout.Policy`, run through :func:`adaptenv.sim.rollout.run_episode`).
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from adaptenv.adapt.analysis import Analysis, Analyzer
from adaptenv.adapt.generators import GenerationContext, GenerationResult, Generator
from adaptenv.adapt.llm.accounting import scene_usage
from adaptenv.errors import AdaptenvError
from adaptenv.scene.house import House
from adaptenv.sim.task import Episode
from adaptenv.sim.trajectory import Trajectory
from adaptenv.sim.world import NavWorld, compile_world

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- running a policy

def _is_batched(policy: Any) -> bool:
    return hasattr(policy, "act") and hasattr(policy, "initial_state")


def policy_label(policy: Any) -> str:
    """A short name for reports."""
    return str(getattr(policy, "name", type(policy).__name__))


def run_policy(world: NavWorld, episodes: list[Episode], policy: Any) -> list[Trajectory]:
    """Roll ``policy`` out on each episode of one world; trajectories carry their metrics."""
    from adaptenv.sim.metrics import episode_metrics

    if not episodes:
        return []
    if _is_batched(policy):
        from adaptenv.agents.evaluate import run_episodes, trajectory_of

        results, recs = run_episodes([world], [(0, ep) for ep in episodes], policy, batch=len(episodes),
                                     record=lambda r: True)
        out = []
        for k, res in enumerate(results):
            traj = trajectory_of(world, res, recs[k], policy_label(policy))
            traj.seed = episodes[k].seed
            traj.metrics = episode_metrics(world, traj)
            out.append(traj)
        return out
    from adaptenv.sim.rollout import run_episode

    return [run_episode(world, ep, policy) for ep in episodes]


def rollout(world: NavWorld, episode: Episode, policy: Any) -> Trajectory:
    """One recorded episode (pose, action, collisions, metrics)."""
    return run_policy(world, [episode], policy)[0]


def checking_episodes(episode: Episode, n: int) -> list[Episode]:
    """``n`` episodes with the same start position and target, headings spread evenly from the original."""
    n = max(1, int(n))
    return [replace(episode, start=(episode.start[0], episode.start[1], (episode.start[2] + k * 360.0 / n) % 360.0))
            for k in range(n)]


def policy_score(world: NavWorld, episodes: list[Episode], policy: Any) -> float:
    """Mean SPL of the policy over the episodes (the R that G tries to lower)."""
    trajs = run_policy(world, episodes, policy)
    return float(np.mean([t.metrics.spl for t in trajs])) if trajs else float("nan")


#: Episodes drawn for adaptation start at least this far (geodesic, m) from the target when possible.
MIN_EPISODE_DISTANCE = 2.5


def draw_episode(world: NavWorld, rng: np.random.Generator, target_type: str | None = None, *,
                 min_distance: float = MIN_EPISODE_DISTANCE, tries: int = 20) -> Episode:
    """A solvable episode whose start is at least ``min_distance`` from the target (else the longest of ``tries``).

    Very short episodes leave G nothing to work with (no route to narrow, occlude or lengthen).
    """
    from adaptenv.sim.geodesic import optimal_path_length
    from adaptenv.sim.task import sample_episode

    best, best_d = None, -1.0
    for _ in range(tries):
        ep = sample_episode(world, rng, target_type)
        d = optimal_path_length(world, ep)
        if d >= min_distance:
            return ep
        if d > best_d:
            best, best_d = ep, d
    return best


def find_solved_episode(world: NavWorld, policy: Any, rng: np.random.Generator, *, tries: int = 10,
                        target_type: str | None = None,
                        min_distance: float = MIN_EPISODE_DISTANCE) -> tuple[Episode, Trajectory] | None:
    """Sample episodes (see :func:`draw_episode`) until the policy succeeds on one (None after ``tries``)."""
    for _ in range(tries):
        ep = draw_episode(world, rng, target_type, min_distance=min_distance)
        traj = rollout(world, ep, policy)
        if traj.metrics.success:
            return ep, traj
    return None


def resolve_policy_spec(spec: str, *, seed: int = 0) -> Any:
    """``--policy`` through :func:`adaptenv.agents.registry.resolve_policy` (falls back to the sim's expert/random)."""
    try:
        from adaptenv.agents.registry import resolve_policy
    except ImportError:
        from adaptenv.sim.rollout import expert_policy, random_policy

        if spec == "expert":
            return expert_policy()
        if spec.startswith("random"):
            return random_policy(seed)
        raise AdaptenvError(f"--policy {spec!r}: only expert and random are available in this installation") from None
    return resolve_policy(spec, seed=seed)


# --------------------------------------------------------------------------- the adapt step

@dataclass
class AdaptResult:
    """Everything one adaptation produced (also written to ``out_dir``)."""

    house: House
    original: House
    episode: Episode
    analysis: Analysis
    generation: GenerationResult
    before: Trajectory
    after: Trajectory
    summary: dict[str, Any] = field(default_factory=dict)
    files: dict[str, Path] = field(default_factory=dict)


def _episode_dict(ep: Episode) -> dict[str, Any]:
    return {"target_type": ep.target_type, "start": list(ep.start), "seed": ep.seed}


def adapt_house(house: House, *, policy: Any, analyzer: Analyzer, generator: Generator, steps: int = 5,
                seed: int = 0, episode: Episode | None = None, target_type: str | None = None,
                out_dir: str | Path | None = None, name: str = "house", rollout_episodes: int = 3,
                check_with_policy: bool = True, render: bool = True) -> AdaptResult:
    """Adapt one house to one policy: rollout -> F -> G -> final validation -> after-rollout -> outputs.

    Args:
        house: the environment e_t (not modified).
        policy: the agent (batched ``act``/``initial_state`` or a per-step callable).
        analyzer: F (``BuiltinAnalyzer`` or ``LLMAnalyzer``).
        generator: G (``make_generator("builtin" | "llm" | "random")``).
        steps: single-object edits to make.
        seed: seeds the episode draw (when ``episode`` is None) and the generator.
        episode: the task; default: drawn with ``seed`` by :func:`draw_episode` (target ``target_type`` if given).
        out_dir: when set, write house.json, before.png, after.png, analysis.json, edits.json,
            summary.json and the two trajectories there.
        rollout_episodes: episodes per rollout check of candidate edits (built-in G).
        check_with_policy: let the built-in G check its best candidates with the policy.
        render: re-render after every edit (always on for the LLM generator).
    """
    from adaptenv.adapt.objectives import RouteSpec, measure, realism_score
    from adaptenv.adapt.validation import validate_scene
    from adaptenv.scene.validate import validate_house
    from adaptenv.sim.geodesic import is_solvable
    from adaptenv.sim.rollout import expert_policy, run_episode
    rng = np.random.default_rng(seed)
    world = compile_world(house, name)
    if episode is None:
        episode = draw_episode(world, np.random.default_rng([seed, 1]), target_type)
    before = rollout(world, episode, policy)
    analysis = analyzer.analyze(before, world)
    out = Path(out_dir) if out_dir is not None else None
    context = GenerationContext(episode=episode, trajectory=before,
                                policy=policy if check_with_policy else None,
                                rollout_episodes=rollout_episodes, render=render,
                                out_dir=out / "steps" if out is not None and render else None)
    generation = generator.generate(house, analysis, steps=steps, context=context, rng=rng)
    new = generation.house

    problems = [str(p) for p in validate_scene(new, episode_targets=[episode.target_type], start=episode.start[:2],
                                               original=house)]
    problems += [p.message for p in validate_house(new)]
    new_world = compile_world(new, name)
    after = rollout(new_world, episode, policy)
    expert = run_episode(new_world, episode, expert_policy())
    route = RouteSpec.from_episode(episode.target_type, episode.start, before)
    obj_before, obj_after = measure(world, route), measure(new_world, route)
    summary = {
        "house": name, "policy": policy_label(policy), "analyzer": getattr(analyzer, "name", "?"),
        "generator": generation.generator, "seed": seed, "episode": _episode_dict(episode),
        "steps_requested": steps, "edits_applied": len(generation.applied),
        "edits_verified": sum(1 for s in generation.steps if s.status == "applied" and s.verified),
        "agent_before": {"success": before.metrics.success, "spl": before.metrics.spl,
                         "steps": before.metrics.episode_length},
        "agent_after": {"success": after.metrics.success, "spl": after.metrics.spl,
                        "steps": after.metrics.episode_length},
        "objective_before": obj_before.as_dict(), "objective_after": obj_after.as_dict(),
        "realism_before": realism_score(house, house), "realism_after": realism_score(new, house),
        "expert_solvable": bool(is_solvable(new_world, episode)),
        "expert_success_after": bool(expert.metrics.success),
        "valid": not problems, "problems": problems, "stopped": generation.stopped,
        "usage": scene_usage(analysis, generation).to_dict(generation.prices or _prices(analyzer), calls=False),
        "llm": generation.llm or _llm_info(analyzer),
    }
    result = AdaptResult(new, house, episode, analysis, generation, before, after, summary)
    if out is not None:
        result.files = write_outputs(result, out)
    return result


def _llm_info(part: Any) -> dict[str, Any] | None:
    """Provider, API, model, base URL, prompt set, temperature of an LLM-backed F or G (never the key)."""
    describe = getattr(getattr(part, "backend", None), "describe", None)
    return describe() if describe is not None else None


def _prices(part: Any) -> Any:
    """Token prices of an LLM-backed F or G (None otherwise)."""
    cfg = getattr(getattr(part, "backend", None), "config", None)
    return cfg.prices() if cfg is not None else None


def write_outputs(result: AdaptResult, out: Path) -> dict[str, Path]:
    """Write the adapted house, renders, analysis, edit log and summary into ``out``."""
    from adaptenv.render.topdown import render_house, save_render
    from adaptenv.scene.house import save_house

    out.mkdir(parents=True, exist_ok=True)
    files = {"house": save_house(result.house, out / "house.json")}
    moved = {e.object_id: "gold" for e in result.generation.applied}
    files["before_png"] = save_render(render_house(result.original, trajectory=result.before, grid=True,
                                                   title="before"), out / "before.png")
    files["after_png"] = save_render(render_house(result.house, trajectory=result.after, grid=True,
                                                  highlight=moved or None, title="after (moved objects in gold)"),
                                     out / "after.png")
    files["analysis"] = _write_json(out / "analysis.json", result.analysis.model_dump(mode="json"))
    files["edits"] = _write_json(out / "edits.json", result.generation.to_json_dict())
    files["trajectory_before"] = result.before.save(out / "trajectory_before.json")
    files["trajectory_after"] = result.after.save(out / "trajectory_after.json")
    files["summary"] = _write_json(out / "summary.json", result.summary)
    return files


def _write_json(path: Path, doc: Any) -> Path:
    path.write_text(json.dumps(doc, indent=1, default=_json_default), encoding="utf-8")
    return path


def _json_default(x: Any) -> Any:
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, Path):
        return str(x)
    raise TypeError(f"not JSON serializable: {type(x).__name__}")
