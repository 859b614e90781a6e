"""``adaptenv validate``: list every problem of one or more house files (and ``adaptenv bench validate``).

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads
torch or numba.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from adaptenv.cli._common import JSON_OPTION
from adaptenv.cli._usage import on_one_line

HOUSES_ARGUMENT = typer.Argument(..., metavar="HOUSE.json", help="House files to check, or house datasets "
                                 "FILE.jsonl[.gz][:START:STOP] (every selected line is checked).", show_default=False)
HOUSE_ARGUMENT = typer.Argument(..., metavar="HOUSE", help="A house file, or one line of a dataset "
                                "(FILE.jsonl.gz:2:3), to validate repeatedly.")
VALIDATE_JSON_OPTION = typer.Option(False, "--json", help="Print the problems as one JSON object.")


def validate(
    houses: list[Path] = HOUSES_ARGUMENT,
    as_json: bool = VALIDATE_JSON_OPTION,
) -> None:
    """Check ProcTHOR house files; print every problem and exit 1 if there is any."""
    from adaptenv.scene.dataset import parse_dataset_spec
    from adaptenv.scene.validate import dropped_children_line

    read = [item for path in houses for item in _house_problems(path)]
    checked = [problems for _, problems in read]
    parsed = [h for h, _ in read if h is not None]
    problems = [p for ps in checked for p in ps]
    bad_files = sum(bool(ps) for ps in checked)
    unit = "house" if any(parse_dataset_spec(path) for path in houses) else "file"
    left_out = dropped_children_line(parsed, of=len(read) if len(read) > 1 else None)
    if as_json:
        dropped = [d for h in parsed for d in h.dropped_children]
        doc = {"files": [str(p) for p in houses], "valid": not problems,
               "problems": [{"file": p.file, "path": p.path, "message": p.message} for p in problems],
               "left_out": {"objects": len(dropped), "houses": sum(bool(h.dropped_children) for h in parsed),
                            "asset_ids": sorted({a for _, a in dropped})}}
        typer.echo(json.dumps(doc, indent=1))
    else:
        for p in problems:
            typer.echo(on_one_line(str(p)))
        n = len(checked)
        if problems:
            typer.echo(f"{len(problems)} problem{'s' if len(problems) != 1 else ''} in {bad_files} of {n} "
                       f"{unit}{'s' if n != 1 else ''}")
        else:
            typer.echo(f"{n} {unit}{'s' if n != 1 else ''} valid")
        if left_out:
            typer.echo(left_out)
    if problems:
        raise typer.Exit(1)


def _house_problems(path: Path) -> list[tuple]:
    """(house or None, problems) of each house a HOUSE argument names: one file, or every selected line of a
    dataset (the house is None where it could not be read, or, in a dataset, is invalid)."""
    from adaptenv.errors import HouseError
    from adaptenv.scene.dataset import dataset_houses, parse_dataset_spec
    from adaptenv.scene.validate import read_and_validate

    dataset = parse_dataset_spec(path)
    if dataset is None:
        return [read_and_validate(path)]
    return [(None, house.problems) if isinstance(house, HouseError) else (house, [])
            for _, house in dataset_houses(dataset)]


def bench_validate(
    house: Path = HOUSE_ARGUMENT,
    repeats: int = typer.Option(20, "--repeats", min=1, help="Timed runs (the median is reported)."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Time house validation and scene-graph construction on one house."""
    from adaptenv.bench import emit, median_time
    from adaptenv.cli._common import load_house_argument
    from adaptenv.scene.geometry import SceneGeometry
    from adaptenv.scene.graph import build_scene_graph
    from adaptenv.scene.validate import validate_house

    _, h = load_house_argument(house)
    geometry = SceneGeometry.from_house(h)
    graph = build_scene_graph(h, geometry)
    figures = {
        "objects": len(graph.nodes),
        "relations": len(graph.relations),
        "validate_ms": 1000 * median_time(lambda: validate_house(h), repeats),
        "scene_graph_ms": 1000 * median_time(lambda: build_scene_graph(h, geometry), repeats),
    }
    emit(f"validate {house.name}", figures, as_json)


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.command("validate")(validate)
    bench.command("validate")(bench_validate)
