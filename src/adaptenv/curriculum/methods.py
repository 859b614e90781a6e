"""Curriculum methods as strategies: which scenes pi_t is rolled out in, which scenes are made, what is trained on.

:func:`~adaptenv.curriculum.loop.run_loop` calls the same hooks of every method, in this order,
each iteration t (the split JaxUED's examples use between a resettable environment and the level
sampler):

1. :meth:`Method.scenes_to_roll_out`: the scenes pi_t plays once each (analysed or scored);
2. the loop rolls pi_t out in them ``score_rollouts`` times each (and the expert, for regret);
3. :meth:`Method.update_buffer`: what goes into the level buffer, scored by :func:`level_score` (PLR, ACCEL, ours);
4. :meth:`Method.make_scenes`: the new training scenes e_{t+1};
5. :meth:`Method.train_on`: the scenes pi_t is fine-tuned on.

A method is one class registered in :data:`METHODS`; adding one is a new class and one registry
line (see docs/curriculum.md). Hooks read and change only the :class:`Iteration` they are given;
every random choice comes from a named :class:`Stream` of ``(seed, t)``. The run's settings
(:class:`LoopConfig`) and saved state (:class:`LoopState`), which every hook reads, are defined here too;
:mod:`adaptenv.curriculum.loop` imports them.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, fields
from enum import IntEnum
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from adaptenv.adapt.generators.learned import load_scorer
from adaptenv.adapt.llm.accounting import check_llm_section
from adaptenv.adapt.target import MAX_DRAWS, check_stop_gap, check_target
from adaptenv.agents.config import FinetuneConfig
from adaptenv.agents.teachers import TEACHERS
from adaptenv.agents.train import check_precision
from adaptenv.configfile import STRICT, parse_config
from adaptenv.curriculum import buffer as lb
from adaptenv.curriculum.executor import Executor
from adaptenv.curriculum.gallery import gallery_item
from adaptenv.curriculum.jobs import (
    Generated,
    GenerateJob,
    GeneratorKind,
    PolicyWeights,
    Rollout,
    needs_policy,
    run_generate,
)
from adaptenv.curriculum.records import GalleryItem, SceneStore, read_iterations
from adaptenv.errors import ConfigError
from adaptenv.limits import check_float, check_seed
from adaptenv.scene.house import House
from adaptenv.scene.procedural import generate_house, preset_spec, rearrange_house
from adaptenv.scene.procedural.variations import vary_house

PPO_ONLY = ("finetune_kl_coef", "finetune_explore_bonus", "finetune_freeze_encoder", "finetune_bc_coef")
"""LoopConfig fields that only anchored PPO reads (DAgger takes them at their defaults or 0)."""


@dataclass
class LoopConfig:
    """Settings of one closed-loop run (one method, one seed); saved as run.json."""

    method: str = "ours"
    """One of none, random, dr, dr-matched, sfl, oracle, rearrange, swap, plr, accel, ours, ours-noselect,
    ours-randomscene, ours-nof, ours-dr, ours-learned, ours-llm."""
    policy: str = "pretrained"
    """Starting policy pi_0: pretrained, a checkpoint path (it must be a neural policy to fine-tune), or scratch /
    scratch-shape: a fresh map-reading network (labels, or the recognising mode) drawn from the run's seed."""
    houses: str = "preset:pretrain-train"
    """Training scenes e_0: a folder of house JSON files, a dataset FILE.jsonl[.gz][:START:STOP] or preset:NAME."""
    heldout: dict[str, str] = field(default_factory=lambda: {"rearranged": "preset:pretrain-rearranged",
                                                             "unseen": "preset:pretrain-unseen"})
    """Held-out sets, never trained on: name -> folder, dataset (FILE.jsonl.gz[:START:STOP]) or preset:NAME."""
    iterations: int = 3
    """Loop iterations T."""
    seed: int = 0
    """Root seed; every random choice derives from (seed, iteration)."""
    scenes_per_iteration: int = 8
    """Scenes rolled out (analysed or scored) and new scenes made per iteration."""
    score_rollouts: int = 4
    """Episodes of pi_t (and of the expert) per rolled-out scene: scene scores average them, F analyses the first."""
    level_score: str = "regret"
    """How plr, accel and ours score a scene: regret (expert success - pi_t's), learnability (p(1-p), p pi_t's
    success rate) or explorer_regret (the map explorer's success - pi_t's; one more rollout per episode)."""
    sfl_candidates: int = 4
    """sfl: fresh houses scored per training scene; it trains on the most learnable 1 in sfl_candidates."""
    match_method: str = "ours"
    """dr-matched: the method whose environment steps it matches (an experiment runs it first, same seed)."""
    match_run: str = ""
    """dr-matched: that run's folder (an experiment fills it in: OUT/<match_method>/seed_<seed>)."""
    edit_steps: int = 5
    """Single-object edits per adapted scene (editing methods)."""
    finetune_algo: str = "ppo"
    """How pi_t is fine-tuned: ppo (anchored PPO on the simulator's reward, the recipe that made ``pretrained``;
    docs/curriculum.md, "The fine-tuning recipe") or dagger (imitation of finetune_teacher)."""
    finetune_frames: int = FinetuneConfig.frames
    """Environment frames of fine-tuning per iteration (identical for every method)."""
    finetune_envs: int = FinetuneConfig.num_envs
    """Parallel agents while fine-tuning."""
    finetune_lr: float = FinetuneConfig.learning_rate
    """Adam learning rate of fine-tuning, annealed to zero over each iteration's frames (the gentler of
    the two rates compared in docs/results/ARCHIVE.md)."""
    finetune_teacher: str = "expert"
    """Who labels fine-tuning's states (DAgger's, or PPO's imitation term finetune_bc_coef): expert (shortest path),
    explorer or map-explorer (search, docs/agent.md) or mix."""
    finetune_min_start: float = 6.0
    """Fine-tuning episodes start at least this geodesic distance (m) from the target where a house allows
    (0: uniform starts; the long suites use 6 m)."""
    finetune_precision: str = "auto"
    """Arithmetic of fine-tuning's gradient steps: auto (bf16 where the CPU computes it natively, else fp32; run.json
    records which), fp32, or bf16 autocast (on CPUs with AVX512_BF16 DAgger's steps about 2.4x faster and PPO end
    to end 1.4x; about 8x slower on AVX2-only CPUs; docs/BENCHMARKS.md)."""
    finetune_beta: float = FinetuneConfig.beta
    """Probability that the teacher's action is executed while fine-tuning (DAgger's beta, constant)."""
    finetune_max_steps: int = 600
    """Episode cap of fine-tuning's episodes (the evaluation's 600, to which the map-reading agent trains)."""
    finetune_kl_coef: float = 0.03
    """ppo: weight of the KL anchor to pi_t (0.3 in the PPO runs of docs/agent.md)."""
    finetune_explore_bonus: float = 0.002
    """ppo: reward per newly seen map cell (as in the PPO runs of docs/agent.md)."""
    finetune_bc_coef: float = 0.0
    """ppo: weight of a cross-entropy to finetune_teacher's labels of the states PPO visits (an imitation term;
    0: off)."""
    finetune_freeze_encoder: bool = False
    """ppo: train pi_t's memory and heads only, its observation encoder fixed at pi_0's weights (faster updates;
    docs/BENCHMARKS.md)."""
    finetune_keep_learner: bool = True
    """ppo: each iteration continues the last one's value head and Adam moments (one PPO run across the loop, as
    UED methods train); false starts every iteration with a fresh critic and a value warm-up."""
    grounded: bool = False
    """sfl, plr, accel and ours take their new levels from the training homes (round robin) after edit_steps random
    edits each, instead of fresh procedural houses (the scarce-homes setting: only dr, dr-matched and oracle, the
    declared upper bounds, draw fresh houses)."""
    appearance_edits: bool = False
    """Random edits (random, accel's children, grounded levels) may also swap an object's asset within its type and
    split or give a room's floor or walls another material (half of them; adapt/appearance.py)."""
    replay_fraction: float = 0.5
    """Share of the fine-tuning scenes drawn from earlier scenes so the policy does not forget."""
    heldout_episodes: int = 100
    """Episodes per held-out set per evaluation (the same episodes every iteration)."""
    gallery: int = 4
    """Adapted scenes per iteration kept with before/after renders for the report."""
    llm: dict[str, Any] = field(default_factory=dict)
    """LLMConfig fields for ours-llm (provider, model, base_url, api, cache_dir, prompts, price_in, price_out,
    max_tokens, max_cost, ...; docs/llm.md). Never an API key: name its variable in api_key_env."""
    buffer_capacity: int = 64
    """Level buffer size (plr, accel, ours)."""
    seed_buffer: bool = True
    """The first iteration scores the training scenes into the level buffer (plr, accel, ours); false keeps
    them out, so the buffer holds only generated scenes (fresh houses and their children)."""
    diagnose_episodes: int = 4
    """Hard episodes F diagnoses per adapted scene (ours, ours-randomscene, ours-nof, ours-dr)."""
    focus_training: bool = False
    """Fine-tuning episodes in a scene adapted after a diagnosis (ours and its variants) ask for the target type
    G's edits aimed at (the worst diagnosed episode's), instead of any type: pi_t trains on the failure it was shown."""
    relocate_targets: bool = False
    """The failure-mode G may answer search failures by moving a target instance inside its room or relocating it
    to a far room of a type where it plausibly stands (the methods with the failure-mode G: ours,
    ours-randomscene, ours-dr); otherwise no edit moves a target."""
    door_edits: bool = False
    """G may also open or shut interior doors: the failure-mode G for search, looping and timeout failures, the LLM
    G (ours-llm) through its set_door_openness tool."""
    learned_scorer: str | None = None
    """ours-learned: the learned G's scorer file (``adaptenv gdata train -o FILE.pt``); null: the shipped one."""
    target_success: float | None = None
    """Difficulty on request: each adapted scene is edited until pi_t's success on target_episodes fixed episodes is
    within target_tolerance of this rate P (0 < P < 1; edit_steps is the edit budget,
    :func:`~adaptenv.adapt.target.adapt_to_success`) instead of being made as hard as G can; null: off. Only the
    methods that adapt scenes with G (ADAPTING_METHODS) take it."""
    target_tolerance: float = 0.10
    """With target_success: stop editing a scene once |success - P| is at most this."""
    target_episodes: int = 20
    """With target_success: episodes pi_t's success on a scene is measured on (the same after every edit)."""
    target_choices: int = 1
    """With target_success: edits G proposes per round, each measured on those episodes; the closest to P is kept."""
    target_draws: int = 1
    """With target_success: action draws per measured episode, each with its own sampling seed."""
    target_stop_gap: float | None = None
    """With target_success: stop editing a scene once |success - P| is at most this (0 to target_tolerance; null:
    half of target_tolerance)."""

    __pydantic_config__ = STRICT

    def check(self, source: str = "loop config") -> LoopConfig:
        """Return self or raise one ConfigError naming the field and the fix (``source`` starts the message)."""
        parse_config(LoopConfig, asdict(self), source)
        if self.method not in METHODS:
            raise ConfigError(f"{source}: method {self.method!r} is unknown; use one of {', '.join(METHODS)}")
        check_seed(self.seed, f"{source}: seed")
        check_float(self.finetune_lr, f"{source}: finetune_lr", 0.0, 1.0, lo_open=True)
        for name in ("finetune_kl_coef", "finetune_explore_bonus", "finetune_bc_coef", "finetune_min_start"):
            check_float(getattr(self, name), f"{source}: {name}")
        for name in ("iterations", "scenes_per_iteration", "finetune_frames", "heldout_episodes", "finetune_envs",
                     "score_rollouts", "sfl_candidates"):
            if getattr(self, name) < 1:
                raise ConfigError(f"{source}: {name} must be at least 1, got {getattr(self, name)}")
        if self.edit_steps < 0 or self.diagnose_episodes < 1 or not 0.0 <= self.replay_fraction < 1.0:
            raise ConfigError(f"{source}: edit_steps must be >= 0, diagnose_episodes >= 1 and replay_fraction "
                              "in [0, 1)")
        check_precision(self.finetune_precision, f"{source}: finetune_precision")
        if self.finetune_algo not in ("dagger", "ppo"):
            raise ConfigError(f"{source}: finetune_algo must be dagger or ppo, got {self.finetune_algo!r}")
        defaults = {f.name: f.default for f in fields(LoopConfig)}
        if self.finetune_algo == "dagger" and any(getattr(self, k) not in (0, defaults[k]) for k in PPO_ONLY):
            raise ConfigError(f"{source}: finetune_kl_coef, finetune_explore_bonus, finetune_freeze_encoder and "
                              "finetune_bc_coef apply to ppo only; set finetune_algo to ppo or leave them unset")
        if not 0.0 <= self.finetune_beta <= 1.0 or self.finetune_max_steps < 1:
            raise ConfigError(f"{source}: finetune_beta must lie in [0, 1] and finetune_max_steps be positive, got "
                              f"{self.finetune_beta} and {self.finetune_max_steps}")
        if self.finetune_min_start < 0:
            raise ConfigError(f"{source}: finetune_min_start must be >= 0 metres, got {self.finetune_min_start}")
        if self.method == "dr-matched" and (self.match_method not in METHODS or self.match_method == "dr-matched"):
            raise ConfigError(f"{source}: match_method {self.match_method!r} must name another method, e.g. ours")
        if self.method == "dr-matched" and not self.match_run:
            raise ConfigError(f"{source}: dr-matched needs match_run, the folder of the run it matches (--match-run); "
                              "an experiment fills it in")
        if self.level_score not in LEVEL_SCORES:
            raise ConfigError(f"{source}: level_score {self.level_score!r} is unknown; use one of "
                              f"{', '.join(LEVEL_SCORES)}")
        if self.finetune_teacher not in TEACHERS:
            raise ConfigError(f"{source}: finetune_teacher {self.finetune_teacher!r} is unknown; use one of "
                              f"{', '.join(TEACHERS)}")
        if self.finetune_algo == "ppo" and (self.finetune_beta != defaults["finetune_beta"] or (
                self.finetune_teacher != defaults["finetune_teacher"] and not self.finetune_bc_coef)):
            raise ConfigError(f"{source}: finetune_beta and finetune_teacher apply to dagger (the teacher also to ppo "
                              "with finetune_bc_coef); set finetune_algo to dagger or leave them unset")
        if self.method == "ours-llm" and not self.llm:
            raise ConfigError(f"{source}: method ours-llm needs an llm section (provider, model, base_url); "
                              "see docs/llm.md")
        check_llm_section(self.llm, source)
        if self.learned_scorer is not None:
            if self.method != "ours-learned":
                raise ConfigError(f"{source}: learned_scorer applies to ours-learned, not {self.method}; pick "
                                  "ours-learned or drop learned_scorer")
            load_scorer(self.learned_scorer)  # a missing or foreign file is refused here, before any work
        if self.target_success is not None:
            check_target(self.target_success, self.target_tolerance, what=f"{source}: target_success",
                         tol_what=f"{source}: target_tolerance")
            if self.method not in ADAPTING_METHODS:
                raise ConfigError(f"{source}: target_success applies to the methods that adapt scenes with G "
                                  f"({', '.join(ADAPTING_METHODS)}), not {self.method}; pick one or drop target_success")
            if self.target_episodes < 1:
                raise ConfigError(f"{source}: target_episodes must be at least 1, got {self.target_episodes}")
            if not 1 <= self.target_choices <= 64:
                raise ConfigError(f"{source}: target_choices must be a whole number from 1 to 64, got "
                                  f"{self.target_choices}")
            check_stop_gap(self.target_stop_gap, self.target_tolerance, what=f"{source}: target_stop_gap")
            if not 1 <= self.target_draws <= MAX_DRAWS:
                raise ConfigError(f"{source}: target_draws must be a whole number from 1 to {MAX_DRAWS}, got "
                                  f"{self.target_draws}")
        return self


@dataclass
class LoopState:
    """Where a run stands after a finished iteration (state.json); scenes live in RUN_DIR/scenes/."""

    __pydantic_config__ = STRICT

    iteration: int = 0
    pool: list[str] = field(default_factory=list)
    """Current training scenes (names), the ones the next iteration rolls out and adapts."""
    archive: list[str] = field(default_factory=list)
    """Every training scene made so far, originals first (replay mix draws from it)."""
    buffer: dict[str, Any] | None = None
    """The level buffer (plr, accel) as JSON-ready data."""
    env_steps: int = 0
    grad_updates: int = 0
    edits: int = 0
    generated: int = 0


class Stream(IntEnum):
    """The independent random streams of one iteration: ``np.random.default_rng([seed, t, stream])``."""

    ACCEL_REPLAY = 1
    """ACCEL: which buffer levels are replayed (and edited)."""
    ACCEL_PARENTS = 2
    """ACCEL: the seeds of the children's random edits."""
    FRESH_HOUSES = 3
    """DR, PLR, ACCEL and ``ours``: seeds of fresh procedural houses."""
    ROLLOUT_EPISODES = 4
    """The episodes pi_t plays in the rolled-out scenes."""
    REPLAY = 5
    """PLR (and ACCEL's first iteration): which buffer levels are trained on."""
    ARCHIVE_MIX = 6
    """Methods that make scenes: which earlier scenes are mixed into fine-tuning."""
    FINETUNE = 7
    """Fine-tuning (episode draws, minibatches)."""
    ORACLE_HOUSES = 8
    """``oracle``: seeds of its fresh houses (from the held-out suites' generator settings)."""
    REARRANGE = 9
    """``rearrange``: which training home is rearranged, and the rearrangement's seed."""
    SWAP = 10
    """``swap``: the seeds of the homes' variations (assets swapped, materials redrawn)."""
    GROUNDED = 11
    """``grounded``: the seeds of the random edits that make new levels from the homes."""
    GENERATE = 100
    """Scene generation; job k of the iteration uses ``[seed, t, GENERATE + k]``."""


@dataclass
class Iteration:
    """What a method's hooks see and change during iteration t; the loop owns it and saves what persists."""

    t: int
    cfg: LoopConfig
    state: LoopState
    store: SceneStore
    buffer: lb.LevelBufferState
    buffer_cfg: lb.LevelBufferConfig
    weights: PolicyWeights
    """pi_t as plain data (jobs carry it to workers)."""
    executor: Executor
    run_dir: Path
    gallery: list[GalleryItem] = field(default_factory=list)
    parents: dict[str, str] = field(default_factory=dict)
    """Scene edited this iteration -> the scene it was edited from (ACCEL's children, editing methods' and ours')."""
    replayed: list[str] = field(default_factory=list)
    """Buffer levels replayed this iteration (ACCEL trains on them)."""
    made: list[tuple[str, Generated]] = field(default_factory=list)
    """Every scene the method's generation jobs made this iteration (parent name, what the job returned)."""
    steps_before: int = 0
    """Environment steps of the run when this iteration began."""

    def rng(self, stream: Stream) -> np.random.Generator:
        """The generator of one named purpose of this iteration, independent of every other."""
        return np.random.default_rng([self.cfg.seed, self.t, int(stream)])

    def seed(self, stream: Stream, *words: int) -> int:
        """A 32-bit seed of one named purpose (for procedural houses, episodes and fine-tuning)."""
        return int(np.random.SeedSequence([self.cfg.seed, self.t, int(stream), *words]).generate_state(1)[0])


class Method:
    """The default hooks; each method overrides what it does differently."""

    name: ClassVar[str]
    replaces_parents: ClassVar[bool] = False
    """Made scenes take their parents' places in the pool (scene-editing methods)."""
    uses_llm: ClassVar[bool] = False
    """F and G call an LLM: the loop keeps its token ledger and budget."""

    def scenes_to_roll_out(self, it: Iteration) -> list[str]:
        """The next ``scenes_per_iteration`` scenes of the pool, round robin."""
        pool, n = it.state.pool, it.cfg.scenes_per_iteration
        first = (it.t - 1) * n % len(pool)
        return [pool[(first + k) % len(pool)] for k in range(min(n, len(pool)))]

    def update_buffer(self, it: Iteration, rolled: list[str], rollouts: list[Rollout]) -> None:
        """Insert scored levels into the buffer (nothing by default)."""

    def make_scenes(self, it: Iteration, rolled: list[str], rollouts: list[Rollout]) -> list[str]:
        """The new training scenes e_{t+1} (none by default)."""
        return []

    def finetune_frames(self, it: Iteration) -> int:
        """Fine-tuning frames of this iteration (the same ``finetune_frames`` for every method but ``dr-matched``)."""
        return it.cfg.finetune_frames

    def train_on(self, it: Iteration, rolled: list[str], new: list[str]) -> list[str]:
        """The new scenes plus earlier ones (``replay_fraction`` of the mix) so the policy does not forget."""
        state = it.state
        if self.replaces_parents:
            pool = list(state.pool)
            for parent, child in zip(rolled, new, strict=True):
                pool[pool.index(parent)] = child
            state.pool = pool
        n_replay = int(round(len(new) * it.cfg.replay_fraction / (1.0 - it.cfg.replay_fraction)))
        earlier = state.archive
        pick = it.rng(Stream.ARCHIVE_MIX).choice(len(earlier), size=min(n_replay, len(earlier)), replace=False)
        state.archive = earlier + [x for x in new if x not in earlier]
        return new + [earlier[i] for i in sorted(pick.tolist())]


class NoNewScenes(Method):
    """``none``: fine-tune on the original training scenes only (the control)."""

    name = "none"

    def train_on(self, it: Iteration, rolled: list[str], new: list[str]) -> list[str]:
        return list(it.state.pool)


class DomainRandomization(Method):
    """``dr``: fresh procedural houses every iteration (open loop)."""

    name = "dr"

    def scenes_to_roll_out(self, it: Iteration) -> list[str]:
        return fresh_houses(it, it.cfg.scenes_per_iteration)

    def make_scenes(self, it: Iteration, rolled: list[str], rollouts: list[Rollout]) -> list[str]:
        return rolled


class DRMatched(DomainRandomization):
    """``dr-matched``: ``dr`` given as many environment steps as another run (``match_run``, e.g. ``ours`` of the
    same seed) spent in each iteration: what that run spent beyond this one's rollouts (F's diagnosis, G's
    rollout checks, scoring) becomes extra fine-tuning frames, so the two compare at equal environment steps."""

    name = "dr-matched"

    def finetune_frames(self, it: Iteration) -> int:
        spent = matched_steps(Path(it.cfg.match_run), it.t)
        return max(it.cfg.finetune_frames, spent - (it.state.env_steps - it.steps_before))


#: How long ``dr-matched`` waits for the matched run's iteration (an experiment runs the two side by side).
MATCH_WAIT_S = 6 * 3600.0


def matched_steps(run: Path, t: int, *, wait_s: float = MATCH_WAIT_S, poll_s: float = 10.0) -> int:
    """Environment steps the run in folder ``run`` spent in its iteration ``t``, waiting up to ``wait_s`` for it."""
    if not run.is_dir():
        raise ConfigError(f"match_run {run}: no such run folder; run the method it matches first (same seed)")
    deadline = time.monotonic() + wait_s
    while True:
        steps = {r.iteration: r.env_steps for r in read_iterations(run)}
        if t in steps and t - 1 in steps:
            return steps[t] - steps[t - 1]
        if time.monotonic() >= deadline:
            raise ConfigError(f"match_run {run}: iteration {t} did not finish within {wait_s:.0f} s; "
                              "finish that run, then resume this one")
        time.sleep(poll_s)


class SFL(Method):
    """``sfl``: Sampling For Learnability (Rutherford et al., 2024). Each iteration scores ``sfl_candidates`` times
    ``scenes_per_iteration`` fresh procedural houses by pi_t's learnability p(1-p) over ``score_rollouts``
    episodes each, and trains on the most learnable ``scenes_per_iteration`` (plus the replay mix)."""

    name = "sfl"

    def scenes_to_roll_out(self, it: Iteration) -> list[str]:
        return new_levels(it, it.cfg.sfl_candidates * it.cfg.scenes_per_iteration)

    def make_scenes(self, it: Iteration, rolled: list[str], rollouts: list[Rollout]) -> list[str]:
        scores = np.array([level_score(ro, "learnability") for ro in rollouts])
        best = np.argsort(-scores, kind="stable")[:it.cfg.scenes_per_iteration]
        return [rolled[i] for i in sorted(best.tolist())]


class EditingMethod(Method):
    """Edit each rolled-out scene into a child with ``edit_steps`` single-object edits of one generator."""

    generator: ClassVar[GeneratorKind]
    tag: ClassVar[str]
    """Letter in child names: ``house~t02a03`` is the child of iteration 2, job 3."""
    replaces_parents = True

    def make_scenes(self, it: Iteration, rolled: list[str], rollouts: list[Rollout]) -> list[str]:
        policy = needs_policy(self.generator)  # random edits ignore pi_t: no weights to pickle per job
        jobs = [GenerateJob(self.generator, it.store.house(name), name, it.cfg.edit_steps,
                            (it.cfg.seed, it.t, Stream.GENERATE + k), weights=it.weights if policy else None,
                            rollout=ro if policy else None, llm=it.cfg.llm, **(target_fields(it.cfg) if policy else {}),
                            appearance=0.0 if policy else appearance_share(it.cfg))
                for k, (name, ro) in enumerate(zip(rolled, rollouts, strict=True))]
        new = []
        for k, (job, made) in enumerate(zip(jobs, it.executor.map(run_generate, jobs, desc="generation"), strict=True)):
            it.made.append((job.name, made))
            it.state.edits += made.edits
            it.state.env_steps += made.rollout_steps
            new.append(it.store.put(f"{job.name.split('~')[0]}~t{it.t:02d}{self.tag}{k:02d}", made.house))
            it.parents[new[-1]] = job.name
            if len(it.gallery) < it.cfg.gallery:
                it.gallery.append(gallery_item(it.run_dir, it.t, new[-1], job.house, made,
                                               made.before if made.before is not None else rollouts[k].trajectory))
        return new


class Oracle(DomainRandomization):
    """``oracle``: the lever test's positive control. Fresh houses every iteration from the held-out suites' own
    generator settings (alternately ``suite-large``'s 7-10 rooms and ``suite-clutter``'s cluttered 3-6 rooms) with
    new seeds, never the held-out houses themselves."""

    name = "oracle"

    def scenes_to_roll_out(self, it: Iteration) -> list[str]:
        return fresh_houses(it, it.cfg.scenes_per_iteration, oracle=True)


class Rearrange(DomainRandomization):
    """``rearrange``: the rearranged-homes lever test's ceiling. Every iteration the training homes rearranged anew
    by ``rearrange_house`` (the generator of the ``rearranged`` suites, with new seeds), never the suites' houses."""

    name = "rearrange"
    stream: ClassVar[Stream] = Stream.REARRANGE
    tag: ClassVar[str] = "ra"
    preset: ClassVar[str] = "pretrain-rearranged"
    """The preset whose generator settings the children take."""

    def child(self, house: House, seed: int) -> House:
        """One new version of a home."""
        return rearrange_house(house, seed, preset_spec(self.preset).config())

    def scenes_to_roll_out(self, it: Iteration) -> list[str]:
        pool, out = it.state.pool, []
        for k in range(it.cfg.scenes_per_iteration):
            n = it.state.generated
            home = pool[((it.t - 1) * it.cfg.scenes_per_iteration + k) % len(pool)]
            house = self.child(it.store.house(home), it.seed(self.stream, n) % 2**31)
            out.append(it.store.put(f"{home.split('~')[0]}~{self.tag}{n:04d}", house))
            it.state.generated += 1
        return out


class Swap(Rearrange):
    """``swap``: the homes' own variations. Every iteration the training homes (round robin) with each object's asset
    swapped for another of its type and split where one fits and the floor and wall materials drawn anew
    (``vary_house``, the ``pretrain-swapped`` preset's settings, new seeds): what N homes give without new layouts."""

    name = "swap"
    stream = Stream.SWAP
    tag = "sw"
    preset = "pretrain-swapped"

    def child(self, house: House, seed: int) -> House:
        return vary_house(house, seed, preset_spec(self.preset).config())


class RandomEdits(EditingMethod):
    """``random``: random single-object edits of the rolled-out scenes (open loop, same edit budget)."""

    name = "random"
    generator = "random"
    tag = "r"


class OursNoSelect(EditingMethod):
    """``ours-noselect``: the plain adaptation step (one episode for F, built-in G with pi_t) on the
    rolled-out scenes in round robin, no regret-based selection (the earlier ``ours``)."""

    name = "ours-noselect"
    generator = "builtin"
    tag = "a"


class PLR(Method):
    """``plr``: Robust PLR. Fresh houses are only scored by regret; training replays high-regret buffer levels."""

    name = "plr"

    def scenes_to_roll_out(self, it: Iteration) -> list[str]:
        if seeds_buffer(it):
            return list(it.state.pool)  # seed the buffer with the original training scenes
        return new_levels(it, it.cfg.scenes_per_iteration)

    def update_buffer(self, it: Iteration, rolled: list[str], rollouts: list[Rollout]) -> None:
        for name, ro in zip(rolled, rollouts, strict=True):
            it.buffer = lb.insert(it.buffer, it.buffer_cfg, name, level_score(ro, it.cfg.level_score), it.t,
                                  parent_id=it.parents.get(name))

    def train_on(self, it: Iteration, rolled: list[str], new: list[str]) -> list[str]:
        if it.replayed:
            return list(it.replayed)
        replay = lb.sample_replay(it.buffer, it.buffer_cfg, it.rng(Stream.REPLAY), it.t, k=it.cfg.scenes_per_iteration)
        it.buffer = lb.update_scores(it.buffer, list(replay), [it.buffer.scores[i] for i in replay], it.t)
        return [it.buffer.level_ids[i] for i in replay]


class ACCEL(PLR):
    """``accel``: replayed high-regret levels get random edits; the children and fresh houses are scored and inserted.

    Gradient steps go to the replayed parents (children and fresh houses were only scored, the
    generator's new levels of the UED loop); the first iteration seeds the buffer with the training
    scenes and trains on a replay of them.
    """

    name = "accel"

    def scenes_to_roll_out(self, it: Iteration) -> list[str]:
        if seeds_buffer(it):
            return list(it.state.pool)
        if it.buffer.size == 0:
            return new_levels(it, it.cfg.scenes_per_iteration)
        idx = lb.sample_replay(it.buffer, it.buffer_cfg, it.rng(Stream.ACCEL_REPLAY), it.t,
                               k=it.cfg.scenes_per_iteration)
        it.replayed = [it.buffer.level_ids[i] for i in idx]
        it.buffer = lb.update_scores(it.buffer, list(idx), [it.buffer.scores[i] for i in idx], it.t)
        plans = lb.select_parents(it.buffer, idx, it.rng(Stream.ACCEL_PARENTS))
        jobs = [GenerateJob("random", it.store.house(p.parent_id), p.parent_id, it.cfg.edit_steps, (p.seed,),
                            appearance=appearance_share(it.cfg))
                for p in plans]
        children = []
        for k, (plan, made) in enumerate(zip(plans, it.executor.map(run_generate, jobs, desc="ACCEL edits"),
                                             strict=True)):
            name = it.store.put(f"{plan.parent_id.split('~')[0]}~t{it.t:02d}c{k:02d}", made.house)
            it.state.edits += made.edits
            it.parents[name] = plan.parent_id
            children.append(name)
            if len(it.gallery) < it.cfg.gallery:
                it.gallery.append(gallery_item(it.run_dir, it.t, name, jobs[k].house, made, None))
        return children + new_levels(it, it.cfg.scenes_per_iteration)


class Ours(Method):
    """``ours``: regret-based selection (as PLR/ACCEL) plus F's multi-episode diagnosis and G aimed at its failure modes.

    A level buffer holds scenes scored by regret (expert success minus pi_t's). Each iteration
    ``scenes_per_iteration`` fresh procedural houses are scored by one episode and inserted (the
    UED loop's new levels; the first iteration also scores every training scene), then as many
    buffer scenes are picked (rank and staleness), each is diagnosed on ``diagnose_episodes`` hard
    episodes and adapted (:class:`GenerateJob`), the parent's score becomes its measured regret,
    and the child goes in scored by pi_t's regret on it. Fine-tuning uses the children plus
    high-regret buffer levels (``replay_fraction`` of the mix).
    """

    name = "ours"
    generator: ClassVar[GeneratorKind] = "failure-modes"
    tag: ClassVar[str] = "f"
    uniform: ClassVar[bool] = False
    """Pick scenes uniformly from the buffer instead of by regret (``ours-randomscene``)."""

    def scenes_to_roll_out(self, it: Iteration) -> list[str]:
        seed = list(it.state.pool) if seeds_buffer(it) else []  # t=1: score every training scene once
        return seed + new_levels(it, it.cfg.scenes_per_iteration)

    def update_buffer(self, it: Iteration, rolled: list[str], rollouts: list[Rollout]) -> None:
        for name, ro in zip(rolled, rollouts, strict=True):
            if it.buffer.index(name) is None:
                it.buffer = lb.insert(it.buffer, it.buffer_cfg, name, level_score(ro, it.cfg.level_score), it.t)

    def make_scenes(self, it: Iteration, rolled: list[str], rollouts: list[Rollout]) -> list[str]:
        parents = it.replayed = self._pick(it, it.cfg.scenes_per_iteration, Stream.REPLAY)
        jobs = [GenerateJob(self.generator, it.store.house(p), p, it.cfg.edit_steps,
                            (it.cfg.seed, it.t, Stream.GENERATE + k), weights=it.weights,
                            diagnose_episodes=it.cfg.diagnose_episodes, llm=it.cfg.llm,
                            relocate_targets=it.cfg.relocate_targets, door_edits=it.cfg.door_edits,
                            learned_scorer=it.cfg.learned_scorer,
                            **target_fields(it.cfg))
                for k, p in enumerate(parents)]
        children = []
        for k, (job, made) in enumerate(zip(jobs, it.executor.map(run_generate, jobs, desc="diagnosis and generation"),
                                            strict=True)):
            it.made.append((job.name, made))
            it.state.edits += made.edits
            it.state.env_steps += made.rollout_steps
            it.buffer = lb.insert(it.buffer, it.buffer_cfg, job.name,
                                  diagnosed_score(made.success_before, made.regret_before, it.cfg.level_score), it.t)
            if not made.valid or made.edits == 0:
                continue
            focus = (made.before.target_type,) if it.cfg.focus_training and made.before is not None else ()
            child = it.store.put(f"{job.name.split('~')[0]}~t{it.t:02d}{self.tag}{k:02d}", made.house, focus)
            it.buffer = lb.insert(it.buffer, it.buffer_cfg, child,
                                  diagnosed_score(made.success_after, made.regret_after, it.cfg.level_score), it.t,
                                  parent_id=job.name)
            it.parents[child] = job.name
            children.append(child)
            if len(it.gallery) < it.cfg.gallery:
                it.gallery.append(gallery_item(it.run_dir, it.t, child, job.house, made, made.before))
        return children

    def train_on(self, it: Iteration, rolled: list[str], new: list[str]) -> list[str]:
        n_replay = int(round(max(len(new), 1) * it.cfg.replay_fraction / (1.0 - it.cfg.replay_fraction)))
        replay = self._pick(it, n_replay, Stream.ARCHIVE_MIX) if n_replay else []
        it.state.archive = it.state.archive + [x for x in new if x not in it.state.archive]
        return list(dict.fromkeys(new + replay)) or list(it.state.pool)

    def _pick(self, it: Iteration, k: int, stream: Stream) -> list[str]:
        """``k`` distinct buffer scenes: by rank and staleness of their regret, or uniformly."""
        n = it.buffer.size
        p = None if self.uniform else lb.replay_distribution(it.buffer, it.buffer_cfg, it.t)
        idx = it.rng(stream).choice(n, size=min(k, n), replace=False, p=p)
        return [it.buffer.level_ids[i] for i in sorted(idx.tolist())]


class OursRandomScene(Ours):
    """``ours-randomscene``: F's diagnosis and the failure-mode G on scenes picked uniformly from the buffer."""

    name = "ours-randomscene"
    uniform = True


class OursNoF(Ours):
    """``ours-nof``: regret-based selection, G with generic objectives and no F analysis (G on regret alone)."""

    name = "ours-nof"
    generator = "regret-only"
    tag = "n"


class OursDR(Ours):
    """``ours-dr``: ``ours``' selection, diagnosis and G, trained on the children plus this iteration's fresh houses.

    ``ours`` replays buffer levels, whose children share few layouts (about 38 distinct houses
    over 4 iterations against DR's 85 in the runs of commit `5bd92a3`); this variant keeps DR's stream of
    new layouts and adds the adapted high-regret scenes to it instead of the buffer replay.
    """

    name = "ours-dr"
    tag = "d"

    def train_on(self, it: Iteration, rolled: list[str], new: list[str]) -> list[str]:
        fresh = [x for x in rolled if x not in it.state.pool]  # t=1 also scores the training scenes
        it.state.archive = it.state.archive + [x for x in new + fresh if x not in it.state.archive]
        return list(dict.fromkeys(new + fresh)) or list(it.state.pool)


class OursLearned(Ours):
    """``ours-learned``: ``ours`` with the learned G (the shipped scorer) instead of the failure-mode G."""

    name = "ours-learned"
    generator = "learned"
    tag = "g"


class OursLLM(Ours):
    """``ours-llm``: ``ours`` with LLM-backed F and G (needs the config's ``llm`` section)."""

    name = "ours-llm"
    generator = "llm"
    tag = "l"
    uses_llm = True


LEVEL_SCORES = ("regret", "learnability", "explorer_regret")
"""Scene scores of the level buffer (``LoopConfig.level_score``); ``sfl`` always uses learnability."""


def learnability(p: float) -> float:
    """SFL's learnability p(1-p) of a success rate p: highest where pi_t succeeds half the time."""
    return p * (1.0 - p)


def level_score(ro: Rollout, kind: str = "regret") -> float:
    """A scene's score from pi_t's ``score_rollouts`` episodes in it (see :data:`LEVEL_SCORES`).

    ``regret``: mean over episodes of the expert's success minus pi_t's (0 where the expert fails);
    ``learnability``: p(1-p); ``explorer_regret``: the same regret with the map explorer, which searches
    with what pi_t could know, as the reference.
    """
    agent = [float(r.success) for r in ro.results]
    if kind == "learnability":
        return learnability(ro.success_rate)
    if kind == "explorer_regret":
        if not ro.explorer_successes:
            raise ValueError("explorer_regret needs rollouts with the explorer (rollout_scenes(..., explorer=True))")
        return lb.success_regret(agent, [float(x) for x in ro.explorer_successes])
    return lb.regret_score(agent, [r.spl for r in ro.results], [float(x) for x in ro.expert_successes])


def diagnosed_score(success: float | None, regret: float | None, kind: str) -> float:
    """The score of a scene ``ours`` diagnosed: learnability of its diagnosis success rate, else its regret
    (the diagnosis runs the expert, not the explorer, so ``explorer_regret`` falls back to regret here)."""
    if kind == "learnability" and success is not None:
        return learnability(success)
    return float(regret or 0.0)


def seeds_buffer(it: Iteration) -> bool:
    """Whether this iteration scores the training scenes into the (still empty) level buffer."""
    return it.buffer.size == 0 and it.cfg.seed_buffer


ORACLE_PRESETS = ("suite-large", "suite-clutter")
"""Whose generator settings ``oracle`` draws from, in turn."""


def fresh_houses(it: Iteration, k: int, *, oracle: bool = False) -> list[str]:
    """``k`` new procedural houses (domain randomization), named ``drNNNN`` and stored; with ``oracle``, from the
    held-out suites' settings (``ORACLE_PRESETS`` in turn), named ``orNNNN``."""
    out = []
    for _ in range(k):
        n = it.state.generated
        if oracle:
            seed = it.seed(Stream.ORACLE_HOUSES, n) % 2**31
            house = generate_house(seed, preset_spec(ORACLE_PRESETS[n % len(ORACLE_PRESETS)]).config())
            out.append(it.store.put(f"or{n:04d}", house))
        else:
            out.append(it.store.put(f"dr{n:04d}", generate_house(it.seed(Stream.FRESH_HOUSES, n) % 2**31)))
        it.state.generated += 1
    return out


def new_levels(it: Iteration, k: int) -> list[str]:
    """``k`` new levels of the UED loop (sfl, plr, accel, ours): fresh procedural houses, or with ``grounded`` the
    training homes after random edits (:func:`grounded_levels`)."""
    return grounded_levels(it, k) if it.cfg.grounded else fresh_houses(it, k)


def grounded_levels(it: Iteration, k: int) -> list[str]:
    """``k`` levels made from the training homes (round robin over the run): each home after ``edit_steps`` random
    edits (with ``appearance_edits``, asset swaps and material changes among them), named ``HOME~gNNNN``."""
    pool, homes = it.state.pool, []
    for _ in range(k):
        homes.append((pool[it.state.generated % len(pool)], it.state.generated))
        it.state.generated += 1
    jobs = [GenerateJob("random", it.store.house(home), home, it.cfg.edit_steps,
                        (it.cfg.seed, it.t, int(Stream.GROUNDED), n), appearance=appearance_share(it.cfg))
            for home, n in homes]
    out = []
    for (home, n), made in zip(homes, it.executor.map(run_generate, jobs, desc="levels from the homes"), strict=True):
        it.state.edits += made.edits
        name = it.store.put(f"{home.split('~')[0]}~g{n:04d}", made.house)
        it.parents[name] = home
        out.append(name)
    return out


APPEARANCE_SHARE = 0.5
"""Share of random edits that are appearance edits with ``appearance_edits``."""


def appearance_share(cfg: LoopConfig) -> float:
    """The ``appearance`` of the run's random-edit jobs: APPEARANCE_SHARE with ``appearance_edits``, else 0."""
    return APPEARANCE_SHARE if cfg.appearance_edits else 0.0


#: Every method by name; add a method with one class and one line here.
METHODS: dict[str, type[Method]] = {m.name: m for m in (NoNewScenes, RandomEdits, DomainRandomization, DRMatched,
                                                        SFL, Oracle, Rearrange, Swap, PLR, ACCEL, Ours, OursNoSelect,
                                                        OursRandomScene, OursNoF, OursDR, OursLearned, OursLLM)}
#: The methods whose new scenes come from G's adaptation step (they take ``LoopConfig.target_success``).
ADAPTING_METHODS: tuple[str, ...] = tuple(n for n, m in METHODS.items() if getattr(m, "generator", "random") != "random")


def target_fields(cfg: LoopConfig) -> dict[str, Any]:
    """The GenerateJob fields of difficulty on request (none when ``target_success`` is off)."""
    if cfg.target_success is None:
        return {}
    return {"target_success": cfg.target_success, "target_tolerance": cfg.target_tolerance,
            "target_episodes": cfg.target_episodes, "target_choices": cfg.target_choices,
            "target_draws": cfg.target_draws, "target_stop_gap": cfg.target_stop_gap}
