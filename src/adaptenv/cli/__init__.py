"""The ``adaptenv`` command line.

Each module in this package owns one group of commands and exposes ``register(app, bench)``;
they are discovered here, so adding a command never means editing this file. Commands keep heavy
imports inside their functions so that ``adaptenv --help`` stays fast. Errors adaptenv raises on
purpose (:class:`~adaptenv.errors.AdaptenvError`), and as a last resort file-system errors (``OSError``),
are printed as one line, without a traceback; so are click's usage errors (a number out of an option's range, an
unknown option), by :class:`_Root` (exit code 2).
Global options (``--assets``, ``--skip-unknown-assets``) are accepted before the command and after it:
:class:`_Root` gives every command a copy of them.
"""

from __future__ import annotations

import copy
import importlib
import pkgutil
import sys
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape
from typer.core import TyperGroup

from adaptenv.cli._outputs import release_folders
from adaptenv.cli._usage import on_one_line, typed_command, usage_in_one_line
from adaptenv.errors import AdaptenvError

HELP_STYLE = {"rich_markup_mode": None}
"""Plain (click) help for every command group: it wraps each option's help across the whole terminal
width, where rich's six-column option table leaves the help a few words wide in 80 columns."""

ASSETS_HELP = ("A JSON table of your own assets (asset id -> object type, bounding box, optional footprint) that "
               "extends the ProcTHOR catalog for every command; repeatable. Give it before or after the command: "
               "adaptenv --assets my_assets.json evaluate ... or adaptenv evaluate ... --assets my_assets.json")


SKIP_UNKNOWN_HELP = ("Load houses whose objects resting on others (children) have asset ids in neither the catalog "
                     "nor an --assets table by leaving those objects out, counted in one line; a house with such a "
                     "top-level object is still refused, naming it (it would block the agent unseen). For every "
                     "command, before or after it.")


def _skip_unknown(on: bool) -> None:
    """Turn on ``--skip-unknown-assets`` for this process and its workers."""
    if on:
        from adaptenv.scene.assets import skip_unknown_assets

        skip_unknown_assets()


def _use_assets(assets) -> None:
    """Extend the asset catalog with the ``--assets`` tables, for this process and its workers."""
    if assets:
        from adaptenv.scene.assets import use_assets

        use_assets(*assets)


class _Root(TyperGroup):
    """The ``adaptenv`` group: every command below it also takes the global options, after its name."""

    def __init__(self, **attrs) -> None:
        super().__init__(**attrs)
        assets = copy.copy(next(p for p in self.params if p.name == "assets"))  # the callback's --assets
        assets.expose_value, assets.help = False, "As adaptenv --assets FILE: your own asset table (repeatable)."
        assets.callback = lambda ctx, param, value: _use_assets(value)
        skip = copy.copy(next(p for p in self.params if p.name == "skip_unknown_assets"))
        skip.expose_value, skip.help = False, "As adaptenv --skip-unknown-assets: leave out unknown child objects."
        skip.callback = lambda ctx, param, value: _skip_unknown(value)
        groups = [self]
        while groups:
            for command in groups.pop().commands.values():
                if isinstance(command, TyperGroup):
                    groups.append(command)
                else:
                    command.params += [assets, skip]

    def make_context(self, info_name, args, parent=None, **extra):
        """Parse the global options; a usage error becomes one line (:mod:`adaptenv.cli._usage`)."""
        with usage_in_one_line():
            return super().make_context(info_name, args, parent, **extra)

    def invoke(self, ctx):
        """Run the command; a usage error any command raises (parsing its options, or later) becomes one line."""
        words = [*getattr(ctx, "_protected_args", getattr(ctx, "protected_args", [])), *ctx.args]
        try:
            with usage_in_one_line(typed_command(self, words)):
                return super().invoke(ctx)
        finally:  # the command has ended: its output folders are free for the next run
            release_folders()


app = typer.Typer(
    name="adaptenv",
    cls=_Root,
    help="Closed-loop, adaptive environment generation for embodied navigation agents.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    **HELP_STYLE,
)
bench = typer.Typer(help="Benchmarks: each prints a table, or one JSON object with --json.",
                    no_args_is_help=True, **HELP_STYLE)
app.add_typer(bench, name="bench")

err_console = Console(stderr=True, emoji=False)
"""Where the one-line errors go; no emoji codes, so a path such as ``d.jsonl:a:b`` prints as typed."""


@app.callback()
def _options(assets: list[Path] = typer.Option(None, "--assets", metavar="FILE", help=ASSETS_HELP),
             skip_unknown_assets: bool = typer.Option(False, "--skip-unknown-assets", help=SKIP_UNKNOWN_HELP)) -> None:
    """Closed-loop, adaptive environment generation for embodied navigation agents."""
    _use_assets(assets)
    _skip_unknown(skip_unknown_assets)


def _register_all() -> None:
    for mod in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if not mod.name.startswith("_"):
            importlib.import_module(f"{__name__}.{mod.name}").register(app, bench)


_register_all()


def main() -> None:
    """Console entry point: run the app, turning adaptenv and file-system errors into one red line and exit code 1."""
    try:
        app()
    except AdaptenvError as exc:
        err_console.print(f"[bold red]error:[/] {escape(on_one_line(str(exc)))}", highlight=False, soft_wrap=True)
        sys.exit(1)
    except KeyboardInterrupt:
        err_console.print("[yellow]interrupted[/]")
        sys.exit(130)
    except OSError as exc:  # a last resort: the commands check their output paths before any work
        err_console.print(f"[bold red]error:[/] {escape(on_one_line(os_error_text(exc)))}", highlight=False,
                          soft_wrap=True)
        sys.exit(1)


def os_error_text(exc: OSError) -> str:
    """One sentence for a file-system error: the path, what went wrong and what to do."""
    where = f"{exc.filename}: " if exc.filename is not None else ""
    return f"{where}{exc.strerror or exc}; check that the path exists and that you can read and write it"
