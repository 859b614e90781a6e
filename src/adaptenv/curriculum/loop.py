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
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

from adaptenv.adapt.llm.accounting import run_changes, scenes_usage
from adaptenv.agents.checkpoint import (
    atomic_torch_save,
    load_checkpoint,
    load_tensors,
    save_checkpoint,
)
from adaptenv.agents.config import FinetuneConfig
from adaptenv.agents.evaluate import EpisodeResult, EvalReport, mean_se, summarize, write_report
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.network import (
    NavNet,
    NeuralPolicy,
    resolve_precision,
    same_arithmetic,
    torch_threads,
)
from adaptenv.agents.ppo import learner_problem
from adaptenv.agents.registry import resolve_policy, weights_record
from adaptenv.agents.train import finetune
from adaptenv.configfile import parse_config, printable, read_json
from adaptenv.curriculum import buffer as lb
from adaptenv.curriculum.executor import Executor, InProcessExecutor
from adaptenv.curriculum.jobs import (
    PolicyWeights,
    Rollout,
    RolloutJob,
    eval_jobs,
    generation_line,
    heldout_set,
    run_eval,
    run_rollout,
    skipped_houses,
)
from adaptenv.curriculum.llm_usage import budget_left, iteration_lines, record_iteration
from adaptenv.curriculum.methods import (
    METHODS,
    Iteration,
    LoopConfig,
    LoopState,
    Stream,
)
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
from adaptenv.files import BOOKKEEPING
from adaptenv.limits import STATE_BYTES
from adaptenv.render.topdown import render_house

#: The fix a corrupt state.json's errors suggest.
STATE_FIX = "the file is damaged: restore it, or start the run again in a new folder"


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
    precision = resolve_precision(cfg.finetune_precision, "--finetune-precision")
    atomic_write_text(run_dir / "run.json", RunInfo(method=cfg.method, seed=cfg.seed, config=asdict(cfg), command=command,
                                                    skipped_houses=skipped, weights=weights,
                                                    finetune_precision=precision).model_dump_json(indent=1))
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
        made_line = generation_line([m for _, m in it.made], cfg.edit_steps) if it.made else ""
        say(f"t={t}: {made_line or f'{cfg.method} makes no edits'} ({len(new)} new scene{'s' * (len(new) != 1)}, "
            f"{stages.seconds['scenes']:.0f} s)")
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
            atomic_torch_save(tuned.learner, iteration_dir(run_dir, t) / LEARNER_FILE)

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
        atomic_write_text(iteration_dir(run_dir, t) / "scenes.json", json.dumps(
            {"rolled_out": rolled, "replayed": it.replayed, "trained_on": train_names,
             "edits_this_iteration": state.edits - edits_before, "parents": it.parents,
             "edits_requested": cfg.edit_steps * len(it.made), "generation": made_line}))
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


def _same_precision(saved: dict[str, Any], cfg: LoopConfig) -> dict[str, str]:
    """``finetune_precision`` as now when the saved one computes alike on this CPU (fp32 saved, auto meaning fp32)."""
    old = saved.get("finetune_precision", LoopConfig.finetune_precision)
    return {"finetune_precision": cfg.finetune_precision} if same_arithmetic(old, cfg.finetune_precision) else {}


def _open_run(cfg: LoopConfig, run_dir: Path, resume: bool, command: str
              ) -> tuple[LoopState, list[IterationRecord], str]:
    """The state, records and command to continue from: a resumed run's, or a fresh run's in an empty folder."""
    state_path = run_dir / STATE
    if resume and state_path.is_file():
        saved, state = read_state(state_path)
        old = saved["config"]  # a field added to LoopConfig since the run started counts as its default
        changed = run_changes({**asdict(LoopConfig()), **old, **_moved_match_run(old, cfg), **_same_precision(old, cfg)},
                              asdict(cfg))
        if changed:
            raise ConfigError(f"{run_dir}: --resume with other settings than the interrupted run: {', '.join(map(printable, changed))}; "
                              "pass the same options (its run.json lists them) or a new output folder")
        records = read_iterations(run_dir)[: state.iteration + 1]
        check_resume_files(cfg, run_dir, state, records)
        info = run_dir / "run.json"
        if info.is_file():  # keep the command that started the run
            try:
                command = RunInfo.model_validate_json(info.read_bytes()).command or command
            except (OSError, ValueError) as exc:  # pydantic's ValidationError is a ValueError
                raise ConfigError(f"{info}: not the run.json the loop wrote ({type(exc).__name__}); {STATE_FIX}") from None
        return state, records, command
    if run_dir.exists() and any(p.name not in BOOKKEEPING for p in run_dir.iterdir()) and not resume:
        raise ConfigError(f"{run_dir}: the output folder is not empty; pass --resume to continue it or "
                          "choose a new folder")
    run_dir.mkdir(parents=True, exist_ok=True)
    return LoopState(), [], command


def read_state(path: Path) -> tuple[dict[str, Any], LoopState]:
    """The saved document and the state of a run's ``state.json``, checked: its shape, its fields, and every level id
    (pool, archive, buffer) a plain name inside the run folder; each failure one line naming the file and value."""
    saved = read_json(path, "loop state (written by the loop)", limit=STATE_BYTES)
    if not isinstance(saved, dict) or not isinstance(saved.get("config"), dict):
        raise ConfigError(f"{path}: expected {{\"config\": ..., \"state\": ...}} as the loop writes it; {STATE_FIX}")
    state = parse_config(LoopState, saved.get("state"), str(path), prefix="state", fix=STATE_FIX)
    for where, ids in (("pool", state.pool), ("archive", state.archive)):
        for level_id in ids:
            if (problem := lb.level_id_problem(level_id)) is not None:
                raise ConfigError(f"{path}: state.{where}: {problem}; {STATE_FIX}")
    if state.buffer:
        lb.LevelBufferState.from_dict(state.buffer, f"{path}: state.buffer")
    return saved, state


def check_run_files(run_dir: Path) -> None:
    """Before any work on --resume: the run's state.json and iterations.jsonl name only the run's own levels and
    files (see :func:`read_state`); one line naming the file and the value otherwise."""
    if (run_dir / STATE).is_file():
        read_state(run_dir / STATE)
    read_iterations(run_dir)


def _checkpoint(run_dir: Path, cfg: LoopConfig, state: LoopState, records: list[IterationRecord]) -> None:
    """Write the iteration log, then the resume state (last, atomically)."""
    write_iterations(run_dir, records)
    atomic_write_text(run_dir / STATE, json.dumps({"config": asdict(cfg), "state": asdict(state)}, indent=1))
