"""``adaptenv loop`` (one method, one seed) and ``adaptenv experiment`` (methods x seeds).

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads
torch or numba.
"""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from adaptenv.cli import _numbers as numbers
from adaptenv.cli._common import interrupted
from adaptenv.cli._outputs import command_line, output_folder
from adaptenv.cli.adapt import (
    API_OPTION,
    CACHE_OPTION,
    KEY_ENV_OPTION,
    LLM_CONFIG_OPTION,
    MAX_COST_OPTION,
    MAX_TOKENS_OPTION,
    PRICE_IN_OPTION,
    PRICE_OUT_OPTION,
    PROMPTS_OPTION,
    TARGET_CHOICES_OPTION,
    TARGET_DRAWS_OPTION,
    TARGET_MOVES_OPTION,
    TARGET_STOP_GAP_OPTION,
)
from adaptenv.curriculum.executor import ADDRESS_OPTION, EXECUTOR_OPTION, WORKERS_OPTION
from adaptenv.errors import ConfigError, RunsFailed


def _heldout(values: list[str] | None) -> dict[str, str] | None:
    """Parse repeated ``NAME=SPEC`` options."""
    if not values:
        return None
    out = {}
    for v in values:
        name, sep, spec = v.partition("=")
        if not sep or not name or not spec:
            raise ConfigError(f"--heldout {v!r}: expected NAME=HOUSES, e.g. rearranged=preset:pretrain-rearranged")
        out[name] = spec
    return out


def loop_llm_section(config_file: Path | None, **flags: object) -> dict[str, object]:
    """The loop config's ``llm`` section from --llm-config and the LLM flags (flags win; never a key)."""
    from adaptenv.adapt.llm import load_llm_config
    from adaptenv.adapt.llm.config import OPENAI_BASE_URL

    llm: dict[str, object] = (load_llm_config(config_file).model_dump(mode="json", exclude_defaults=True)
                              if config_file is not None else {})
    llm.update({k: v for k, v in flags.items() if v is not None})
    if flags.get("base_url"):
        llm["provider"] = "openai" if str(flags["base_url"]).rstrip("/") == OPENAI_BASE_URL else "openai-compatible"
    return llm


STRICT_OPTION = typer.Option(False, "--strict", help="Fail on the first house that cannot be used instead of "
                             "skipping it with a warning.")


def check_house_sets(specs: list[str], strict: bool, say) -> dict[str, int]:
    """Load each house set once up front: with ``strict`` the first unusable house is an error; otherwise
    say how many houses each set skips (the loop skips the same ones). Returns skipped counts by spec."""
    from adaptenv.agents.houses import load_house_set

    counts = {}
    for spec in dict.fromkeys(specs):
        skipped = load_house_set(spec, strict=strict).skipped
        counts[spec] = len(skipped)
        if skipped:
            say(f"{spec}: skipping {len(skipped)} house(s) that cannot be used: "
                + ", ".join(f"{h.name} ({h.reason})" for h in skipped[:3]) + (", ..." if len(skipped) > 3 else ""))
    return counts


def check_start_policy(spec: str) -> None:
    """Refuse a ``--policy`` the loop cannot fine-tune (no network, no such file, a checkpoint that does not load)
    before any work; the loop loads it again when it starts."""
    from adaptenv.agents.checkpoint import load_checkpoint
    from adaptenv.agents.registry import SCRATCH, init_checkpoint

    if spec.strip() in SCRATCH:
        return  # fresh weights: nothing to load
    path = init_checkpoint(spec, flag="--policy")
    if not path.is_file():
        raise ConfigError(f"--policy {spec}: no such checkpoint file; pass pretrained or the path of a .pt checkpoint")
    load_checkpoint(path)


def check_resumable(out: Path) -> None:
    """Refuse ``--resume`` unless ``out`` holds a loop run (its state.json, or run.json of a run cut short before)."""
    from adaptenv.curriculum.records import RUN_INFO, STATE

    if not out.is_dir():
        raise ConfigError(f"--resume: the run folder {out} does not exist; pass the -o of the interrupted run, or "
                          "start without --resume")
    if not (out / STATE).is_file() and not (out / RUN_INFO).is_file():
        raise ConfigError(f"--resume: {out} holds no loop run (no {STATE}); pass the -o of the interrupted run, or "
                          "start without --resume in a new folder")
    from adaptenv.curriculum.loop import check_run_files

    check_run_files(out)


def loop(
    policy: str = typer.Option("pretrained", "--policy", help="Starting policy: pretrained (the strongest shipped agent), pretrained-map, pretrained-scan, scratch or scratch-shape (a fresh map-reading network: labels or the recognising mode) or a checkpoint path."),
    houses: str = typer.Option("preset:pretrain-train", "--houses", help="Training scenes: a folder of house "
                                "JSON files, a house file, a dataset FILE.jsonl[.gz][:START:STOP] or preset:NAME."),
    iterations: int = typer.Option(3, "--iterations", "-T", min=1, help="Loop iterations."),
    method: str = typer.Option("ours", "--method", help="none, random, dr, dr-matched, sfl, oracle, rearrange, swap, plr, accel, "
                                "ours, ours-noselect, ours-randomscene, ours-nof, ours-dr, ours-learned or ours-llm."),
    seed: int = typer.Option(0, "--seed", callback=numbers.seed, help="Root seed."),
    out: Path = typer.Option(Path("runs/loop"), "-o", "--out", help="Run folder."),
    resume: bool = typer.Option(False, "--resume", help="Continue the run in --out from its last iteration."),
    scenes: int = typer.Option(8, "--scenes", min=1, help="Scenes rolled out and made per iteration."),
    edit_steps: int = typer.Option(5, "--edit-steps", min=0, help="Single-object edits per adapted scene."),
    finetune_frames: int = typer.Option(16_384, "--finetune-frames", min=1, help="Fine-tuning frames per iteration."),
    finetune_algo: str = typer.Option("dagger", "--finetune-algo", help="Fine-tuning: dagger (imitation of "
                                      "--finetune-teacher) or ppo (anchored PPO on the simulator's reward)."),
    finetune_kl_coef: float = typer.Option(0.0, "--finetune-kl-coef", min=0.0, callback=numbers.finite, help="ppo: weight of the KL anchor "
                                           "to pi_t (0.3 in docs/agent.md's runs)."),
    finetune_explore_bonus: float = typer.Option(0.0, "--finetune-explore-bonus", min=0.0, callback=numbers.finite, help="ppo: reward per "
                                                 "newly seen map cell (0.002 in docs/agent.md's runs)."),
    finetune_bc_coef: float = typer.Option(0.0, "--finetune-bc-coef", min=0.0, callback=numbers.finite, help="ppo: weight of a "
                                           "cross-entropy to --finetune-teacher's labels of the visited states."),
    finetune_freeze_encoder: bool = typer.Option(False, "--finetune-freeze-encoder", help="ppo: train pi_t's memory "
                                                 "and heads only, the observation encoder fixed (faster updates)."),
    finetune_keep_learner: bool = typer.Option(True, "--finetune-keep-learner/--finetune-fresh-learner",
                                               help="ppo: every iteration continues the last one's value head and "
                                               "Adam moments (one PPO run across the loop), or starts them afresh."),
    score_rollouts: int = typer.Option(4, "--score-rollouts", min=1, help="Episodes of pi_t per rolled-out scene; "
                                       "scene scores average them."),
    level_score: str = typer.Option("regret", "--level-score", help="Scene score of plr, accel and ours: regret, "
                                    "learnability (p(1-p)) or explorer_regret."),
    sfl_candidates: int = typer.Option(4, "--sfl-candidates", min=1, help="sfl: fresh houses scored per training "
                                       "scene kept."),
    match_run: str = typer.Option("", "--match-run", help="dr-matched: the run folder (same seed) whose "
                                  "environment steps per iteration it matches."),
    finetune_lr: float = typer.Option(1e-4, "--finetune-lr", min=0.0, callback=numbers.finite, help="Adam learning rate of fine-tuning."),
    finetune_teacher: str = typer.Option("expert", "--finetune-teacher", help="Who labels fine-tuning's states: "
                                         "expert, explorer (searches), map-explorer (searches on the agent's own map) "
                                         "or mix."),
    finetune_beta: float = typer.Option(0.8, "--finetune-beta", min=0.0, max=1.0, help="Probability that the "
                                        "teacher's action is executed while fine-tuning (DAgger's beta)."),
    finetune_max_steps: int = typer.Option(300, "--finetune-max-steps", min=1, help="Episode cap of fine-tuning's "
                                           "episodes (600 for the map-reading agent)."),
    finetune_min_start: float = typer.Option(0.0, "--finetune-min-start", min=0.0, callback=numbers.finite, help="Fine-tuning episodes start "
                                             "at least this geodesic distance (m) from the target (0: uniform)."),
    finetune_precision: str = typer.Option("auto", "--finetune-precision", help="Arithmetic of fine-tuning's "
                                           "gradient steps: auto (bf16 where the CPU computes it natively, else "
                                           "fp32), fp32, or bf16 (faster on CPUs with AVX512_BF16, about 8x slower "
                                           "on AVX2-only ones)."),
    grounded: bool = typer.Option(False, "--grounded", help="sfl, plr, accel and ours take their new levels from the "
                                  "training homes and random edits of them instead of fresh procedural houses."),
    appearance_edits: bool = typer.Option(False, "--appearance-edits", help="Random edits (random, accel, grounded "
                                          "levels) may also swap an object's asset or change a room's material."),
    focus_training: bool = typer.Option(False, "--focus-training", help="Fine-tuning episodes in adapted scenes ask "
                                        "for the target type G's edits aimed at."),
    relocate_targets: bool = typer.Option(False, "--relocate-targets", help="The failure-mode G may move a target "
                                          "inside its room or to a far room where its type plausibly stands (search "
                                          "failures); otherwise no edit moves a target."),
    door_edits: bool = typer.Option(False, "--door-edits", help="G may also open or shut interior doors (the "
                                    "failure-mode G for search, looping and timeout failures; the LLM G by a tool)."),
    learned_scorer: Path | None = typer.Option(None, "--learned-scorer", metavar="FILE.pt", help="ours-learned: "
                                               "the learned G's scorer (adaptenv gdata train -o FILE.pt); default: "
                                               "the shipped one."),
    target_success: float | None = typer.Option(None, "--target-success", metavar="P",
                                                  callback=numbers.finite, help="Difficulty on request "
                                                "(adapting methods): edit each adapted scene until pi_t's success on "
                                                "--target-episodes fixed episodes is within --target-tolerance of P "
                                                "(0 < P < 1), --edit-steps edits at most."),
    target_tolerance: float = typer.Option(0.10, "--target-tolerance", callback=numbers.finite,
                                           help="With --target-success: the tolerance."),
    target_episodes: int = typer.Option(20, "--target-episodes", min=1, max=500, help="With --target-success: "
                                        "episodes per scene the success is measured on."),
    target_choices: int = TARGET_CHOICES_OPTION,
    target_draws: int = TARGET_DRAWS_OPTION,
    target_stop_gap: float | None = TARGET_STOP_GAP_OPTION,
    heldout_episodes: int = typer.Option(100, "--heldout-episodes", callback=numbers.episodes, help="Episodes per held-out set."),
    heldout: list[str] = typer.Option(None, "--heldout", help="Held-out set NAME=HOUSES (repeatable); default: "
                                      "rearranged=preset:pretrain-rearranged and unseen=preset:pretrain-unseen."),
    model: str = typer.Option(None, "--model", help="LLM model for ours-llm (default gpt-4.1-mini)."),
    base_url: str = typer.Option(None, "--base-url", help="Server URL ending in /v1 for ours-llm (default "
                                 "$OPENAI_BASE_URL, else the OpenAI API)."),
    api: str = API_OPTION,
    api_key_env: str = KEY_ENV_OPTION,
    llm_cache: Path = CACHE_OPTION,
    prompts: str = PROMPTS_OPTION,
    price_in: float = PRICE_IN_OPTION,
    price_out: float = PRICE_OUT_OPTION,
    max_tokens: int = MAX_TOKENS_OPTION,
    max_cost: float = MAX_COST_OPTION,
    allow_target_moves: bool = TARGET_MOVES_OPTION,
    llm_config_file: Path = LLM_CONFIG_OPTION,
    executor: str = EXECUTOR_OPTION,
    workers: int = WORKERS_OPTION,
    address: str = ADDRESS_OPTION,
    strict: bool = STRICT_OPTION,
) -> None:
    """Run the closed loop: evaluate, analyze (F), generate (G), fine-tune, measure held-out success.

    Rollouts, held-out evaluation and scene generation run on --executor (same results on each).
    """
    from rich.console import Console

    from adaptenv.curriculum.executor import ExecutorOptions
    from adaptenv.curriculum.loop import LoopConfig, run_loop

    if resume and not out.is_dir():  # before the folder is locked (and so made)
        check_resumable(out)
    folder = output_folder(out, "-o", "loop", inputs=[houses, policy, match_run or None, learned_scorer], keep=True,
                           force_flag=None, then=(lambda: check_resumable(out)) if resume else None)
    if not resume:
        check_start_policy(policy)
    console = Console()
    llm = loop_llm_section(llm_config_file, model=model, base_url=base_url, api=api, api_key_env=api_key_env,
                           cache_dir=str(llm_cache) if llm_cache else None, prompts=prompts, price_in=price_in,
                           price_out=price_out, max_tokens=max_tokens, max_cost=max_cost,
                           allow_target_moves=allow_target_moves or None)
    cfg = LoopConfig(method=method, policy=policy, houses=houses, iterations=iterations, seed=seed,
                     scenes_per_iteration=scenes, edit_steps=edit_steps, finetune_frames=finetune_frames,
                     finetune_lr=finetune_lr, finetune_teacher=finetune_teacher, finetune_algo=finetune_algo,
                     finetune_kl_coef=finetune_kl_coef, finetune_explore_bonus=finetune_explore_bonus,
                     finetune_bc_coef=finetune_bc_coef,
                     finetune_keep_learner=finetune_keep_learner, finetune_freeze_encoder=finetune_freeze_encoder,
                     score_rollouts=score_rollouts, level_score=level_score, sfl_candidates=sfl_candidates,
                     match_run=match_run,
                     finetune_min_start=finetune_min_start, finetune_precision=finetune_precision,
                     finetune_beta=finetune_beta, finetune_max_steps=finetune_max_steps,
                     relocate_targets=relocate_targets, door_edits=door_edits, focus_training=focus_training,
                     grounded=grounded, appearance_edits=appearance_edits,
                     learned_scorer=str(learned_scorer) if learned_scorer else None,
                     heldout_episodes=heldout_episodes, llm=llm, target_success=target_success,
                     target_tolerance=target_tolerance, target_episodes=target_episodes,
                     target_choices=target_choices, target_draws=target_draws,
                     target_stop_gap=target_stop_gap, **({"heldout": h} if (h := _heldout(heldout)) else {}))
    cfg.check("adaptenv loop")
    options = ExecutorOptions(executor, workers, address).check()
    check_house_sets([cfg.houses, *cfg.heldout.values()], strict, console.print)
    command = command_line()
    try:
        with folder, options.make() as ex:
            records = run_loop(cfg, out, resume=resume, executor=ex, progress=lambda text: console.print(f"[dim]{text}[/]"),
                               command=command)
    except KeyboardInterrupt:
        again = command if resume else f"{command} --resume"
        interrupted(f"the finished iterations are saved in {out}; continue the run with: {again}")
    from rich.table import Table

    table = Table(title=f"{method} seed {seed}: held-out success per iteration (Delta R against pi_0)")
    sets = sorted(records[0].heldout)
    for col in ["iteration", "env steps", "updates", "edits", *sets]:
        table.add_column(col, justify="right")
    for r in records:
        table.add_row(str(r.iteration), f"{r.env_steps:,}", f"{r.grad_updates:,}", str(r.edits),
                      *[f"{r.heldout[s].success:.3f} ({r.heldout[s].success - records[0].heldout[s].success:+.3f})"
                        for s in sets])
    console.print(table)
    console.print(f"run folder: [bold]{out}[/]  (report: adaptenv report {out})")


def experiment(
    config: Path = typer.Option(..., "--config", help="Experiment config JSON (see configs/)."),
    out: Path = typer.Option(None, "-o", "--out", help="Experiment folder (default runs/<config name>)."),
    executor: str = EXECUTOR_OPTION,
    workers: int = WORKERS_OPTION,
    address: str = ADDRESS_OPTION,
    final_episodes: int = typer.Option(0, "--final-episodes", callback=numbers.episodes_or_none, help="Evaluate pi_0 and each run's last "
                                       "policy on this many held-out episodes per set as the run finishes "
                                       "(final_eval.json; summary_final.md at the end)."),
    strict: bool = STRICT_OPTION,
) -> None:
    """Run methods x seeds (resuming finished runs), then write CSVs, the summary table and plots.

    With --executor process|ray the (method, seed) runs go to the workers, one run per worker.
    """
    from rich.console import Console

    from adaptenv.curriculum.executor import check_executor, make_executor
    from adaptenv.curriculum.experiment import ExperimentConfig, run_experiment

    console = Console()
    cfg = ExperimentConfig.load(config)
    check_executor(executor, workers, address)
    out = out or Path("runs") / config.stem
    folder = output_folder(out, "-o", "experiment", inputs=[config], keep=True, force_flag=None)
    ref = cfg.loop_config(cfg.reference, cfg.seeds[0])
    check_house_sets([ref.houses, *ref.heldout.values()], strict, console.print)
    # one run per task: runs are long, and in order a stopped experiment leaves whole seeds
    ex = None if executor == "inprocess" else make_executor(executor, workers, address, chunksize=1)

    def say(text: str) -> None:
        console.print(f"[dim]{text}[/]")

    failed: RunsFailed | None = None
    try:
        with folder:
            try:
                run_experiment(cfg, out, executor=ex, command=" ".join(["adaptenv"] + sys.argv[1:]), progress=say,
                               final_episodes=final_episodes)
            except RunsFailed as exc:  # the other runs finished: show them, then say which failed
                failed = exc
            console.print((out / "summary.md").read_text(encoding="utf-8"))
            if final_episodes and failed is None:
                from adaptenv.curriculum.experiment import final_evaluation

                final_evaluation(out, cfg, final_episodes, executor=ex, progress=say)
                console.print(f"[bold]final evaluation on {final_episodes} episodes per set[/]")
                console.print((out / "summary_final.md").read_text(encoding="utf-8"))
    except KeyboardInterrupt:
        interrupted(f"the finished runs and iterations are kept in {out}; run the same command again to continue")
    finally:
        if ex is not None:
            ex.close()
    console.print(f"experiment folder: [bold]{out}[/]  (report: adaptenv report {out})")
    if failed is not None:
        raise failed


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.command("loop")(loop)
    app.command("experiment")(experiment)
