"""``adaptenv demo``: the main job, the closed loop end to end, offline on built-in defaults.

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads
torch or numba.
"""

from __future__ import annotations

from pathlib import Path

import typer

from adaptenv.cli import _numbers as numbers
from adaptenv.cli._outputs import MANIFEST, OutputFolder, output_folder

DEMO_METHODS = ("dr", "ours")
"""The demo compares the closed loop (ours) with domain randomization on the same houses, seed and fine-tuning frames."""
HELDOUT_EPISODES_PER_HOUSE = 25
"""Held-out episodes per house of each set: evaluation is cheap, and more paired episodes narrow the verdict's
interval."""


MARKER = MANIFEST
"""The manifest the demo leaves in its output folder (adaptenv.cli._outputs): a later demo replaces only its own."""
OWNED = ("houses", "run")
"""The demo's sub-folders, replaced when the demo runs again into its own folder (nothing else there is touched)."""


def prepare_out(out: Path) -> OutputFolder:
    """Check ``out`` for the demo: new, empty or an earlier demo's (whose outputs go on ``with``); refuse anything
    else, before any work."""
    return output_folder(out, "-o", "demo", owns=OWNED, force_flag=None)


def demo(
    out: Path = typer.Option(Path("runs/demo"), "-o", "--out", help="Folder for the demo's outputs: new, empty, or "
                             "an earlier demo's (whose houses/ and run/ are replaced)."),
    houses: int = typer.Option(4, "--houses", min=1, max=50, help="Procedural training houses to generate."),
    iterations: int = typer.Option(2, "--iterations", min=1, max=20, help="Closed-loop iterations."),
    seed: int = typer.Option(0, "--seed", callback=numbers.seed, help="Root seed: the same seed gives the same outputs."),
    policy: str = typer.Option("pretrained", "--policy", help="Starting policy: pretrained (the strongest shipped agent), pretrained-map, pretrained-scan or a checkpoint path."),
) -> None:
    """Generate houses, run the closed loop and domain randomization on them, write the report and its verdict."""
    folder = prepare_out(out)  # before any work: a folder the demo did not write is refused, not emptied
    from rich.console import Console

    from adaptenv.curriculum.experiment import ExperimentConfig, run_experiment, verdict_lines
    from adaptenv.curriculum.experiment import run_dir as experiment_run_dir
    from adaptenv.curriculum.records import read_iterations
    from adaptenv.curriculum.verdict import budget_line
    from adaptenv.progress import ProgressBar
    from adaptenv.report import build_report
    from adaptenv.scene.house import save_house
    from adaptenv.scene.procedural import generate_houses, rearrange_house

    with folder:
        console = Console()
        train, heldout_re, heldout_new = out / "houses" / "train", out / "houses" / "rearranged", out / "houses" / "unseen"
        console.print(f"[bold]1/4[/] generating {houses} training houses, their rearranged variants and "
                      f"{houses} unseen houses")
        with ProgressBar("houses", 3 * houses) as bar:
            for i, house in enumerate(generate_houses(houses, seed)):
                save_house(house, train / f"house_{i:02d}.json")
                save_house(rearrange_house(house, seed + 1000 + i), heldout_re / f"house_{i:02d}.json")
                bar.advance(2)
            for i, house in enumerate(generate_houses(houses, seed + 1)):
                save_house(house, heldout_new / f"house_{i:02d}.json")
                bar.advance()

        console.print(f"[bold]2/4[/] closed loop ({iterations} iterations) against domain randomization (dr), with "
                      "the same fine-tuning frames per iteration: roll out the agent, analyze each trajectory (F), edit "
                      "the scenes (G), fine-tune, evaluate on held-out houses")
        loop = {"policy": policy, "houses": str(train), "heldout": {"rearranged": str(heldout_re), "unseen": str(heldout_new)},
                "iterations": iterations, "scenes_per_iteration": houses, "edit_steps": 5, "finetune_frames": 8192,
                "finetune_envs": 64, "heldout_episodes": HELDOUT_EPISODES_PER_HOUSE * houses, "gallery": houses}
        cfg = ExperimentConfig(methods=list(DEMO_METHODS), seeds=[seed], loop=loop)
        run_dir = out / "run"
        summary = run_experiment(cfg, run_dir, command="adaptenv demo",
                                 progress=lambda text: console.print(f"    [dim]{text}[/]"))

        console.print("[bold]3/4[/] held-out success per iteration (± standard error over episodes):")
        for method in cfg.methods:
            for r in read_iterations(experiment_run_dir(run_dir, method, seed)):
                figs = ", ".join(f"{k} {v.success:.2f} ± {v.success_se:.2f}" for k, v in sorted(r.heldout.items()))
                took = f", {r.wall_time_s:.0f} s" if r.wall_time_s else ""
                console.print(f"    {method:>4} t={r.iteration}: {figs}  ({r.edits} edits, {r.env_steps:,} env steps{took})")
        console.print(f"    Each figure comes from {loop['heldout_episodes']} episodes per set; t=0 is the starting policy "
                      "(the same for both methods).")
        for line in verdict_lines(summary) or ["Verdict: none (no held-out episodes evaluated by both methods)."]:
            console.print(line, style="bold", markup=False)
        if budget := budget_line(summary):
            console.print(budget, markup=False)

        console.print("[bold]4/4[/] writing the report")
        index = build_report(run_dir)
        console.print(f"report: [bold]{index}[/]")


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.command("demo")(demo)
