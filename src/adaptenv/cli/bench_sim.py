"""``adaptenv bench sim``: simulator steps per second (batched and single env), clutter cost, memory.

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads
torch or numba.
"""

from __future__ import annotations

import typer

from adaptenv.cli import _numbers as numbers
from adaptenv.cli._common import JSON_OPTION


def bench_sim(
    batch: int = typer.Option(1024, "--batch", min=1, help="Agents stepped together by BatchSim."),
    seconds: float = typer.Option(2.0, "--seconds", min=0.1, help="Length of each timed repeat (s)."),
    repeats: int = typer.Option(5, "--repeats", min=1, help="Timed repeats per figure (the median is reported)."),
    p_end: float = typer.Option(0.01, "--p-end", min=0.0, max=1.0,
                                help="Probability of the random policy issuing `end` at each step."),
    seed: int = typer.Option(0, "--seed", callback=numbers.seed, help="Seed of the random actions and episodes."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Simulator throughput with the full observation, cost versus clutter, memory, MiniGrid alongside."""
    from adaptenv.bench import emit
    from adaptenv.bench.sim import run

    figures, notes = run(batch=batch, seconds=seconds, repeats=repeats, seed=seed, p_end=p_end)
    emit("simulator: steps per second, clutter cost, memory", figures, as_json, notes=notes)


def register(app: typer.Typer, bench: typer.Typer) -> None:
    bench.command("sim")(bench_sim)
