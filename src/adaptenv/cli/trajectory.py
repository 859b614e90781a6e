"""``adaptenv trajectory``: bring episodes recorded elsewhere in as adaptenv trajectories.

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from adaptenv.cli._common import existing_file, load_house_argument
from adaptenv.cli._outputs import FORCE_OPTION, output_file, record_file

trajectory_app = typer.Typer(help="Trajectories from other simulators: convert an AI2-THOR episode log.",
                             no_args_is_help=True, rich_markup_mode=None)  # plain help, like adaptenv.cli.HELP_STYLE


@trajectory_app.command("from-ai2thor")
def from_ai2thor(
    log: Path = typer.Argument(..., metavar="LOG", show_default=False,
                               help="JSON lines: an optional header {house, target_type}, then one "
                                    "{action, agent, lastActionSuccess} per AI2-THOR event (docs/simulator.md)."),
    house: Path = typer.Option(..., "--house", metavar="HOUSE", help="The house the episode ran in: a ProcTHOR "
                               "house JSON file or one line of a dataset, e.g. FILE.jsonl.gz:2:3 (give --assets "
                               "first for Objaverse assets)."),
    out: Path = typer.Option(..., "-o", "--out", metavar="TRAJ.json", help="Where to write the trajectory."),
    target: str | None = typer.Option(None, "--target", metavar="TYPE", help="Target type (e.g. Bed, or bed.n.01); "
                                      "default: the log header's target_type."),
    as_json: bool = typer.Option(False, "--json", help="Print the metrics and dropped actions as JSON."),
    force: bool = FORCE_OPTION,
) -> None:
    """Convert an episode your agent ran in AI2-THOR into an adaptenv trajectory.

    Then adaptenv analyze HOUSE TRAJ, adaptenv render HOUSE -t TRAJ and adaptenv adapt HOUSE
    --trajectory TRAJ work on it. Poses are copied (same frame and yaw as AI2-THOR); success, SPL
    and sight are adaptenv's, judged at those poses.
    """
    from rich.console import Console

    from adaptenv.sim.ai2thor import convert_ai2thor_log
    from adaptenv.sim.world import compile_world

    output_file(out, "-o", "trajectory from-ai2thor", force=force, inputs=[log, house])
    name, h = load_house_argument(house)
    world = compile_world(h, name)
    conv = convert_ai2thor_log(existing_file(log, "AI2-THOR log"), world, target_type=target)
    traj = conv.trajectory
    traj.save(out)
    record_file(out, "trajectory from-ai2thor")
    m = traj.metrics
    if as_json:
        typer.echo(json.dumps({"trajectory": str(out), "target_type": traj.target_type, "steps": len(traj.steps),
                               "dropped": dict(conv.dropped), "metrics": m.model_dump()}, indent=1))
        return
    dropped = ", ".join(f"{n} {a}" for a, n in conv.dropped.most_common()) or "none"
    Console().print(f"wrote [bold]{out}[/]: {len(traj.steps)} steps looking for {traj.target_type} "
                    f"(dropped, no floor motion: {dropped}); adaptenv judges success {m.success}, SPL {m.spl:.3f}, "
                    f"{m.collisions} collisions", highlight=False)


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.add_typer(trajectory_app, name="trajectory")
