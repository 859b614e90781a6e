"""The loop's parallel work as picklable jobs: held-out evaluation, rollouts and scene generation.

:func:`~adaptenv.curriculum.loop.run_loop` hands these to an executor (in process, a process pool
or Ray). A job carries everything it needs as plain data (policy weights, a house, seeds), so it
runs the same in any worker. Work is cut into pieces that do not depend on the number of workers
(evaluation in chunks of :data:`EVAL_CHUNK` episodes, one job per scene), so every executor returns
the same numbers.
"""

from __future__ import annotations

import functools
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from adaptenv.adapt.analysis import Analysis, Analyzer, BuiltinAnalyzer, LLMAnalyzer
from adaptenv.adapt.diagnosis import NoAnalyzer, hard_episodes
from adaptenv.adapt.edits import edit_counts
from adaptenv.adapt.generators import GenerationResult, Generator, make_generator
from adaptenv.adapt.generators.random_perturbation import random_single_edits
from adaptenv.adapt.llm import LLMConfig, make_backend
from adaptenv.adapt.llm.accounting import scene_usage
from adaptenv.adapt.llm.usage import Usage
from adaptenv.adapt.step import adapt_scene, changed_objects, edits_line, missed_edit_reasons
from adaptenv.adapt.target import adapt_to_success, measure
from adaptenv.agents.evaluate import EpisodeResult, Recorded, run_episodes, sample_episodes
from adaptenv.agents.houses import HouseSet, load_house_set
from adaptenv.agents.map_explorer import MapExplorerPolicy
from adaptenv.agents.policy import ExpertPolicy
from adaptenv.agents.rollout import run_recorded
from adaptenv.curriculum.records import SkippedHouses
from adaptenv.scene.house import House
from adaptenv.sim.task import Episode, sample_episode
from adaptenv.sim.trajectory import Trajectory
from adaptenv.sim.world import NavWorld, compile_world

if TYPE_CHECKING:
    from adaptenv.agents.network import NeuralPolicy

#: Episodes per evaluation job: fixed, so results never depend on the worker count. A set of 1,000 (an experiment's
#: final evaluation) is one job: fewer jobs draining their last slots (tools/time_eval_chunks.py, docs/BENCHMARKS.md).
EVAL_CHUNK = 1000
#: Simulator slots of an evaluation job: a slot whose episode ended takes the chunk's next episode, so few slots
#: idle while the longest episodes finish. An episode's result does not depend on which others share the batch.
EVAL_BATCH = 100


@dataclass(frozen=True)
class PolicyWeights:
    """A neural policy's architecture, weights and stop threshold as plain data, so a job can carry it to any worker."""

    config: dict[str, Any]
    state: dict[str, Any]
    end_threshold: float

    @classmethod
    def of(cls, policy: NeuralPolicy) -> PolicyWeights:
        net = policy.net
        return cls(asdict(net.config), {k: v.detach().clone() for k, v in net.state_dict().items()},
                   float(policy.end_threshold))

    def policy(self) -> NeuralPolicy:
        """The weights as a batched NeuralPolicy (the loop's evaluation and rollout policy)."""
        from adaptenv.agents.network import (  # torch: loaded in workers only
            NavNet,
            NetConfig,
            NeuralPolicy,
        )

        net = NavNet(NetConfig(**self.config))
        net.load_state_dict(self.state)
        return NeuralPolicy(net, end_threshold=self.end_threshold)


@functools.lru_cache(maxsize=8)
def heldout_set(spec: str) -> HouseSet:
    """The compiled house set of ``spec``, loaded once per process (held-out sets never change)."""
    return load_house_set(spec)


def skipped_houses(specs: Iterable[str]) -> dict[str, SkippedHouses]:
    """Per house-set spec, the houses it skips (count, names and reasons) as a run records them."""
    return {spec: SkippedHouses(count=len(s := heldout_set(spec).skipped), houses={h.name: h.reason for h in s})
            for spec in dict.fromkeys(specs)}


@dataclass(frozen=True)
class EvalJob:
    """Episodes ``start:stop`` of a set's fixed held-out episodes (episode k depends on (seed, k) only)."""

    weights: PolicyWeights
    spec: str
    seed: int
    start: int
    stop: int


def eval_jobs(weights: PolicyWeights, specs: dict[str, str], episodes: int, seed: int,
              chunk: int = EVAL_CHUNK) -> list[tuple[str, EvalJob]]:
    """Every set's episodes cut into pieces of ``chunk``, tagged with the set's name."""
    return [(name, EvalJob(weights, spec, seed, a, min(a + chunk, episodes)))
            for name, spec in specs.items() for a in range(0, episodes, chunk)]


def run_eval(job: EvalJob) -> tuple[list[EpisodeResult], dict[int, Recorded]]:
    """Run one chunk of held-out episodes: their EpisodeResults in order, and the failed ones' recordings.

    Results and recordings carry the episode's index in the whole set (``start`` + position).
    """
    hs = heldout_set(job.spec)
    eps = sample_episodes(hs.worlds, job.stop, job.seed, start=job.start)
    results, recs = run_episodes(hs.worlds, eps, job.weights.policy(), batch=min(len(eps), EVAL_BATCH),
                                 record=lambda r: not r.success)
    for r in results:
        r.index += job.start
    return results, {k + job.start: rec for k, rec in recs.items()}


@dataclass(frozen=True)
class RolloutJob:
    """Episodes of a policy in one scene, and the expert's on the same episodes (for analysis and scores)."""

    weights: PolicyWeights
    house: House
    name: str
    episode_seed: int
    episodes: int = 1
    """Episodes of pi_t (the first is the one F analyses; scores average all of them)."""
    explorer: bool = False
    """Also run the map explorer on the same episodes (for the ``explorer_regret`` score)."""


@dataclass
class Rollout:
    """pi_t's episodes in one scene: the tasks, results, trajectories (with metrics) and the references' successes.

    The first episode is the one F analyses (``episode``, ``result``, ``trajectory``); level scores
    (:func:`~adaptenv.curriculum.methods.level_score`) read every episode.
    """

    episodes: list[Episode]
    results: list[EpisodeResult]
    trajectories: list[Trajectory]
    expert_successes: list[bool]
    explorer_successes: list[bool] = field(default_factory=list)

    @property
    def episode(self) -> Episode:
        return self.episodes[0]

    @property
    def result(self) -> EpisodeResult:
        return self.results[0]

    @property
    def trajectory(self) -> Trajectory:
        return self.trajectories[0]

    @property
    def expert_success(self) -> bool:
        return self.expert_successes[0]

    @property
    def success_rate(self) -> float:
        """p: the fraction of pi_t's episodes that succeeded."""
        return float(np.mean([r.success for r in self.results]))

    @property
    def steps(self) -> int:
        """Environment steps pi_t took over all its episodes."""
        return sum(r.steps for r in self.results)


def rollout_episodes(world: NavWorld, seed: int, n: int) -> list[Episode]:
    """``n`` episodes of one scene: the first from ``seed`` itself, episode j from ``SeedSequence([seed, j])``."""
    seeds = [seed] + [int(np.random.SeedSequence([seed, j]).generate_state(1)[0]) for j in range(1, n)]
    return [sample_episode(world, s) for s in seeds]


def run_rollout(job: RolloutJob) -> Rollout:
    """Roll the policy out ``job.episodes`` times in the scene, then the expert (and the explorer) on the same episodes."""
    world = compile_world(job.house, job.name)
    episodes = rollout_episodes(world, job.episode_seed, job.episodes)
    recorded = run_recorded(world, episodes, job.weights.policy())
    tasks = [(0, ep) for ep in episodes]
    expert, _ = run_episodes([world], tasks, ExpertPolicy(), batch=len(tasks))
    explorer = []
    if job.explorer:
        explorer, _ = run_episodes([world], tasks, MapExplorerPolicy(), batch=len(tasks))
    return Rollout(episodes, [r for r, _ in recorded], [t for _, t in recorded], [r.success for r in expert],
                  [r.success for r in explorer])


GeneratorKind = Literal["random", "builtin", "llm", "failure-modes", "regret-only", "learned"]


def needs_policy(kind: GeneratorKind) -> bool:
    """Whether a generation job of this kind uses pi_t and its rollout (every G but ``random`` edits)."""
    return kind != "random"


@dataclass(frozen=True)
class GenerateJob:
    """Make one new scene from a parent: ``random`` single-object edits, or the adaptation step with F and G."""

    kind: GeneratorKind
    """``random`` (random, accel) or the G of :func:`~adaptenv.adapt.step.adapt_scene` (``builtin``, ``llm``)."""
    house: House
    name: str
    edit_steps: int
    seed: tuple[int, ...]
    """Seed words of the job's generator (``np.random.default_rng(seed)``)."""
    weights: PolicyWeights | None = None
    """pi_t: G checks its candidate edits against it and the child is rolled out with it (None for ``random``)."""
    rollout: Rollout | None = None
    """pi_t's episode in the parent (what F analyses); required for ``builtin`` and ``llm``."""
    llm: dict[str, Any] = field(default_factory=dict)
    diagnose_episodes: int = 0
    """When > 0: F diagnoses this many hard episodes of the parent (no ``rollout`` needed) and the
    child is diagnosed again on them (``failure-modes``: G aims at the failure families;
    ``regret-only``: G gets generic objectives, no F analysis)."""
    relocate_targets: bool = False
    """``failure-modes``: G may relocate a target instance to a far room (``LoopConfig.relocate_targets``)."""
    door_edits: bool = False
    """``failure-modes`` and ``llm``: G may open or shut interior doors (``LoopConfig.door_edits``)."""
    learned_scorer: str | None = None
    """``learned``: the scorer file (``LoopConfig.learned_scorer``); None: the shipped one."""
    appearance: float = 0.0
    """``random``: share of the edits that swap an asset or change a material instead of moving an object
    (``LoopConfig.appearance_edits``; 0: moves only)."""
    target_success: float | None = None
    """When set: edit toward pi_t's success rate P on ``target_episodes`` fixed episodes
    (:func:`~adaptenv.adapt.target.adapt_to_success`, ``edit_steps`` the budget) instead of the most difficulty."""
    target_tolerance: float = 0.10
    target_episodes: int = 20
    target_choices: int = 1
    target_draws: int = 1
    target_stop_gap: float | None = None


@dataclass
class Generated:
    """What a generation job returns: the child scene and how it was made."""

    house: House
    edit_log: dict[str, Any]
    """The edits as written to edits.json (a generator's steps with verification, or an EditLog)."""
    edits: int
    """Edits that are in the child (applied and changing the scene)."""
    analysis: Analysis | None = None
    after: Trajectory | None = None
    """pi_t's episode in the child (same start and target as the parent's rollout)."""
    moved: list[str] = field(default_factory=list)
    """Ids of the objects (and doors) the child's edits changed on net: moved or turned from where they stood."""
    valid: bool = True
    """False when the final validation refused the edited house (the child is then the parent, unedited)."""
    usage: Usage | None = None
    """LLM usage of F and G for this scene (empty for the built-ins; None for random edits)."""
    stopped: str = ""
    """Why G ended early (LLM unavailable, budget used up), else empty."""
    regret_before: float | None = None
    """Regret of pi_t in the parent over the diagnosis episodes (diagnosing jobs)."""
    regret_after: float | None = None
    """Regret of pi_t in the child over the same episodes."""
    success_before: float | None = None
    """pi_t's success rate in the parent over the diagnosis episodes (diagnosing jobs)."""
    success_after: float | None = None
    """pi_t's success rate in the child over the same episodes."""
    rollout_steps: int = 0
    """pi_t's environment steps in this job: the diagnosis episodes (parent and child) and G's rollout checks."""
    before: Trajectory | None = None
    """The episode F analysed in the parent (the worst one of a diagnosis)."""


def run_generate(job: GenerateJob) -> Generated:
    """Apply the job's generator to its parent scene."""
    rng = np.random.default_rng(list(job.seed))
    if job.kind == "random":
        child, log = random_single_edits(job.house, job.edit_steps, rng, appearance=job.appearance)
        moved = [e.object_id for e in log.edits if e.accepted and e.changed]
        return Generated(child, log.model_dump(mode="json"), len(moved), moved=moved)
    if job.target_success is not None:
        return _run_targeted(job)
    if job.diagnose_episodes > 0:
        return _run_diagnosed(job, rng)
    if job.rollout is None or job.weights is None:
        raise ValueError(f"GenerateJob {job.name}: kind {job.kind!r} needs the policy weights and its rollout")
    analyzer, generator = make_fg(job.kind, job.llm, door_edits=job.door_edits, learned_scorer=job.learned_scorer)
    res = adapt_scene(job.house, job.rollout.episode, policy=job.weights.policy(), analyzer=analyzer,
                      generator=generator, steps=job.edit_steps, rng=rng, before=job.rollout.trajectory,
                      name=job.name)
    log, gen = res.generation.to_json_dict(), res.generation
    common = dict(usage=scene_usage(res.analysis, gen), stopped=gen.stopped, rollout_steps=check_steps(gen))
    if not res.valid:  # the final check refused the whole edited house: the parent stands, nothing was applied
        log["final_validation"] = res.problems
        return Generated(job.house, log, 0, res.analysis, res.before, valid=False, **common)
    return Generated(res.house, log, res.edits_applied, res.analysis, res.after,
                     moved=changed_objects(res), **common)


def _run_diagnosed(job: GenerateJob, rng: np.random.Generator) -> Generated:
    """Diagnose the parent on hard episodes, adapt it (G per the job's kind), diagnose the child on the same episodes."""
    if job.weights is None:
        raise ValueError(f"GenerateJob {job.name}: kind {job.kind!r} needs the policy weights")
    episodes = hard_episodes(compile_world(job.house, job.name), rng, job.diagnose_episodes)
    analyzer, generator = make_fg(job.kind, job.llm, relocate_targets=job.relocate_targets,
                                  door_edits=job.door_edits, learned_scorer=job.learned_scorer)
    res = adapt_scene(job.house, episodes[0], policy=job.weights.policy(), analyzer=analyzer, generator=generator,
                      steps=job.edit_steps, rng=rng, name=job.name, episodes=episodes)
    log = res.generation.to_json_dict()
    log["diagnosis"] = res.diagnosis.model_dump(mode="json")
    log["diagnosis_after"] = res.diagnosis_after.model_dump(mode="json")
    steps = (sum(e.steps for e in res.diagnosis.episodes) + sum(e.steps for e in res.diagnosis_after.episodes)
             + check_steps(res.generation))
    common = dict(regret_before=res.diagnosis.regret, success_before=res.diagnosis.success_rate,
                  rollout_steps=steps, before=res.before,
                  usage=scene_usage(res.analysis, res.generation), stopped=res.generation.stopped)
    if not res.valid:
        log["final_validation"] = res.problems
        return Generated(job.house, log, 0, res.analysis, res.before, valid=False,
                         regret_after=res.diagnosis.regret, success_after=res.diagnosis.success_rate, **common)
    return Generated(res.house, log, res.edits_applied, res.analysis, res.after,
                     moved=changed_objects(res), regret_after=res.diagnosis_after.regret,
                     success_after=res.diagnosis_after.success_rate, **common)


def _run_targeted(job: GenerateJob) -> Generated:
    """Edit the parent until pi_t's measured success is near the job's target; score parent and child on the
    same episodes (pi_t's success, and its regret against the expert)."""
    if job.weights is None:
        raise ValueError(f"GenerateJob {job.name}: kind {job.kind!r} needs the policy weights")
    analyzer, generator = make_fg(job.kind, job.llm, relocate_targets=job.relocate_targets, door_edits=job.door_edits,
                                  learned_scorer=job.learned_scorer)
    res = adapt_to_success(job.house, job.weights.policy(), generator, job.target_success,
                           tolerance=job.target_tolerance, episodes=job.target_episodes, max_edits=job.edit_steps,
                           analyzer=analyzer, seed=job.seed, name=job.name, choices=job.target_choices,
                           draws=job.target_draws, stop_gap=job.target_stop_gap)
    expert_before, _ = measure(compile_world(job.house, job.name), res.episodes, ExpertPolicy())
    expert_after, _ = measure(compile_world(res.house, job.name), res.episodes, ExpertPolicy()) if res.edits \
        else (expert_before, None)
    return Generated(res.house, res.generation_log(), len(res.edits), None, res.trajectories_after[0],
                     moved=[o["id"] for o in edit_counts(res.edits, job.house, res.house)["objects"] if o["changed"]],
                     usage=res.usage, regret_before=max(0.0, expert_before.success - res.before.success),
                     regret_after=max(0.0, expert_after.success - res.after.success),
                     success_before=res.before.success, success_after=res.after.success,
                     rollout_steps=res.env_steps, before=res.trajectories_before[0])


def generation_line(made: Sequence[Generated], requested: int) -> str:
    """One line on what G made in an iteration's generation jobs (each asked for ``requested`` edits) and, where
    fewer, why: :func:`~adaptenv.adapt.step.edits_line` over the jobs' logs and diagnoses."""
    reasons: Counter[str] = Counter()
    no_failure = [0, 0]
    for m in made:
        if m.edits < requested:
            reasons += missed_edit_reasons(m.edit_log)
        episodes = (m.edit_log.get("diagnosis") or {}).get("episodes")
        if episodes and all(e.get("success") for e in episodes):
            no_failure[0] += 1
            no_failure[1] += len(episodes)
        elif episodes is None and m.analysis is not None and m.analysis.outcome.success:
            no_failure[0] += 1
            no_failure[1] += 1
    return edits_line(requested * len(made), sum(m.edits for m in made), reasons, scenes=len(made),
                      refused=sum(not m.valid for m in made), no_failure=(no_failure[0], no_failure[1]),
                      stopped=[m.stopped for m in made])


def check_steps(generation: GenerationResult) -> int:
    """pi_t's environment steps in G's rollout checks of one generation."""
    return sum(s.check_steps for s in generation.steps)


def make_fg(kind: GeneratorKind, llm: dict[str, Any], *, relocate_targets: bool = False,
            door_edits: bool = False, learned_scorer: str | None = None) -> tuple[Analyzer, Generator]:
    """Analyzer F and generator G: built-in, learned (``learned_scorer``: its scorer file, None the shipped one), or
    LLM-backed (one backend shared by F and G)."""
    if kind == "llm":
        backend = make_backend(LLMConfig(**llm))
        return LLMAnalyzer(backend), make_generator("llm", backend=backend, door_edits=door_edits)
    if kind == "failure-modes":
        return BuiltinAnalyzer(), make_generator("failure-modes", relocate_targets=relocate_targets,
                                                     door_edits=door_edits)
    if kind == "regret-only":
        return NoAnalyzer(), make_generator("builtin")
    if kind == "learned":
        return BuiltinAnalyzer(), make_generator("learned", checkpoint=learned_scorer)
    return BuiltinAnalyzer(), make_generator("builtin")
