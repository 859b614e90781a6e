"""``adaptenv demo``: the main job, the closed loop end to end, offline on built-in defaults.

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads
torch or numba.
"""

from __future__ import annotations

from pathlib import Path

import typer

MARKER = ".adaptenv-demo"
"""The file the demo writes into its output folder: a later demo may replace only a folder that holds it."""
OWNED = ("houses", "run")
"""The demo's sub-folders, replaced when the demo runs again into its own folder (nothing else there is touched)."""


def prepare_out(out: Path) -> None:
    """Make ``out`` ready for the demo: new, empty or an earlier demo's (its outputs removed); refuse anything else."""
    import shutil

    from adaptenv.cli._common import writable_folder
    from adaptenv.errors import ConfigError

    writable_folder(out, "-o")  # also refuses a file
    if out.is_dir() and any(out.iterdir()):
        if not (out / MARKER).is_file():
            raise ConfigError(f"-o {out}: the folder is not empty and was not written by adaptenv demo, so nothing "
                              "in it is replaced; pass a new or empty folder with -o")
        for name in OWNED:
            if (out / name).is_dir():
                shutil.rmtree(out / name)
    out.mkdir(parents=True, exist_ok=True)
    (out / MARKER).write_text("written by adaptenv demo; a later demo with the same -o replaces houses/ and run/\n",
                              encoding="utf-8")


def demo(
    out: Path = typer.Option(Path("runs/demo"), "-o", "--out", help="Folder for the demo's outputs: new, empty, or "
                             "an earlier demo's (whose houses/ and run/ are replaced)."),
    houses: int = typer.Option(4, "--houses", min=1, max=50, help="Procedural training houses to generate."),
    iterations: int = typer.Option(2, "--iterations", min=1, max=20, help="Closed-loop iterations."),
    seed: int = typer.Option(0, "--seed", help="Root seed: the same seed gives the same outputs."),
    policy: str = typer.Option("pretrained", "--policy", help="Starting policy: pretrained or a checkpoint path."),
) -> None:
    """Generate houses, run the pretrained agent, analyze and adapt its scenes, fine-tune, write the report."""
    prepare_out(out)  # before any work: a folder the demo did not write is refused, not emptied
    from rich.console import Console

    from adaptenv.curriculum.loop import LoopConfig, run_loop
    from adaptenv.progress import ProgressBar
    from adaptenv.report import build_report
    from adaptenv.scene.house import save_house
    from adaptenv.scene.procedural import generate_houses, rearrange_house

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

    console.print(f"[bold]2/4[/] closed loop ({iterations} iterations): roll out the agent, analyze each trajectory (F), "
                  "edit the scenes (G), fine-tune, evaluate on held-out houses")
    cfg = LoopConfig(method="ours", policy=policy, houses=str(train),
                     heldout={"rearranged": str(heldout_re), "unseen": str(heldout_new)}, iterations=iterations,
                     seed=seed, scenes_per_iteration=houses, edit_steps=5, finetune_frames=8192, finetune_envs=64,
                     heldout_episodes=4 * houses, gallery=houses)
    run_dir = out / "run"
    records = run_loop(cfg, run_dir, progress=lambda text: console.print(f"    [dim]{text}[/]"),
                       command="adaptenv demo")

    console.print("[bold]3/4[/] held-out success per iteration (± standard error over episodes):")
    for r in records:
        figs = ", ".join(f"{k} {v.success:.2f} ± {v.success_se:.2f}" for k, v in sorted(r.heldout.items()))
        took = f", {r.wall_time_s:.0f} s" if r.wall_time_s else ""
        console.print(f"    t={r.iteration}: {figs}  ({r.edits} edits, {r.env_steps:,} env steps{took})")
    console.print(f"    Each figure comes from {cfg.heldout_episodes} episodes per set, so a change smaller than "
                  "about two standard errors is noise, not learning or forgetting; t=0 is the starting policy.")

    console.print("[bold]4/4[/] writing the report")
    index = build_report(run_dir)
    console.print(f"report: [bold]{index}[/]")


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.command("demo")(demo)
