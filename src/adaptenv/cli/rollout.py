"""``adaptenv rollout``: run one ObjectNav episode in a house; ``adaptenv bench expert``.

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads
torch or numba.
"""

from __future__ import annotations

from pathlib import Path

import typer

from adaptenv.cli import _numbers as numbers
from adaptenv.cli._common import HOUSE_HELP, JSON_OPTION, load_house_argument
from adaptenv.cli._outputs import FORCE_OPTION, output_file, record_file

POLICIES = ("expert", "random")
_HOUSE = typer.Argument(..., metavar="HOUSE", help=HOUSE_HELP, show_default=False)
_OUT = typer.Option(Path("traj.json"), "-o", "--out", help="Where to write the trajectory JSON.")
UNITS = {"spl": "0..1", "sel": "0..1", "episode_length": "steps", "path_length": "m", "final_geodesic": "m",
         "collisions": "blocked moves", "min_clearance": "m", "rooms_visited": "rooms", "first_sight_step": "step",
         "optimal_path_length": "m", "expert_episode_length": "steps"}
"""Units of the metrics ``rollout`` prints."""
NOT_AVAILABLE = {"expert_episode_length": "the expert fails", "first_sight_step": "never in sight"}
"""What a metric without a value (n/a) means, printed in place of its unit."""
_RENDER = typer.Option(None, "--render", help="Also draw the trajectory top-down to this PNG.")


def resolve_policy(name: str, seed: int | None = None):
    """The policy called ``name``: anything ``adaptenv.agents.registry.resolve_policy`` accepts."""
    from adaptenv.agents.policy import as_step_policy
    from adaptenv.agents.registry import resolve_policy as resolve_agent

    return as_step_policy(resolve_agent(name, seed=0 if seed is None else seed))


def rollout(
    house: Path = _HOUSE,
    policy: str = typer.Option("pretrained", "--policy", help="Who acts: pretrained (the strongest shipped agent), pretrained-map, pretrained-scan, expert, explorer, map-explorer, random, a checkpoint (.pt) or module:attribute."),
    target: str | None = typer.Option(None, "--target", help="Target object type (default: drawn among the solvable ones)."),
    seed: int = typer.Option(0, "--seed", callback=numbers.seed, help="Seed of the episode draw (and of the random policy)."),
    use_house_start: bool = typer.Option(False, "--use-house-start", help="Start at the house's metadata agent pose."),
    max_steps: int | None = typer.Option(None, "--max-steps", min=1, help="Step limit (default: spec.MAX_STEPS = 600)."),
    out: Path = _OUT,
    render: Path | None = _RENDER,
    force: bool = FORCE_OPTION,
) -> None:
    """Run one episode, print its metrics and write the trajectory (optionally a top-down image)."""
    from rich.console import Console
    from rich.table import Table

    from adaptenv.sim.rollout import expert_episode_length, run_episode
    from adaptenv.sim.spec import MAX_STEPS
    from adaptenv.sim.task import sample_episode
    from adaptenv.sim.world import compile_world

    _, house_model = load_house_argument(house)
    output_file(out, "-o", "rollout", force=force, inputs=[house])
    if render is not None:
        output_file(render, "--render", "rollout", force=force, inputs=[house, out])
    world = compile_world(house_model, name=str(house))
    pol = resolve_policy(policy, seed)
    episode = sample_episode(world, seed, target_type=target, use_house_start=use_house_start)
    expert_length = expert_episode_length(world, episode, max_steps=max_steps or MAX_STEPS)
    traj = run_episode(world, episode, pol, max_steps=max_steps or MAX_STEPS, policy_name=policy,
                       expert_length=expert_length)
    traj.save(out)
    record_file(out, "rollout")
    table = Table(title=f"{policy} looking for {traj.target_type} in {house.name}")
    table.add_column("metric")
    table.add_column("value", justify="right")
    table.add_column("unit")
    for key, value in traj.metrics.model_dump().items():
        shown = "n/a" if value is None else f"{value:.3f}" if isinstance(value, float) else str(value)
        unit = NOT_AVAILABLE.get(key, "") if value is None else UNITS.get(key, "")
        table.add_row(key, shown, unit)
    console = Console()
    console.print(table)
    console.print(f"wrote the trajectory to [bold]{out}[/]")
    if render is not None:
        from adaptenv.render.topdown import render_house, save_render

        save_render(render_house(house_model, trajectory=traj), render)
        record_file(render, "rollout")
        console.print(f"wrote the top-down image to [bold]{render}[/]")


def bench_expert(
    episodes: int = typer.Option(500, "--episodes", min=1, help="Episodes to run."),
    houses: int = typer.Option(50, "--houses", min=1, help="Procedural houses to spread them over."),
    seed: int = typer.Option(0, "--seed", callback=numbers.seed, help="Root seed."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Shortest-path expert: success rate, SPL, labels/s and unsolvable episodes on generated houses."""
    from adaptenv.bench import emit
    from adaptenv.bench.expert import run

    figures, notes = run(episodes=episodes, n_houses=houses, seed=seed)
    emit("expert", figures, as_json, notes)


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.command("rollout")(rollout)
    bench.command("expert")(bench_expert)
