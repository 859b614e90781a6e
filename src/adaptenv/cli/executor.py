"""``adaptenv bench executor``: speedup of the process pool and Ray from 1 to 2 workers.

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads
torch or numba.
"""

from __future__ import annotations

from typing import Literal

import typer

from adaptenv.cli._common import JSON_OPTION

KIND_OPTION = typer.Option(None, "--kind", help="Only this executor (default: process, and ray when installed).")
ITEMS_OPTION = typer.Option(None, "--items", min=2, help="Items per timed map: levels (default 16) or "
                            "evaluation chunks of 50 episodes (default 8).")
WORKLOAD_OPTION = typer.Option("levels", "--workload", help="levels: expert episodes in generated houses; "
                               "heldout: the loop's held-out evaluation jobs (shipped policy).")
REPEATS_OPTION = typer.Option(3, "--repeats", min=1, help="Timed maps per configuration (the median is printed).")


def bench_executor(kind: Literal["process", "ray"] | None = KIND_OPTION, n_items: int | None = ITEMS_OPTION,
                   repeats: int = REPEATS_OPTION, workload: Literal["levels", "heldout"] = WORKLOAD_OPTION,
                   as_json: bool = JSON_OPTION) -> None:
    """Speedup from 1 to 2 workers (process pool and Ray) on the closed loop's work."""
    import importlib.util

    from adaptenv.bench import emit
    from adaptenv.bench.executor import run

    notes = ["target: speedup 1->2 >= 1.6x on a 2-core machine; overhead per item = (1-worker time - "
             "in-process time) / items"]
    if kind is not None:
        kinds: tuple[str, ...] = (kind,)
    elif importlib.util.find_spec("ray") is not None:
        kinds = ("process", "ray")
    else:
        kinds = ("process",)
        notes.append("ray is not installed, so it was skipped (pip install 'adaptenv[ray]')")
    figures = run(kinds, n_items=n_items, repeats=repeats, workload=workload)
    title = {"levels": "expert episodes in generated houses", "heldout": "the loop's held-out evaluation jobs"}
    emit(f"executor: {title[workload]} (median wall time)", figures, as_json, notes=notes)


def register(app: typer.Typer, bench: typer.Typer) -> None:
    bench.command("executor")(bench_executor)
