"""Benchmark helpers: timing with medians and one way to print results (table or JSON).

Speed targets live here and in docs/BENCHMARKS.md, never in unit tests.

rich is imported only when a table is printed (``--json`` output does without it).
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import time
from collections.abc import Callable
from typing import Any


def machine() -> dict[str, Any]:
    """What the figures were measured on."""
    return {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform(),
            "processor": platform.processor() or platform.machine()}


def median_time(fn: Callable[[], Any], repeats: int = 5, warmup: int = 1) -> float:
    """Median wall time (s) of ``fn()`` over ``repeats`` runs after ``warmup`` unmeasured runs."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def emit(title: str, figures: dict[str, Any], as_json: bool, notes: list[str] | None = None) -> None:
    """Print named figures as a rich table, or as one JSON object (with the machine) when ``as_json``."""
    if as_json:
        print(json.dumps({"benchmark": title, **figures, "machine": machine()}, default=float))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title)
    table.add_column("figure")
    table.add_column("value", justify="right")
    for key, value in figures.items():
        text = f"{value:,.4g}" if isinstance(value, float) else str(value)
        table.add_row(key, text)
    console = Console()
    console.print(table)
    for note in notes or []:
        console.print(note)
