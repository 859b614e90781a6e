"""``adaptenv memory-check``: does the agent use long memory? Wipe it every K steps and compare success.

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads
torch or numba.
"""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Any

import typer

from adaptenv.cli import _numbers as numbers
from adaptenv.cli._outputs import FORCE_OPTION
from adaptenv.files import atomic_write_text


def memory_check(
    policy: str = typer.Option("pretrained", "--policy", "-p", help="Policy: pretrained, a checkpoint path (.pt), "
                               "or module:attribute with forget(state, indices) or an array state."),
    houses: str = typer.Option(..., "--houses", help="Folder of house JSON files, a house file, a dataset "
                               "FILE.jsonl[.gz][:START:STOP], preset:NAME or suite:NAME."),
    episodes: int = typer.Option(200, "--episodes", "-n", callback=numbers.episodes, help="Episodes per interval (the same episodes "
                                 "for every interval)."),
    seed: int = typer.Option(0, "--seed", "-s", callback=numbers.seed, help="Seed of the episodes (same seed, same results)."),
    every: list[int] = typer.Option([128, 32, 8], "--every", help="Wipe interval K in steps; repeat for several "
                                    "(never wiping always runs as the baseline)."),
    workers: int = typer.Option(1, "--workers", "-w", min=1, help="Worker processes (episodes are split among them)."),
    batch: int = typer.Option(64, "--batch", min=1, help="Episodes simulated at once per process."),
    out: Path | None = typer.Option(None, "-o", "--out", help="Also write OUT/memory_check.json."),
    force: bool = FORCE_OPTION,
) -> None:
    """Wipe the policy's memory every K steps of each episode: success, SPL and the paired drop from never.

    The last column is the paired difference in success from never wiping, +- its 95% interval.
    """
    import json

    from rich.console import Console

    from adaptenv.agents.memory import memory_check as run_check
    from adaptenv.agents.memory import wipe_intervals
    from adaptenv.agents.network import configure_torch
    from adaptenv.cli._common import writable_folder
    from adaptenv.cli._outputs import output_file, record_file
    from adaptenv.progress import ProgressBar

    ks = wipe_intervals(every, "--every")
    if out is not None:
        writable_folder(out, "-o")
        output_file(out / "memory_check.json", "-o", "memory-check", force=force, inputs=[policy, houses])
    configure_torch()
    command = shlex.join(["adaptenv", "memory-check", "--policy", policy, "--houses", houses, "-n", str(episodes),
                          "--seed", str(seed), *[a for k in ks[1:] for a in ("--every", str(k))],
                          "--workers", str(workers), "--batch", str(batch), *(["-o", str(out)] if out else [])])
    with ProgressBar(f"{policy} on {houses}, {len(ks)} wipe intervals", episodes * len(ks)) as bar:
        result = run_check(policy, houses, episodes, ks, seed=seed, workers=workers, batch=batch, progress=bar.update)
    result["command"] = command
    console = Console()
    console.print(memory_table(result))
    if out is not None:
        atomic_write_text(out / "memory_check.json", json.dumps(result, indent=1, default=float) + "\n")
        record_file(out / "memory_check.json", "memory-check")
        console.print(f"wrote [bold]{out / 'memory_check.json'}[/]")


def memory_table(result: dict[str, Any]):
    """A rich table of a memory check: K, success, SPL, length, paired success difference from never +- 95% CI."""
    from rich.table import Table

    table = Table(title=f"{result['policy']} on {result['houses']} ({result['floor']}): {result['episodes']} "
                  f"episodes, seed {result['seed']}")
    for col in ("wipe every", "success", "SPL", "length", "vs never (95%)"):
        table.add_column(col, justify="right")
    for r in result["runs"]:
        d = r["success_diff"]
        diff = "-" if r["every"] == 0 else f"{d['diff']:+.3f} +- {(d['ci95'][1] - d['ci95'][0]) / 2:.3f}"
        table.add_row("never" if r["every"] == 0 else str(r["every"]), f"{r['success']:.3f} +- {r['success_se']:.3f}",
                      f"{r['spl']:.3f} +- {r['spl_se']:.3f}", f"{r['steps']:.0f}", diff)
    return table


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.command("memory-check")(memory_check)
