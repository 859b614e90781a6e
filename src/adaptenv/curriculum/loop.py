"""The closed loop, t = 1..T: roll pi_t out, make e_{t+1}, fine-tune, measure held-out.

One function, :func:`run_loop`, reads top to bottom (CleanRL style) and runs any method of
:data:`~adaptenv.curriculum.methods.METHODS` under the same explicit budgets; what differs between
methods lives in their strategy classes (:mod:`adaptenv.curriculum.methods`):

- ``none``: no new scenes; fine-tune on the original training scenes.
- ``random``: ``edit_steps`` random single-object edits of each rolled-out training scene.
- ``dr``: domain randomization, fresh procedural houses.
- ``dr-matched``: ``dr`` with as many environment steps per iteration as another run (``match_run``).
- ``sfl``: Sampling For Learnability; scores fresh procedural houses by p(1-p) and trains on the most learnable.
- ``plr``: Robust PLR; fresh procedural houses are only scored (regret against the expert's
  measured success), gradient steps are taken on levels replayed from a prioritized buffer.
- ``accel``: ACCEL; replayed high-regret levels get ``edit_steps`` random edits each, the children
  and fresh procedural houses are scored and inserted; gradient steps on replayed levels only.
- ``ours``: regret-based scene selection (a level buffer fed with fresh procedural houses, as
  PLR/ACCEL) plus the paper's adaptation step (:func:`~adaptenv.adapt.step.adapt_scene`) with F's
  diagnosis over ``diagnose_episodes`` hard episodes and G aimed at the dominant failure modes;
  ablations ``ours-noselect`` (the plain
  step, one episode, round robin), ``ours-randomscene`` (uniform scene choice), ``ours-nof``
  (G on regret alone, no F analysis); variant ``ours-dr`` (trained on the children plus DR's
  fresh houses instead of the buffer replay), ``ours-learned`` (the learned G, see
  :mod:`adaptenv.adapt.generators.learned`, instead of the failure-mode G).
- ``ours-llm``: the same with LLM F and G (needs an LLM config).

Per iteration every method plays ``score_rollouts`` episodes in each scene it rolls out and spends
the same number of fine-tuning frames (hence the same gradient updates); the editing methods make
``edit_steps`` edits per adapted scene. Environment steps (rollouts, F's diagnosis episodes, G's
rollout checks and fine-tuning frames), updates and edits are counted and logged.
Every iteration is checkpointed atomically; ``resume=True`` continues from the last finished one
and ends with the same results as an uninterrupted run (all randomness derives from (seed, t)).
"""

from __future__ import annotations

import json
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from adaptenv.adapt.llm.accounting import check_llm_section, run_changes, scenes_usage
from adaptenv.adapt.target import check_target
from adaptenv.agents.checkpoint import load_checkpoint, load_tensors, save_checkpoint
from adaptenv.agents.config import FinetuneConfig
from adaptenv.agents.evaluate import EpisodeResult, EvalReport, mean_se, summarize, write_report
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.network import NavNet, NeuralPolicy, torch_threads
from adaptenv.agents.ppo import learner_problem
from adaptenv.agents.registry import resolve_policy, weights_record
from adaptenv.agents.teachers import TEACHERS
from adaptenv.agents.train import check_precision, finetune
from adaptenv.configfile import STRICT, parse_config, printable, read_json
from adaptenv.curriculum import buffer as lb
from adaptenv.curriculum.executor import Executor, InProcessExecutor
from adaptenv.curriculum.jobs import (
    PolicyWeights,
    Rollout,
    RolloutJob,
    eval_jobs,
    heldout_set,
    run_eval,
    run_rollout,
    skipped_houses,
)
from adaptenv.curriculum.llm_usage import budget_left, iteration_lines, record_iteration
from adaptenv.curriculum.methods import ADAPTING_METHODS, LEVEL_SCORES, METHODS, Iteration, Stream
from adaptenv.curriculum.records import (
    HELDOUT_DIR,
    ITERATIONS,
    STATE,
    IterationRecord,
    RunInfo,
    SceneStore,
    SetMetrics,
    atomic_write_text,
    iteration_dir,
    read_iterations,
    write_iterations,
)
from adaptenv.errors import ConfigError
from adaptenv.limits import check_float, check_seed
from adaptenv.render.topdown import render_house

#: The fix a corrupt state.json's errors suggest.
STATE_FIX = "the file is damaged: restore it, or start the run again in a new folder"


@dataclass
class LoopConfig:
    """Settings of one closed-loop run (one method, one seed); saved as run.json."""

    method: str = "ours"
    """One of none, random, dr, dr-matched, sfl, plr, accel, ours, ours-noselect, ours-randomscene, ours-nof, ours-dr, ours-learned, ours-llm."""
    policy: str = "pretrained"
    """Starting policy pi_0: pretrained or a checkpoint path (it must be a neural policy to fine-tune)."""
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
    finetune_algo: str = "dagger"
    """How pi_t is fine-tuned: dagger (imitation of finetune_teacher) or ppo (anchored PPO on the simulator's
    reward, docs/agent.md)."""
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
    finetune_min_start: float = 0.0
    """Fine-tuning episodes start at least this geodesic distance (m) from the target where a house allows
    (0: uniform starts; the long suites use 6 m)."""
    finetune_precision: str = "fp32"
    """Arithmetic of fine-tuning's gradient steps: fp32, or bf16 autocast (on CPUs with AVX512_BF16 DAgger's steps
    about 2.4x faster and PPO end to end 1.4x, slower elsewhere; docs/BENCHMARKS.md)."""
    finetune_beta: float = FinetuneConfig.beta
    """Probability that the teacher's action is executed while fine-tuning (DAgger's beta, constant)."""
    finetune_max_steps: int = FinetuneConfig.max_episode_steps
    """Episode cap of fine-tuning's episodes (the map-reading agent trains to the evaluation's 600)."""
    finetune_kl_coef: float = 0.0
    """ppo: weight of the KL anchor to pi_t (0.3 in the PPO runs of docs/agent.md)."""
    finetune_explore_bonus: float = 0.0
    """ppo: reward per newly seen map cell (0.002 in the PPO runs of docs/agent.md)."""
    finetune_bc_coef: float = 0.0
    """ppo: weight of a cross-entropy to finetune_teacher's labels of the states PPO visits (an imitation term;
    0: off)."""
    finetune_freeze_encoder: bool = False
    """ppo: train pi_t's memory and heads only, its observation encoder fixed at pi_0's weights (faster updates;
    docs/BENCHMARKS.md)."""
    finetune_keep_learner: bool = True
    """ppo: each iteration continues the last one's value head and Adam moments (one PPO run across the loop, as
    UED methods train); false starts every iteration with a fresh critic and a value warm-up."""
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
    target_success: float | None = None
    """Difficulty on request: each adapted scene is edited until pi_t's success on target_episodes fixed episodes is
    within target_tolerance of this rate P (0 < P < 1; edit_steps is the edit budget,
    :func:`~adaptenv.adapt.target.adapt_to_success`) instead of being made as hard as G can; null: off. Only the
    methods that adapt scenes with G (ADAPTING_METHODS) take it."""
    target_tolerance: float = 0.10
    """With target_success: stop editing a scene once |success - P| is at most this."""
    target_episodes: int = 20
    """With target_success: episodes pi_t's success on a scene is measured on (the same after every edit)."""

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
        if self.finetune_algo == "dagger" and (self.finetune_kl_coef or self.finetune_explore_bonus
                                               or self.finetune_freeze_encoder or self.finetune_bc_coef):
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
        if self.method == "ours-llm" and not self.llm:
            raise ConfigError(f"{source}: method ours-llm needs an llm section (provider, model, base_url); "
                              "see docs/llm.md")
        check_llm_section(self.llm, source)
        if self.target_success is not None:
            check_target(self.target_success, self.target_tolerance, what=f"{source}: target_success",
                         tol_what=f"{source}: target_tolerance")
            if self.method not in ADAPTING_METHODS:
                raise ConfigError(f"{source}: target_success applies to the methods that adapt scenes with G "
                                  f"({', '.join(ADAPTING_METHODS)}), not {self.method}; pick one or drop target_success")
            if self.target_episodes < 1:
                raise ConfigError(f"{source}: target_episodes must be at least 1, got {self.target_episodes}")
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


def set_metrics(results: list[EpisodeResult]) -> SetMetrics:
    """A set's figures (success, SPL, collisions, with standard errors) from its episodes' results."""
    s, s_se = mean_se([float(r.success) for r in results])
    spl, spl_se = mean_se([r.spl for r in results])
    col, _ = mean_se([float(r.collisions) for r in results])
    return SetMetrics(success=s, spl=spl, collisions=col, episodes=len(results), success_se=s_se, spl_se=spl_se)


def rollout_scenes(store: SceneStore, names: list[str], weights: PolicyWeights, seed: int, executor: Executor,
                   *, episodes: int = 1, explorer: bool = False) -> list[Rollout]:
    """``episodes`` episodes of the policy (and of the expert, and the explorer if asked) in each named scene."""
    jobs = [RolloutJob(weights, store.house(n), n, int(np.random.SeedSequence([seed, i]).generate_state(1)[0]),
                       episodes, explorer)
            for i, n in enumerate(names)]
    return executor.map(run_rollout, jobs, desc="rollouts")


def evaluate_sets(weights: PolicyWeights, specs: dict[str, str], episodes: int, seed: int, executor: Executor,
                  out_dir: Path | None = None, label: str = "pi") -> dict[str, SetMetrics]:
    """Held-out figures of a policy on each set, on the same episodes every call (paired comparisons).

    With ``out_dir``, each set's results go to ``out_dir/<set>/`` in ``adaptenv evaluate``'s layout
    (summary, per-episode and per-house tables, renders of failed episodes), which the report reads.
    """
    tagged = eval_jobs(weights, specs, episodes, seed)
    chunks = executor.map(run_eval, [job for _, job in tagged], desc="held-out evaluation")
    metrics = {}
    for name, spec in specs.items():
        results = [r for (n, _), (rs, _) in zip(tagged, chunks, strict=True) if n == name for r in rs]
        metrics[name] = set_metrics(results)
        if out_dir is not None:
            recordings = {k: v for (n, _), (_, recs) in zip(tagged, chunks, strict=True) if n == name
                          for k, v in recs.items()}
            report = EvalReport(label, spec, seed, summarize(results), results, recordings)
            write_report(report, heldout_set(spec), out_dir / name, render=render_house)
    return metrics


def finetune_config(cfg: LoopConfig, end_threshold: float) -> FinetuneConfig:
    """The loop's fine-tuning recipe (identical for every method): DAgger at ``finetune_beta`` with
    ``finetune_teacher``'s labels, or anchored PPO; episodes start ``finetune_min_start`` or more from the target."""
    return FinetuneConfig(algo=cfg.finetune_algo, kl_coef=cfg.finetune_kl_coef,
                          explore_bonus=cfg.finetune_explore_bonus, freeze_encoder=cfg.finetune_freeze_encoder,
                          bc_coef=cfg.finetune_bc_coef, frames=cfg.finetune_frames, num_envs=cfg.finetune_envs, learning_rate=cfg.finetune_lr,
                          end_threshold=end_threshold, teacher=cfg.finetune_teacher,
                          min_start_distance=cfg.finetune_min_start, precision=cfg.finetune_precision,
                          beta=cfg.finetune_beta, max_episode_steps=cfg.finetune_max_steps)


def run_loop(cfg: LoopConfig, run_dir: str | Path, *, resume: bool = False, executor: Executor | None = None,
             progress: Callable[[str], None] | None = None, command: str = "") -> list[IterationRecord]:
    """Run (or resume) one method for ``cfg.iterations`` iterations; returns every iteration's record.

    Rollouts, held-out evaluation and scene generation go through ``executor`` (in process when
    None; see :mod:`adaptenv.curriculum.executor`); every executor gives the same results.
    ``progress(text)`` is called with one line per finished stage. In-process work runs on one torch thread
    (rollouts, G's checks and evaluations are small batches; fine-tuning sets its own), then the caller's is back.
    """
    with torch_threads(1):
        return _run_loop(cfg, run_dir, resume, executor, progress, command)


def _pi0_weights(cfg: LoopConfig, run_dir: Path, *, fresh: bool) -> dict[str, str] | None:
    """pi_0's name, file and sha256: read from ``cfg.policy`` when the run starts, kept from run.json on resume."""
    if not fresh and (run_dir / "run.json").is_file():
        try:
            return RunInfo.model_validate_json((run_dir / "run.json").read_text(encoding="utf-8")).weights
        except ValueError:
            pass
    return weights_record(cfg.policy)


def _run_loop(cfg: LoopConfig, run_dir: str | Path, resume: bool, executor: Executor | None,
              progress: Callable[[str], None] | None, command: str) -> list[IterationRecord]:
    cfg.check()
    run_dir = Path(run_dir)
    say = progress or (lambda text: None)
    state, records, command = _open_run(cfg, run_dir, resume, command)
    skipped = skipped_houses([cfg.houses, *cfg.heldout.values()])
    weights = _pi0_weights(cfg, run_dir, fresh=state.iteration == 0 and not records)
    atomic_write_text(run_dir / "run.json", RunInfo(method=cfg.method, seed=cfg.seed, config=asdict(cfg), command=command,
                                                    skipped_houses=skipped, weights=weights).model_dump_json(indent=1))
    store = SceneStore(run_dir / "scenes")
    ex = executor if executor is not None else InProcessExecutor()
    method = METHODS[cfg.method]()
    bcfg = lb.LevelBufferConfig(capacity=cfg.buffer_capacity, min_fill=0.0, replay_prob=1.0).check()

    if state.iteration == 0 and not records:
        base = load_house_set(cfg.houses)
        state.pool = [store.put(n, h) for n, h in zip(base.names, base.houses, strict=True)]
        state.archive = list(state.pool)
        policy = resolve_policy(cfg.policy, seed=cfg.seed)
        if not isinstance(policy, NeuralPolicy):
            raise ConfigError(f"--policy {cfg.policy!r} is not a neural policy; the loop fine-tunes, so pass "
                              "pretrained or a checkpoint path")
        save_checkpoint(iteration_dir(run_dir, 0) / "policy.pt", policy.net,
                        {"iteration": 0, "end_threshold": policy.end_threshold})
        say("evaluating pi_0 on the held-out sets")
        records = [IterationRecord(iteration=0, env_steps=0, grad_updates=0, edits=0,
                                   heldout=evaluate_sets(PolicyWeights.of(policy), cfg.heldout,
                                                         cfg.heldout_episodes, cfg.seed, ex))]
        _checkpoint(run_dir, cfg, state, records)

    for t in range(state.iteration + 1, cfg.iterations + 1):
        if why := budget_left(run_dir, cfg.llm):  # stop cleanly; raise the budget and --resume to go on
            say(f"stopping before t={t}: {why}")
            break
        start = time.perf_counter()
        pi_t = load_checkpoint(iteration_dir(run_dir, t - 1) / "policy.pt").policy()
        shutil.rmtree(iteration_dir(run_dir, t), ignore_errors=True)  # a killed attempt at t starts over
        it = Iteration(t=t, cfg=cfg, state=state, store=store, executor=ex, run_dir=run_dir,
                       buffer=lb.LevelBufferState.from_dict(state.buffer) if state.buffer else lb.empty_state(),
                       buffer_cfg=bcfg, weights=PolicyWeights.of(pi_t), steps_before=state.env_steps)
        edits_before = state.edits
        stages = StageClock()

        # 1. roll pi_t out in the scenes this method looks at (analysis or scoring)
        rolled = method.scenes_to_roll_out(it)
        say(f"t={t}: rolling out pi_{t - 1} in {len(rolled)} scenes")
        rollouts = rollout_scenes(store, rolled, it.weights, it.seed(Stream.ROLLOUT_EPISODES), ex,
                                  episodes=cfg.score_rollouts, explorer=cfg.level_score == "explorer_regret")
        stages.lap("rollouts")
        state.env_steps += sum(ro.steps for ro in rollouts)
        train_metrics = set_metrics([r for ro in rollouts for r in ro.results])

        # 2. the method's buffer and its new training scenes e_{t+1}
        method.update_buffer(it, rolled, rollouts)
        new = method.make_scenes(it, rolled, rollouts)
        train_names = method.train_on(it, rolled, new)
        stages.lap("scenes")
        llm_usage = None
        if method.uses_llm:
            made = [m for _, m in it.made]
            llm_usage = record_iteration(run_dir, t, scenes_usage(made), cfg.llm).iterations[str(t)]
            for line in iteration_lines(t, [n for n, _ in it.made], made, run_dir, cfg.llm):
                say(line)

        # 3. fine-tune pi on the chosen scenes (DAgger with the teacher's labels, or anchored PPO)
        ft = replace(finetune_config(cfg, pi_t.end_threshold), frames=method.finetune_frames(it))
        say(f"t={t}: fine-tuning on {len(train_names)} scenes ({ft.frames} frames)")
        tuned = finetune(pi_t.net, [store.world(x) for x in train_names], ft, seed=it.seed(Stream.FINETUNE) % 2**31,
                         learner=_load_learner(iteration_dir(run_dir, t - 1)) if cfg.finetune_keep_learner else None)
        net, card = tuned.net, tuned.card
        state.env_steps += int(card["frames"])
        state.grad_updates += int(card["updates"])
        pi_next = NeuralPolicy(net, end_threshold=pi_t.end_threshold)
        stages.lap("finetune")
        save_checkpoint(iteration_dir(run_dir, t) / "policy.pt", net,
                        {"iteration": t, "method": cfg.method, "end_threshold": pi_next.end_threshold})
        if tuned.learner is not None and cfg.finetune_keep_learner:
            torch.save(tuned.learner, iteration_dir(run_dir, t) / LEARNER_FILE)

        # 4. held-out evaluation of pi_{t+1}
        say(f"t={t}: evaluating on the held-out sets")
        heldout = evaluate_sets(PolicyWeights.of(pi_next), cfg.heldout, cfg.heldout_episodes, cfg.seed, ex,
                                out_dir=iteration_dir(run_dir, t) / HELDOUT_DIR, label=f"pi_{t}")
        stages.lap("evaluate")
        state.buffer = it.buffer.to_dict() if it.buffer.size else None
        state.iteration = t
        records.append(IterationRecord(iteration=t, env_steps=state.env_steps, grad_updates=state.grad_updates,
                                       edits=state.edits, train=train_metrics, heldout=heldout, gallery=it.gallery,
                                       wall_time_s=round(time.perf_counter() - start, 2),
                                       stage_seconds=stages.seconds, llm_usage=llm_usage))
        (iteration_dir(run_dir, t) / "scenes.json").write_text(json.dumps(
            {"rolled_out": rolled, "replayed": it.replayed, "trained_on": train_names,
             "edits_this_iteration": state.edits - edits_before, "parents": it.parents}),
            encoding="utf-8")
        _checkpoint(run_dir, cfg, state, records)
    return records


#: PPO's value head and optimizer state after an iteration's fine-tuning (the next iteration continues from it).
LEARNER_FILE = "learner.pt"


def _load_learner(folder: Path, net: NavNet | None = None, freeze_encoder: bool = False) -> dict[str, Any] | None:
    """The learner state an iteration saved, or None (the first iteration, DAgger, or a run made without it); one
    ConfigError when it is not one (never code: tensors only), or, given the iteration's ``net``, does not fit it."""
    path = folder / LEARNER_FILE
    if not path.is_file():
        return None
    try:
        learner = load_tensors(path)
    except Exception as exc:  # torch raises many types for corrupt or foreign files
        raise ConfigError(f"{path}: not a learner state the loop wrote ({type(exc).__name__}); {STATE_FIX}") from None
    if net is not None and (why := learner_problem(learner, net, freeze_encoder)) is not None:
        raise ConfigError(f"{path}: {why}; {STATE_FIX}")
    return learner


def check_resume_files(cfg: LoopConfig, run_dir: Path, state: LoopState, records: list[IterationRecord]) -> None:
    """Before any work on --resume: the state must fit its run (iteration in range, one record per finished
    iteration, no negative counter) and the last policy and learner state must load, each failure one line."""
    path = run_dir / STATE
    if not 0 <= state.iteration <= cfg.iterations:
        raise ConfigError(f"{path}: state.iteration {state.iteration} lies outside 0 .. {cfg.iterations} "
                          f"(--iterations); {STATE_FIX}")
    if len(records) != state.iteration + 1 and (state.iteration or records):
        raise ConfigError(f"{path}: state.iteration {state.iteration} but {run_dir / ITERATIONS} records "
                          f"{len(records)} iterations; {STATE_FIX}")
    counts = {"env_steps": state.env_steps, "grad_updates": state.grad_updates, "edits": state.edits,
              "generated": state.generated}
    if (bad := next((k for k, v in counts.items() if v < 0), None)) is not None:
        raise ConfigError(f"{path}: state.{bad} is negative ({counts[bad]}); {STATE_FIX}")
    if (state.iteration == 0 and not records) or state.iteration >= cfg.iterations:
        return  # nothing to continue from, or nothing left to do (a packed copy holds no policies)
    policy = iteration_dir(run_dir, state.iteration) / "policy.pt"
    net = load_checkpoint(policy).net
    if cfg.finetune_algo == "ppo" and cfg.finetune_keep_learner:
        _load_learner(iteration_dir(run_dir, state.iteration), net, cfg.finetune_freeze_encoder)


class StageClock:
    """Wall seconds per named stage of one iteration (``lap(name)`` closes the stage that just ended)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._last = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.seconds[name] = round(now - self._last, 2)
        self._last = now


def _moved_match_run(saved: dict[str, Any], cfg: LoopConfig) -> dict[str, str]:
    """``match_run`` as now when the saved one names the same run (method and seed folders) in an experiment folder
    since moved or copied, so a packed copy resumes; otherwise nothing (a real change is then reported)."""
    old = saved.get("match_run") or ""
    if old and cfg.match_run and Path(old).parts[-2:] == Path(cfg.match_run).parts[-2:]:
        return {"match_run": cfg.match_run}
    return {}


def _open_run(cfg: LoopConfig, run_dir: Path, resume: bool, command: str
              ) -> tuple[LoopState, list[IterationRecord], str]:
    """The state, records and command to continue from: a resumed run's, or a fresh run's in an empty folder."""
    state_path = run_dir / STATE
    if resume and state_path.is_file():
        saved = read_json(state_path, "loop state (written by the loop)")
        if not isinstance(saved, dict) or not isinstance(saved.get("config"), dict):
            raise ConfigError(f"{state_path}: expected {{\"config\": ..., \"state\": ...}} as the loop writes it; "
                              f"{STATE_FIX}")
        old = saved["config"]  # a field added to LoopConfig since the run started counts as its default
        changed = run_changes({**asdict(LoopConfig()), **old, **_moved_match_run(old, cfg)}, asdict(cfg))
        if changed:
            raise ConfigError(f"{run_dir}: --resume with other settings than the interrupted run: {', '.join(map(printable, changed))}; "
                              "pass the same options (its run.json lists them) or a new output folder")
        state = parse_config(LoopState, saved.get("state"), str(state_path), prefix="state", fix=STATE_FIX)
        if state.buffer:
            lb.LevelBufferState.from_dict(state.buffer, f"{state_path}: state.buffer")
        records = read_iterations(run_dir)[: state.iteration + 1]
        check_resume_files(cfg, run_dir, state, records)
        info = run_dir / "run.json"
        if info.is_file():  # keep the command that started the run
            try:
                command = RunInfo.model_validate_json(info.read_bytes()).command or command
            except (OSError, ValueError) as exc:  # pydantic's ValidationError is a ValueError
                raise ConfigError(f"{info}: not the run.json the loop wrote ({type(exc).__name__}); {STATE_FIX}") from None
        return state, records, command
    if run_dir.exists() and any(run_dir.iterdir()) and not resume:
        raise ConfigError(f"{run_dir}: the output folder is not empty; pass --resume to continue it or "
                          "choose a new folder")
    run_dir.mkdir(parents=True, exist_ok=True)
    return LoopState(), [], command


def _checkpoint(run_dir: Path, cfg: LoopConfig, state: LoopState, records: list[IterationRecord]) -> None:
    """Write the iteration log, then the resume state (last, atomically)."""
    write_iterations(run_dir, records)
    atomic_write_text(run_dir / STATE, json.dumps({"config": asdict(cfg), "state": asdict(state)}, indent=1))
