"""``adaptenv assets``: build the ``--assets`` table of your own assets from other tools' files.

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from adaptenv.cli._outputs import FORCE_OPTION, output_file, record_file
from adaptenv.errors import ConfigError

assets_app = typer.Typer(help="Asset tables for --assets: build one from objathor's annotations.",
                         no_args_is_help=True, rich_markup_mode=None)  # plain help, like adaptenv.cli.HELP_STYLE


@assets_app.command("from-objathor")
def from_objathor(
    annotations: Path = typer.Argument(..., metavar="ANNOTATIONS", show_default=False,
                                       help="objathor's annotations.json.gz (python -m "
                                            "objathor.dataset.download_annotations --version 2023_07_28)."),
    out: Path = typer.Option(..., "-o", "--out", metavar="TABLE", help="Where to write the asset table (JSON)."),
    unmapped: str = typer.Option("keep", "--unmapped", help="keep (type assets that name no catalog type "
                                 "RoomDecor, with a note) or skip them."),
    as_json: bool = typer.Option(False, "--json", help="Print the counts as one JSON object."),
    force: bool = FORCE_OPTION,
) -> None:
    """Build the --assets table of Objaverse-asset houses (SPOC's ProcTHOR-Objaverse) from objathor's annotations.

    Sizes are AI2-THOR's bounding boxes from the annotations; types are mapped to the catalog's from
    ref_category, most_specific_lemma, synset or category. Then: adaptenv --assets TABLE evaluate ...
    """
    from rich.console import Console

    from adaptenv.scene.objathor import FALLBACK_TYPE, objathor_table

    if unmapped not in ("keep", "skip"):
        raise ConfigError(f"--unmapped {unmapped!r}: use keep or skip")
    output_file(out, "-o", "assets from-objathor", force=force, inputs=[annotations])
    table = objathor_table(annotations, out, unmapped=unmapped)
    record_file(out, "assets from-objathor")
    counts = {"written": len(table.assets), "mapped_by": table.mapped_by, "unmapped": len(table.unmapped),
              "unmapped_kept_as": FALLBACK_TYPE if unmapped == "keep" else None, "skipped_no_size": len(table.no_size),
              "table": str(out)}
    if as_json:
        typer.echo(json.dumps(counts, indent=1))
        return
    by = ", ".join(f"{n} by {k}" for k, n in sorted(table.mapped_by.items())) or "none"
    fate = f"typed {FALLBACK_TYPE} (see each row's note)" if unmapped == "keep" else "left out"
    Console().print(f"wrote [bold]{out}[/]: {len(table.assets)} assets; types mapped: {by}; "
                    f"{len(table.unmapped)} named no catalog type, {fate}; "
                    f"{len(table.no_size)} left out without a usable size (none, not finite, or over 100 m)", highlight=False)


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.add_typer(assets_app, name="assets")
