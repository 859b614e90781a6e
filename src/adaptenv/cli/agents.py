"""``adaptenv train`` (imitation learning), ``adaptenv evaluate`` (the harness), ``adaptenv bench train``.

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads
torch or numba.
"""

from __future__ import annotations

import inspect
import shlex
from dataclasses import MISSING, fields
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from adaptenv.cli import _numbers as numbers
from adaptenv.cli._common import JSON_OPTION, interrupted
from adaptenv.cli._outputs import (
    FORCE_OPTION,
    OutputFolder,
    continued_folder,
    output_file,
    output_folder,
    recording,
)
from adaptenv.files import atomic_write_text

if TYPE_CHECKING:
    from adaptenv.agents.config import PPOConfig, TrainConfig

_SHORT = {"output": ["-o"], "seed": ["-s"]}
_HOUSES_OPTION = typer.Option(..., "--houses", help="Folder of house JSON files, a house file, a dataset "
                              "FILE.jsonl[.gz] (a slice such as FILE.jsonl.gz:0:100 picks lines), preset:NAME or "
                              "suite:NAME; "
                              "repeat to compare sets (the first is the baseline of the drop).")
_OUT_OPTION = typer.Option(Path("runs/eval"), "-o", "--out", help="Output folder (one subfolder per house set).")


def _config_params(cls: type) -> list[inspect.Parameter]:
    """One typer option per field of the config dataclass ``cls``, its docstring as the help."""
    from adaptenv.agents.config import field_docs

    docs = field_docs(cls)
    params = []
    for f in fields(cls):
        default = f.default if f.default is not MISSING else None
        flag = "--" + f.name.replace("_", "-")
        decls = [f"{flag}/--no-{f.name.replace('_', '-')}"] if f.type in ("bool", bool) else [flag]
        decls += _SHORT.get(f.name, [])
        kind = {"bool": bool, "int": int, "float": float, "str": str}.get(str(f.type), str)
        params.append(inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, annotation=kind,
                                        default=typer.Option(default, *decls, help=docs.get(f.name, ""))))
    return params


def final_eval_text(card: dict) -> str:
    """The training card's final evaluation in words ("no final evaluation" when it ran no episodes)."""
    n = card["final_eval_episodes"]
    if not n:
        return "no final evaluation was run (--final-eval-episodes 0)"
    return f"success on fresh training episodes {card['final_train_success']:.1%} (n={n})"


def check_frames(cfg: TrainConfig | PPOConfig, command: str) -> None:
    """Refuse a --frames budget below one collection block (num_envs x rollout_steps); say when it is rounded up."""
    from adaptenv.errors import ConfigError

    block = cfg.num_envs * cfg.rollout_steps
    if cfg.frames < block:
        raise ConfigError(f"--frames {cfg.frames} is less than one collection block (--num-envs {cfg.num_envs} x "
                          f"--rollout-steps {cfg.rollout_steps} = {block:,} frames); pass --frames {block} or more, "
                          "or lower --num-envs or --rollout-steps")
    if cfg.frames % block:
        total = -(-cfg.frames // block) * block
        typer.echo(f"{command} collects whole blocks of {block:,} frames: --frames {cfg.frames} trains "
                   f"{total:,} frames (the card records them)")


RUN_DIR_OWNS = ("config.json", "metrics.csv", "state.pt", "tb")
"""What ``train`` and ``ppo`` write into their run folder (--run-dir)."""


def check_outputs(cfg: TrainConfig | PPOConfig, run_dir: Path | None, command: str,
                  force: bool = False) -> tuple[list[Path], OutputFolder | None]:
    """Check before any work that the checkpoint (--output), its card and the run folder (--run-dir) may be
    written (the output rule of :mod:`adaptenv.cli._outputs`); returns the files and the folder to write."""
    from adaptenv.errors import ConfigError

    resume = bool(getattr(cfg, "resume", False))
    inputs = [cfg.init or None, cfg.houses]
    files = []
    if cfg.output:
        out = Path(cfg.output)
        card = out.with_suffix(".json")
        if out.suffix.lower() == ".json":
            raise ConfigError(f"--output {out}: the training card is written beside the checkpoint as {card.name}, "
                              "which would overwrite the checkpoint; name the checkpoint .pt (e.g. -o "
                              f"{out.with_suffix('.pt')})")
        continued = resume and run_dir is not None and _recorded_output(run_dir) == str(cfg.output)
        output_file(out, "--output", command, force=force or continued, inputs=inputs)
        output_file(card, "--output", command, force=force or continued, inputs=inputs,
                    name=f"--output {out}: its card {card}")
        files = [out, card]
    if run_dir is None:
        return files, None
    if resume:  # the run's own folder, continued: train checks its state.pt before writing anything
        return files, continued_folder(run_dir, "--run-dir", command)
    return files, output_folder(run_dir, "--run-dir", command, force=force, inputs=inputs, owns=RUN_DIR_OWNS)


def _recorded_output(run_dir: Path) -> str | None:
    """The checkpoint path an earlier run in ``run_dir`` wrote (its config.json's output), if any."""
    import json

    try:
        return json.loads((run_dir / "config.json").read_text(encoding="utf-8")).get("output")
    except (OSError, ValueError, AttributeError):
        return None


def _train_command():
    """Build ``adaptenv train`` from TrainConfig: one option per field, its docstring as the help."""
    from adaptenv.agents.config import TrainConfig

    params = _config_params(TrainConfig)

    def train(**kwargs) -> None:
        """Train a navigation policy by behaviour cloning + DAgger from the shortest-path expert."""
        from rich.console import Console

        from adaptenv.agents.train import TrainConfig, check_config, default_run_dir
        from adaptenv.agents.train import train as run_training

        force = kwargs.pop("force")
        cfg = TrainConfig(**kwargs)
        check_config(cfg)
        check_frames(cfg, "adaptenv train")
        files, folder = check_outputs(cfg, default_run_dir(cfg), "train", force)
        command = train_command_line(cfg)
        try:
            with recording(files, folder, "train"):
                result = run_training(cfg, command=command)
        except KeyboardInterrupt:
            run_dir = default_run_dir(cfg)
            saved = run_dir is not None and (run_dir / "state.pt").is_file()
            again = command if cfg.resume else f"{command} --resume"
            interrupted(f"the run is saved in {run_dir}, continue it with: {again}" if saved else "")
        card = result.card
        Console().print(
            f"trained on {card['n_houses']} houses ({card['houses']}): {card['frames']:,} frames in "
            f"{card['wall_time_s']:.0f} s; {final_eval_text(card)}"
            + (f"; wrote [bold]{cfg.output}[/]" if cfg.output else ""))

    force = inspect.Parameter("force", inspect.Parameter.KEYWORD_ONLY, annotation=bool, default=FORCE_OPTION)
    train.__signature__ = inspect.Signature([*params, force])  # type: ignore[attr-defined]
    return train


def _ppo_command():
    """Build ``adaptenv ppo`` from PPOConfig: one option per field, its docstring as the help."""
    from adaptenv.agents.config import PPOConfig

    def ppo(**kwargs) -> None:
        """Fine-tune a navigation policy by PPO on the simulator's SPOC-style reward (warm start: --init)."""
        from rich.console import Console

        from adaptenv.agents.ppo import check_ppo_config, default_ppo_run_dir, train_ppo

        force = kwargs.pop("force")
        cfg = PPOConfig(**kwargs)
        check_ppo_config(cfg)
        check_frames(cfg, "adaptenv ppo")
        files, folder = check_outputs(cfg, default_ppo_run_dir(cfg), "ppo", force)
        with recording(files, folder, "ppo"):
            result = train_ppo(cfg, command=config_command_line("ppo", cfg))
        card = result.card
        Console().print(
            f"PPO on {card['n_houses']} houses ({card['houses']}): {card['frames']:,} frames in "
            f"{card['wall_time_s']:.0f} s; end threshold {card['end_threshold']}; {final_eval_text(card)}"
            + (f"; wrote [bold]{cfg.output}[/]" if cfg.output else ""))

    force = inspect.Parameter("force", inspect.Parameter.KEYWORD_ONLY, annotation=bool, default=FORCE_OPTION)
    ppo.__signature__ = inspect.Signature([*_config_params(PPOConfig), force])  # type: ignore[attr-defined]
    return ppo


def evaluate(
    policy: str = typer.Option("pretrained", "--policy", "-p",
                               help="Policy: pretrained (the strongest shipped agent), pretrained-map, "
                               "pretrained-scan, expert, explorer, map-explorer, random, a checkpoint path (.pt), or "
                               "module:attribute."),
    houses: list[str] = _HOUSES_OPTION,
    episodes: int = typer.Option(200, "--episodes", "-n", callback=numbers.episodes, help="Episodes per house set."),
    seed: int = typer.Option(0, "--seed", "-s", callback=numbers.seed, help="Seed of the episodes (same seed, same results)."),
    workers: int = typer.Option(1, "--workers", "-w", min=1, help="Worker processes (episodes are split among them)."),
    batch: int = typer.Option(64, "--batch", min=1, help="Episodes simulated at once per process."),
    out: Path = _OUT_OPTION,
    min_geodesic: float = typer.Option(0.0, "--min-geodesic", min=0.0, callback=numbers.finite,
                                       help="Keep only starts at least this geodesic distance (m) from the target "
                                            "(overrides a suite's floor; 0 keeps the suite's or none)."),
    min_expert_steps: int = typer.Option(0, "--min-expert-steps", min=0,
                                         help="Keep only starts the shortest-path expert needs at least this many "
                                              "steps for (redraws per episode, paired across policies)."),
    strict: bool = typer.Option(False, "--strict", help="Fail on the first house that cannot be used instead of "
                                "skipping it with a warning."),
    wipe_every: int = typer.Option(0, "--wipe-every", min=0, help="Wipe the policy's memory (recurrent state and "
                                   "map) at steps K, 2K, ... of each episode (0: never; see adaptenv memory-check)."),
    force: bool = FORCE_OPTION,
) -> None:
    """Evaluate a policy: success, SPL, SEL, collisions, length (mean +- s.e.), per-house CSV, failure maps."""
    import json
    from functools import partial

    from rich.console import Console
    from rich.table import Table

    from adaptenv.agents.evaluate import by_rooms_line, drop, write_report
    from adaptenv.agents.evaluate import evaluate as run_eval
    from adaptenv.agents.houses import load_house_set
    from adaptenv.agents.network import configure_torch
    from adaptenv.agents.registry import resolve_policy
    from adaptenv.agents.suites import EpisodeFloor
    from adaptenv.progress import ProgressBar
    from adaptenv.render.topdown import render_house

    folder = output_folder(out, "-o", "evaluate", force=force, inputs=[policy, *houses])
    configure_torch()
    console = Console()
    command = shlex.join(["adaptenv", "evaluate", "--policy", policy, *[a for h in houses for a in ("--houses", h)],
                          "--episodes", str(episodes), "--seed", str(seed), "--workers", str(workers),
                          "--batch", str(batch), "-o", str(out), *(["--strict"] if strict else [])]
                         + (["--min-geodesic", f"{min_geodesic:g}"] if min_geodesic > 0 else [])
                         + (["--min-expert-steps", str(min_expert_steps)] if min_expert_steps > 0 else [])
                         + (["--wipe-every", str(wipe_every)] if wipe_every > 0 else []))
    floor = (EpisodeFloor(min_geodesic=min_geodesic, min_expert_steps=min_expert_steps)
             if min_geodesic > 0 or min_expert_steps > 0 else None)
    resolved = resolve_policy(policy, seed=seed)  # fail early on a bad --policy
    wrap = None
    if wipe_every:
        from adaptenv.agents.memory import WipeMemory, require_wipeable

        require_wipeable(resolved, "--wipe-every")
        wrap = partial(WipeMemory, every=wipe_every)
    summaries = []
    with folder:
        for spec in houses:
            house_set = load_house_set(spec, strict=strict)
            with ProgressBar(f"{policy} on {spec}", episodes) as bar:
                report = run_eval(policy if workers > 1 else resolved, house_set, episodes=episodes, seed=seed,
                                  batch=batch, workers=workers, floor=floor, progress=bar.update, wrap=wrap)
            report.policy = policy
            if wipe_every:
                report.summary["wipe_every"] = wipe_every
            sub = out / _slug(spec) if len(houses) > 1 else out
            report.summary["failure_modes"] = failure_modes(report, house_set)
            paths = write_report(report, house_set, sub, command=command, render=render_house)
            summaries.append((spec, report.summary, paths))
        table = Table(title=f"{policy}: {episodes} episodes per set, seed {seed}")
        rows = [[f"{s['success']:.3f} [{s['success_ci95'][0]:.3f}, {s['success_ci95'][1]:.3f}]",
                 f"{s['spl']:.3f} [{s['spl_ci95'][0]:.3f}, {s['spl_ci95'][1]:.3f}]",
                 f"{s['sel']:.3f} +- {s['sel_se']:.3f}", f"{s['collisions']:.1f} +- {s['collisions_se']:.1f}",
                 f"{s['steps']:.0f} +- {s['steps_se']:.0f}"] for _, s, _ in summaries]
        specs = [spec for spec, _, _ in summaries]
        headers = ["success [95% CI]", "SPL [95% CI]", "SEL", "collisions", "length"]
        room, widths = column_widths(console.width, headers, rows)
        labels = set_labels(specs, room)
        table.add_column("houses", justify="left", no_wrap=True, width=max(map(len, labels)))
        for col, width in zip(headers, widths, strict=True):
            table.add_column(col, justify="right", width=width)
        for label, row in zip(labels, rows, strict=True):
            table.add_row(label, *row)
        console.print(table)
        for label, spec in zip(labels, specs, strict=True):
            if label != spec:
                console.print(f"{label} = {spec}", highlight=False, soft_wrap=True)
        for spec, s, _ in summaries:
            if s["skipped_houses"]:
                console.print(f"skipped {len(s['skipped_houses'])} house(s) of {spec} that cannot be used "
                              f"({', '.join(list(s['skipped_houses'])[:5])}{', ...' if len(s['skipped_houses']) > 5 else ''}); "
                              "see summary.json for the reasons", highlight=False)
        for spec, s, _ in summaries:
            if "floor_left_out" in s:
                console.print(floor_line(spec, s), highlight=False)
        for spec, s, _ in summaries:
            if len(s["by_rooms"]) > 1 or len(summaries) == 1:
                console.print(f"{by_rooms_line(s['by_rooms'])}" + (f" on {spec}" if len(summaries) > 1 else ""),
                              highlight=False, soft_wrap=True)
        for spec, s, _ in summaries:
            if s["failure_modes"]:
                console.print(f"failures on {spec} (built-in analysis F): "
                              + ", ".join(f"{mode} {n}" for mode, n in s["failure_modes"].items()))
        if len(summaries) > 1:
            base_spec, base, _ = summaries[0]
            drops = {}
            for spec, s, _ in summaries[1:]:
                d_s, d_p = drop(base, s, "success"), drop(base, s, "spl")
                drops[spec] = {"success": d_s, "spl": d_p}
                console.print(f"drop {base_spec} -> {spec}: success {d_s['drop']:+.3f} "
                              f"[{d_s['ci95'][0]:+.3f}, {d_s['ci95'][1]:+.3f}], SPL {d_p['drop']:+.3f} "
                              f"[{d_p['ci95'][0]:+.3f}, {d_p['ci95'][1]:+.3f}]")
            atomic_write_text(out / "comparison.json", json.dumps(
                {"policy": policy, "episodes": episodes, "seed": seed, "command": command,
                 "sets": {spec: s for spec, s, _ in summaries}, "drop_from": base_spec, "drops": drops},
                indent=1, default=float) + "\n")
        console.print(f"wrote results to [bold]{out}[/]")


def failure_modes(report, house_set) -> dict[str, int]:
    """How the failed episodes failed, as the built-in analysis F classifies them, most common first."""
    from collections import Counter

    from adaptenv.adapt.analysis import BuiltinAnalyzer
    from adaptenv.agents.evaluate import trajectory_of
    from adaptenv.sim.metrics import episode_metrics

    analyzer, modes = BuiltinAnalyzer(), Counter()
    for r in report.results:
        if not r.success and r.index in report.recordings:
            world = house_set.worlds[r.env]
            traj = trajectory_of(world, r, report.recordings[r.index], report.policy)
            traj.metrics = episode_metrics(world, traj)
            modes[str(analyzer.analyze(traj, world).outcome.failure_mode)] += 1
    return dict(modes.most_common())


def train_command_line(cfg) -> str:
    """The ``adaptenv train`` command reproducing ``cfg`` (options that differ from the defaults)."""
    return config_command_line("train", cfg)


def config_command_line(command: str, cfg) -> str:
    """The ``adaptenv COMMAND`` line reproducing the config ``cfg`` (options that differ from the defaults)."""
    default = type(cfg)()
    args = ["adaptenv", command]
    for f in fields(cfg):
        value = getattr(cfg, f.name)
        if value == getattr(default, f.name) and f.name not in ("houses", "frames", "output", "seed"):
            continue
        flag = "--" + f.name.replace("_", "-")
        if isinstance(value, bool):
            args.append(flag if value else f"--no-{f.name.replace('_', '-')}")
        else:
            args += [flag, str(value)]
    return shlex.join(args)


def floor_line(spec: str, s: dict) -> str:
    """How many houses of a set the episode floor left out (no start that far), and how many the episodes used."""
    left = s["floor_left_out"]
    return (f"floor {s['floor']} on {spec}: left out {len(left)} house(s) with no start that far from a target"
            + (f" ({', '.join(left[:3])}{', ...' if len(left) > 3 else ''}; see summary.json)" if left else "")
            + f"; the episodes used {s['houses_used']} of its {s['houses_in_set']} houses")


def column_widths(console_width: int, headers: list[str], rows: list[list[str]]) -> tuple[int, list[int]]:
    """(characters left for the houses column, width of each figure column) of the evaluate table: the figures
    on one line when that leaves the houses 24 characters, else wrapped to their longest word (one space of
    padding each side and a border per column)."""
    texts = [[h, *(r[i] for r in rows)] for i, h in enumerate(headers)]
    one_line = [max(len(t) for t in col) for col in texts]
    frame = 3 * (len(headers) + 1) + 1
    if console_width - sum(one_line) - frame >= 24:
        return console_width - sum(one_line) - frame, one_line
    narrowest = [max(len(w) for t in col for w in t.split()) for col in texts]
    return max(12, console_width - sum(narrowest) - frame), narrowest


def set_labels(specs: list[str], width: int) -> list[str]:
    """Distinct names of at most ``width`` characters for house sets: the specs when they fit, else their
    tails ("..." and the end, where sets from one folder differ), else "set 1", "set 2", ..."""
    if all(len(s) <= width for s in specs):
        return list(specs)
    tails = [s if len(s) <= width else "..." + s[len(s) - width + 3:] for s in specs]
    if len(set(tails)) == len(tails):
        return tails
    return [f"set {i + 1}" for i in range(len(specs))]


def _slug(spec: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in spec.replace("preset:", "")).strip("_") or "houses"


def bench_train(as_json: bool = JSON_OPTION,
                envs: int = typer.Option(256, "--envs", help="Agents simulated at once."),
                steps: int = typer.Option(200, "--steps", help="Steps timed per measurement."),
                algo: str = typer.Option("dagger", "--algo", help="dagger (imitation figures and end to end), ppo, or map "
                                         "(the map-reading recipe beside today's: labelling and end to end)."),
                iterations: int = typer.Option(3, "--iterations", min=0,
                                               help="Training iterations timed end to end (0: skip that figure)."),
                hidden: int | None = typer.Option(None, "--hidden", min=1, help="GRU memory size (default: TrainConfig's)."),
                feature_dim: int | None = typer.Option(None, "--feature-dim", min=1,
                                                       help="Per-step feature size (default: TrainConfig's)."),
                conv_channels: int | None = typer.Option(None, "--conv-channels", min=1,
                                                         help="Ray convolution channels (default: TrainConfig's)."),
                updates_per_iter: int | None = typer.Option(None, "--updates-per-iter", min=1,
                                                            help="Gradient steps per collection, i.e. the replay ratio "
                                                                 "(default: TrainConfig's)."),
                precision: str | None = typer.Option(None, "--precision", help="auto, fp32 or bf16: the gradient steps "
                                                     "of the recipe and of the end-to-end figure (default: "
                                                     "TrainConfig's, auto; both are timed either way).")
                ) -> None:
    """Training throughput: labelled, gradient and end-to-end frames/s, inference steps/s, parameter count."""
    from adaptenv.bench.train import run, run_map, run_ppo

    recipe = {k: v for k, v in (("hidden", hidden), ("feature_dim", feature_dim), ("conv_channels", conv_channels),
                                ("updates_per_iter", updates_per_iter), ("precision", precision)) if v is not None}
    if precision is not None:
        from adaptenv.agents.train import check_precision

        check_precision(precision, "--precision")
    if algo == "ppo":
        run_ppo(as_json=as_json, iterations=max(1, iterations))
    elif algo == "map":
        run_map(as_json=as_json, iterations=max(1, iterations))
    elif algo == "dagger":
        run(as_json=as_json, envs=envs, steps=steps, iterations=iterations, recipe=recipe)
    else:
        raise typer.BadParameter(f"expected dagger, ppo or map, got {algo!r}", param_hint="--algo")


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.command("train")(_train_command())
    app.command("ppo")(_ppo_command())
    app.command("evaluate")(evaluate)
    bench.command("train")(bench_train)
