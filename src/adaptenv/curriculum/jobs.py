"""The loop's parallel work as picklable jobs: held-out evaluation, rollouts and scene generation.

:func:`~adaptenv.curriculum.loop.run_loop` hands these to an executor (in process, a process pool
or Ray). A job carries everything it needs as plain data (policy weights, a house, seeds), so it
runs the same in any worker. Work is cut into pieces that do not depend on the number of workers
(evaluation in chunks of :data:`EVAL_CHUNK` episodes, one job per scene), so every executor returns
the same numbers.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from adaptenv.adapt.llm.accounting import scene_usage

#: Episodes per evaluation job: fixed, so results never depend on the worker count.
EVAL_CHUNK = 50


@dataclass(frozen=True)
class PolicyWeights:
    """A network's architecture and weights as plain data, so a job can carry its policy to any worker."""

    config: dict[str, Any]
    state: dict[str, Any]

    @classmethod
    def of(cls, net: Any) -> PolicyWeights:
        from dataclasses import asdict

        return cls(asdict(net.config), {k: v.detach().clone() for k, v in net.state_dict().items()})

    def policy(self) -> Any:
        """The weights as a batched NeuralPolicy (the loop's evaluation and rollout policy)."""
        from adaptenv.agents.network import NavNet, NetConfig, NeuralPolicy

        net = NavNet(NetConfig(**self.config))
        net.load_state_dict(self.state)
        return NeuralPolicy(net)


@functools.lru_cache(maxsize=8)
def heldout_set(spec: str) -> Any:
    """The compiled house set of ``spec``, loaded once per process (held-out sets never change)."""
    from adaptenv.agents.houses import load_house_set

    return load_house_set(spec)


@dataclass(frozen=True)
class EvalJob:
    """Episodes ``start:stop`` of a set's fixed held-out episodes (episode k depends on (seed, k) only)."""

    weights: PolicyWeights
    spec: str
    seed: int
    start: int
    stop: int


def eval_jobs(weights: PolicyWeights, specs: dict[str, str], episodes: int, seed: int) -> list[tuple[str, EvalJob]]:
    """Every set's episodes cut into :data:`EVAL_CHUNK` pieces, tagged with the set's name."""
    return [(name, EvalJob(weights, spec, seed, a, min(a + EVAL_CHUNK, episodes)))
            for name, spec in specs.items() for a in range(0, episodes, EVAL_CHUNK)]


def run_eval(job: EvalJob) -> list[Any]:
    """Run one chunk of held-out episodes; returns their EpisodeResults in order."""
    from adaptenv.agents.evaluate import run_episodes, sample_episodes

    hs = heldout_set(job.spec)
    eps = sample_episodes(hs.worlds, job.stop, job.seed, start=job.start)
    results, _ = run_episodes(hs.worlds, eps, job.weights.policy(), batch=len(eps))
    return results


@dataclass(frozen=True)
class RolloutJob:
    """One episode of a policy in one scene (for analysis or regret scoring)."""

    weights: PolicyWeights
    house: Any
    name: str
    episode_seed: int


def run_rollout(job: RolloutJob) -> tuple[Any, Any]:
    """Roll the policy out once in the scene; returns the EpisodeResult and the trajectory with metrics."""
    from adaptenv.agents.evaluate import run_episodes, trajectory_of
    from adaptenv.sim import task
    from adaptenv.sim.metrics import episode_metrics
    from adaptenv.sim.world import compile_world

    world = compile_world(job.house, job.name)
    episode = task.sample_episode(world, job.episode_seed)
    results, recs = run_episodes([world], [(0, episode)], job.weights.policy(), batch=1, record=lambda r: True)
    traj = trajectory_of(world, results[0], recs[results[0].index], "policy")
    traj.metrics = episode_metrics(world, traj)
    return results[0], traj


@dataclass(frozen=True)
class GenerateJob:
    """Make one new scene from a parent: ``random`` single-object edits or the paper's F then G."""

    kind: str
    """``random`` (random, accel) or ``ours`` / ``ours-llm`` (analysis F, then generator G)."""
    house: Any
    name: str
    edit_steps: int
    seed: tuple[int, ...]
    """Seed words of the job's generator (``np.random.default_rng(seed)``)."""
    trajectory: Any = None
    llm: dict[str, Any] = field(default_factory=dict)


@dataclass
class Generated:
    """What a generation job returns: the child scene, its edit log, the analysis (F) and the edit count."""

    house: Any
    edit_log: Any
    edits: int
    analysis: Any = None
    usage: Any = None
    """LLM usage of F and G for this scene (:class:`adaptenv.adapt.llm.Usage`; None for built-in methods)."""
    stopped: str = ""
    """Why G ended early (LLM unavailable, budget used up), else empty."""


def run_generate(job: GenerateJob) -> Generated:
    """Apply the job's generator to its parent scene."""
    rng = np.random.default_rng(list(job.seed))
    if job.kind == "random":
        from adaptenv.adapt.generators.random_perturbation import random_single_edits

        child, log = random_single_edits(job.house, job.edit_steps, rng)
        return Generated(child, log, sum(1 for e in log.edits if e.accepted and e.changed))
    from adaptenv.adapt.generators import GenerationContext
    from adaptenv.sim.task import Episode
    from adaptenv.sim.world import compile_world

    analyzer, generator = make_fg(job.kind, job.llm)
    traj = job.trajectory
    analysis = analyzer.analyze(traj, compile_world(job.house, job.name))
    episode = Episode(traj.target_type, (traj.start.x, traj.start.z, traj.start.yaw), traj.seed)
    ctx = GenerationContext(episode=episode, trajectory=traj, policy=None, render=False)
    gen = generator.generate(job.house, analysis, steps=job.edit_steps, context=ctx, rng=rng)
    return Generated(gen.house, gen.edit_log, len(gen.applied), analysis, scene_usage(analysis, gen), gen.stopped)


def make_fg(kind: str, llm: dict[str, Any]) -> tuple[Any, Any]:
    """Analyzer F and generator G of a method: built-in for ``ours``, LLM-backed for ``ours-llm``."""
    from adaptenv.adapt.analysis import BuiltinAnalyzer, LLMAnalyzer
    from adaptenv.adapt.generators import make_generator

    if kind == "ours-llm":
        from adaptenv.adapt.llm import LLMConfig, make_backend

        backend = make_backend(LLMConfig(**llm))
        return LLMAnalyzer(backend), make_generator("llm", backend=backend)
    return BuiltinAnalyzer(), make_generator("builtin")
