"""The ``adaptenv`` command line.

Each module in this package owns one group of commands and exposes ``register(app, bench)``;
they are discovered here, so adding a command never means editing this file. Commands keep heavy
imports inside their functions so that ``adaptenv --help`` stays fast. Errors adaptenv raises on
purpose (:class:`~adaptenv.errors.AdaptenvError`) are printed as one line, without a traceback.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape

from adaptenv.errors import AdaptenvError

HELP_STYLE = {"rich_markup_mode": None}
"""Plain (click) help for every command group: it wraps each option's help across the whole terminal
width, where rich's six-column option table leaves the help a few words wide in 80 columns."""

app = typer.Typer(
    name="adaptenv",
    help="Closed-loop, adaptive environment generation for embodied navigation agents.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    **HELP_STYLE,
)
bench = typer.Typer(help="Benchmarks: each prints a table, or one JSON object with --json.",
                    no_args_is_help=True, **HELP_STYLE)
app.add_typer(bench, name="bench")

err_console = Console(stderr=True)


@app.callback()
def _options(assets: list[Path] = typer.Option(
        None, "--assets", metavar="FILE", help="A JSON table of your own assets (asset id -> object type, bounding "
        "box, optional footprint) that extends the ProcTHOR catalog for every command; repeatable. Give it "
        "before the command: adaptenv --assets my_assets.json evaluate ...")) -> None:
    """Closed-loop, adaptive environment generation for embodied navigation agents."""
    if assets:
        from adaptenv.scene.assets import use_assets

        use_assets(*assets)


def _register_all() -> None:
    for mod in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if not mod.name.startswith("_"):
            importlib.import_module(f"{__name__}.{mod.name}").register(app, bench)


_register_all()


def main() -> None:
    """Console entry point: run the app, turning adaptenv errors into one red line and exit code 1."""
    try:
        app()
    except AdaptenvError as exc:
        err_console.print(f"[bold red]error:[/] {escape(str(exc))}", highlight=False, soft_wrap=True)
        sys.exit(1)
    except KeyboardInterrupt:
        err_console.print("[yellow]interrupted[/]")
        sys.exit(130)
