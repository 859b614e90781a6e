"""``adaptenv demo``: the main job, offline on built-in defaults."""

from __future__ import annotations

from pathlib import Path

import typer


def demo(
    out: Path = typer.Option(Path("runs/demo"), "-o", "--out", help="Folder for the demo's outputs."),
    houses: int = typer.Option(3, "--houses", min=1, max=50, help="How many procedural houses to generate."),
    seed: int = typer.Option(0, "--seed", help="Root seed: the same seed gives the same outputs."),
) -> None:
    """Generate procedural houses and render them top-down (offline, deterministic)."""
    from rich.console import Console
    from rich.progress import track

    from adaptenv.render.topdown import render_house
    from adaptenv.scene.house import save_house
    from adaptenv.scene.procedural import generate_houses

    console = Console()
    out.mkdir(parents=True, exist_ok=True)
    generated = generate_houses(houses, seed)
    for i, house in enumerate(track(generated, description="rendering houses", console=console)):
        save_house(house, out / f"house_{i:04d}.json")
        render_house(house, grid=True).save(out / f"house_{i:04d}.png")
    console.print(f"wrote {len(generated)} houses and their top-down renders to [bold]{out}[/]")


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.command("demo")(demo)
