"""``adaptenv bench edits``: validated edits per second (placement + validation).

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads
torch or numba.
"""

from __future__ import annotations

from pathlib import Path

import typer

from adaptenv.cli import _numbers as numbers
from adaptenv.cli._common import JSON_OPTION

HOUSE_OPTION = typer.Option(None, "--house", help="A house JSON (or one dataset line, FILE.jsonl.gz:2:3) to use "
                            "instead of a procedural 5-room house.")


def bench_edits(
    n: int = typer.Option(2000, "--edits", min=10, help="How many random edit proposals to time."),
    seed: int = typer.Option(0, "--seed", callback=numbers.seed, help="Seed of the house and the proposals."),
    house: Path | None = HOUSE_OPTION,
    as_json: bool = JSON_OPTION,
) -> None:
    """Validated edits per second on one core for a 5-room house (collision-aware placement + validation)."""
    from adaptenv.bench import emit
    from adaptenv.bench.adapt_edits import TARGET_PER_SECOND, run

    h = None
    if house is not None:
        from adaptenv.cli._common import load_house_argument

        _, h = load_house_argument(house)
    figures = run(n, seed, h)
    emit("edits: collision-aware placement + validation", figures, as_json,
         notes=[f"target: at least {TARGET_PER_SECOND:,.0f} validated edits per second"])


def register(app: typer.Typer, bench: typer.Typer) -> None:
    bench.command("edits")(bench_edits)
