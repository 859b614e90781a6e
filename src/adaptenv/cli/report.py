"""``adaptenv report``: an offline HTML report of a closed-loop run or an experiment folder.

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads
torch or numba.
"""

from __future__ import annotations

from pathlib import Path

import typer

FOLDER_ARGUMENT = typer.Argument(..., metavar="RUN_OR_EXPERIMENT_DIR", show_default=False,
                                 help="A run folder (run.json, iterations.jsonl) or an experiment folder "
                                      "(<method>/seed_<s>/ run folders).")
OUT_OPTION = typer.Option(None, "-o", "--out", metavar="OUT_DIR",
                          help="Folder to write the report into (default: <folder>/report).")


def report(folder: Path = FOLDER_ARGUMENT, out: Path | None = OUT_OPTION) -> None:
    """Write an HTML report (curves, results table, before/after gallery) and print index.html's path."""
    from adaptenv.cli._common import writable_folder
    from adaptenv.report import build_report

    writable_folder(out if out is not None else folder / "report", "-o")
    print(build_report(folder, out))


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.command("report")(report)
