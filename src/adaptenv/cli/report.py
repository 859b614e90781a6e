"""``adaptenv report``: an offline HTML report of a closed-loop run or an experiment folder.

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads
torch or numba.
"""

from __future__ import annotations

from pathlib import Path

import typer

from adaptenv.cli._outputs import FORCE_OPTION, output_folder

FOLDER_ARGUMENT = typer.Argument(..., metavar="RUN_OR_EXPERIMENT_DIR", show_default=False,
                                 help="A run folder (run.json, iterations.jsonl) or an experiment folder "
                                      "(<method>/seed_<s>/ run folders).")
OUT_OPTION = typer.Option(None, "-o", "--out", metavar="OUT_DIR",
                          help="Folder to write the report into (default: <folder>/report).")


def report(folder: Path = FOLDER_ARGUMENT, out: Path | None = OUT_OPTION, force: bool = FORCE_OPTION) -> None:
    """Write an HTML report (curves, results table, before/after gallery) and print index.html's path."""
    from adaptenv.report import build_report
    from adaptenv.report.data import detect
    from adaptenv.report.html import OWNS

    if not folder.is_dir():  # named before its default report folder, folder/report, is made (and locked)
        detect(folder)
    target = out if out is not None else folder / "report"
    with output_folder(target, "-o", "report", force=force, inputs=[folder], owns=OWNS):
        index = build_report(folder, out)
    print(index)


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.command("report")(report)
