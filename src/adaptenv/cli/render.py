"""``adaptenv render``: a house (and optionally an episode) as a top-down PNG; ``adaptenv bench render``.

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads
torch or numba.
"""

from __future__ import annotations

from pathlib import Path

import typer

from adaptenv.cli._common import HOUSE_HELP, JSON_OPTION, load_house_argument
from adaptenv.cli._outputs import FORCE_OPTION, output_file, record_file

HOUSE_ARGUMENT = typer.Argument(..., metavar="HOUSE", help=HOUSE_HELP, show_default=False)
OUT_OPTION = typer.Option(Path("map.png"), "-o", "--out", help="Image file to write (PNG).")
TRAJECTORY_OPTION = typer.Option(None, "--trajectory", "-t", metavar="TRAJ.json",
                                 help="Trajectory JSON to draw on the map (path, collisions, targets).")
GRID_OPTION = typer.Option(False, "--grid", help="Draw the paper's normalized 0..100 grid with ticks.")
SIZE_OPTION = typer.Option(1024, "--size", min=256, max=8192, help="Longer side of the image in pixels.")
NO_LABELS_OPTION = typer.Option(False, "--no-labels", help="Leave out object ids and room names.")
TITLE_OPTION = typer.Option(None, "--title", help="A bold line above the map.")
HIGHLIGHT_OPTION = typer.Option([], "--highlight", metavar="ID[=COLOUR]",
                                help="Fill this object with a colour (default deepskyblue); repeatable.")
BENCH_HOUSE_OPTION = typer.Option(None, "--house", help="House to render (default: the real test house).")


def render(
    house: Path = HOUSE_ARGUMENT,
    out: Path = OUT_OPTION,
    trajectory: Path | None = TRAJECTORY_OPTION,
    grid: bool = GRID_OPTION,
    size: int = SIZE_OPTION,
    no_labels: bool = NO_LABELS_OPTION,
    title: str | None = TITLE_OPTION,
    highlight: list[str] = HIGHLIGHT_OPTION,
    force: bool = FORCE_OPTION,
) -> None:
    """Render a house top-down (rooms, walls, doors, furniture with ids), optionally with an episode."""
    from rich.console import Console

    from adaptenv.cli._common import check_recorded_in
    from adaptenv.render.labels import LABEL_LIMIT, labels_fit
    from adaptenv.render.topdown import render_to_file
    from adaptenv.sim.trajectory import Trajectory
    from adaptenv.sim.world import compile_world

    name, h = load_house_argument(house)
    output_file(out, "-o", "render", force=force, inputs=[house, trajectory])
    traj = Trajectory.load(trajectory) if trajectory is not None else None
    if traj is not None:
        check_recorded_in(traj, compile_world(h, name), trajectory, house)
    colours = {}
    for item in highlight:
        oid, _, colour = item.partition("=")
        colours[oid] = colour or "deepskyblue"
    path = render_to_file(h, out, trajectory=traj, grid=grid, size=size, labels=not no_labels, title=title,
                          highlight=colours or None)
    if not no_labels and not labels_fit(n := _floor_objects(h)):
        Console().print(f"{house}: {n:,} floor objects, more than the {LABEL_LIMIT} that get id labels; the map "
                        "shows room names only", highlight=False)
    record_file(path, "render")
    Console().print(f"wrote [bold]{path}[/]")


def _floor_objects(house) -> int:
    """How many floor objects a render of ``house`` labels (only counted when there may be too many)."""
    from adaptenv.render.labels import LABEL_LIMIT
    from adaptenv.scene.geometry import SceneGeometry

    return len(house.objects) if len(house.objects) <= LABEL_LIMIT else len(SceneGeometry.from_house(house).floor_objects)


def bench_render(
    house: Path | None = BENCH_HOUSE_OPTION,
    size: int = SIZE_OPTION,
    as_json: bool = JSON_OPTION,
) -> None:
    """Median render time of a 10-room house at 1024 px: plain, with grid, and with a 600-step episode."""
    from adaptenv.bench import emit
    from adaptenv.bench.render import REAL_HOUSE, run

    figures = run(house or REAL_HOUSE, size=size)
    emit("render: top-down map (median ms)", figures, as_json, notes=["target: under 50 ms at 1024 px"])


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.command("render")(render)
    bench.command("render")(bench_render)
