"""``adaptenv houses``: generate procedural ProcTHOR-format houses and rearranged variants, and split
house datasets (one house JSON per line) into house files.

Also registers ``adaptenv bench houses`` (generation speed).

Commands import their dependencies when they run, so ``adaptenv --help`` stays fast and never loads
torch or numba.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Annotated

import typer
from typer.core import TyperCommand

from adaptenv.cli import _numbers as numbers
from adaptenv.cli._common import JSON_OPTION, load_house_argument
from adaptenv.cli._outputs import FORCE_OPTION, output_file, output_folder, record_file
from adaptenv.errors import ConfigError

houses_app = typer.Typer(help="ProcTHOR-format houses: generate new ones, rearrange existing ones, split datasets "
                              "into house files.",
                         no_args_is_help=True, rich_markup_mode=None)  # plain help, like adaptenv.cli.HELP_STYLE

_ROOMS_HELP = ("Rooms per house: a count from 1 to 10 (e.g. 5) or a comma-separated list of types "
               "(e.g. Kitchen,LivingRoom,Bedroom). Default: 2 to 6 rooms.")


def _config_for(rooms: str | None, split: str):
    """The generation config for the --rooms and --split options, with errors naming the option."""
    from adaptenv.scene.assets import ROOM_TYPES
    from adaptenv.scene.procedural import GenerationConfig
    from adaptenv.scene.procedural.config import MAX_ROOMS, MIN_ROOMS, SPLITS

    if split not in SPLITS:
        raise ConfigError(f"--split: unknown asset split {split!r}; use one of {', '.join(SPLITS)}")
    cfg = GenerationConfig(split=split)
    if rooms is None:
        return cfg
    text = rooms.strip()
    if text.lstrip("-").isdigit():
        n = int(text)
        if not MIN_ROOMS <= n <= MAX_ROOMS:
            raise ConfigError(f"--rooms: expected {MIN_ROOMS} to {MAX_ROOMS} rooms, got {n}; pick a count in that range")
        return cfg.with_rooms(n)
    types = [t.strip() for t in text.split(",") if t.strip()]
    bad = [t for t in types if t not in ROOM_TYPES]
    if bad or not types:
        raise ConfigError(f"--rooms: unknown room type {bad[0] if bad else text!r}; give a count or a comma-separated "
                          f"list of {', '.join(ROOM_TYPES)}")
    if len(types) > MAX_ROOMS:
        raise ConfigError(f"--rooms: {len(types)} room types given; give at most {MAX_ROOMS}")
    return cfg.with_rooms(",".join(types))


def _summary_row(name: str, house) -> tuple[str, str, str, str]:
    from adaptenv.scene.assets import load_catalog
    from adaptenv.sim.spec import TARGET_TYPES

    catalog = load_catalog()
    abbrev = {"Kitchen": "K", "LivingRoom": "L", "Bedroom": "B", "Bathroom": "b"}
    types = sorted({catalog.asset(o.assetId).object_type for o in house.objects} & set(TARGET_TYPES))
    rooms = "".join(abbrev.get(r.roomType, "?") for r in house.rooms)
    return name, f"{len(house.rooms)} ({rooms})", str(len(house.objects)), ", ".join(types)


def _print_summary(rows: list[tuple[str, str, str, str]], out: Path) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"houses written to {out}")
    for col, justify in (("house", "left"), ("rooms", "left"), ("objects", "right"), ("target types", "left")):
        table.add_column(col, justify=justify)
    for row in rows:
        table.add_row(*row)
    console = Console()
    console.print(table)
    console.print("rooms: K kitchen, L living room, B bedroom, b bathroom", style="dim")


class _GenerateCommand(TyperCommand):
    """``houses generate``, whose --preset help lists the preset registry's names when help is shown (importing
    the registry takes most of a second, too long for every command line)."""

    def format_help(self, ctx: typer.Context, formatter) -> None:
        from adaptenv.scene.procedural.presets import PRESETS

        names = "\n".join(textwrap.wrap(", ".join(PRESETS), 40, break_on_hyphens=False))
        for param in self.params:
            if param.name == "preset":  # \b: click keeps the lines, so no name is split at its hyphen
                param.help = ("A named house set (ignores --n, --seed and --rooms; docs/houses.md), one of:"
                              f"\n\n\b\n{names}")
        super().format_help(ctx, formatter)


@houses_app.command("generate", cls=_GenerateCommand)
def generate(
    out: Annotated[Path, typer.Option("-o", "--out", help="Folder to write house_0000.json, ... (or the preset's names) to.")],
    n: Annotated[int, typer.Option("--n", help="Number of houses (ignored with --preset).")] = 1,
    seed: Annotated[int, typer.Option("--seed", callback=numbers.seed, help="Root seed: the same seed gives byte-identical houses.")] = 0,
    rooms: Annotated[str | None, typer.Option("--rooms", help=_ROOMS_HELP)] = None,
    preset: Annotated[str | None, typer.Option("--preset", help="A named house set (listed by --help).")] = None,
    split: Annotated[str, typer.Option("--split", help="ProcTHOR asset split the furniture comes from.")] = "train",
    force: bool = FORCE_OPTION,
) -> None:
    """Generate procedural ProcTHOR-format houses (loadable in AI2-THOR >= 5.0)."""
    from adaptenv.progress import ProgressBar
    from adaptenv.scene.house import save_house
    from adaptenv.scene.procedural import child_seeds, generate_house, generate_preset
    from adaptenv.scene.procedural.presets import PRESETS

    if n < 1 or n > 100_000:
        raise ConfigError(f"--n: expected 1 to 100000 houses, got {n}")
    if seed < 0:
        raise ConfigError(f"--seed: expected a non-negative integer, got {seed}")
    if out.exists() and not out.is_dir():
        raise ConfigError(f"{out}: exists and is not a folder; pass a folder to -o")
    folder = output_folder(out, "-o", "houses generate", force=force)
    if preset is not None and preset not in PRESETS:
        raise ConfigError(f"--preset: unknown preset {preset!r}; use one of {', '.join(PRESETS)}")
    cfg = _config_for(rooms, split) if preset is None else None  # check the options before any output
    rows = []
    if preset is not None:
        with ProgressBar(f"generating {preset}", PRESETS[preset].n_houses) as bar:
            named = generate_preset(preset, on_house=lambda i, total: bar.update(i + 1, total=total))
    else:
        with ProgressBar("generating houses", n) as bar:
            named = []
            for i, s in enumerate(child_seeds(seed, n)):
                named.append((f"house_{i:04d}", generate_house(s, cfg)))
                bar.advance()
    with folder:
        out.mkdir(parents=True, exist_ok=True)
        for name, house in named:
            save_house(house, out / f"{name}.json")
            rows.append(_summary_row(name, house))
    _print_summary(rows, out)


@houses_app.command("rearrange")
def rearrange(
    house_path: Annotated[Path, typer.Argument(metavar="HOUSE", help="The house to rearrange: a house JSON file or "
                                               "one line of a dataset, e.g. FILE.jsonl.gz:2:3.")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Where to write the rearranged house (a .json file).")],
    seed: Annotated[int, typer.Option("--seed", callback=numbers.seed, help="Seed of the new arrangement.")] = 0,
    force: bool = FORCE_OPTION,
) -> None:
    """Place a house's movable furniture anew (same rooms, doors, fixtures and target types)."""
    from rich.console import Console

    from adaptenv.scene.house import save_house
    from adaptenv.scene.procedural import rearrange_house

    if seed < 0:
        raise ConfigError(f"--seed: expected a non-negative integer, got {seed}")
    if out.suffix.lower() != ".json":
        raise ConfigError(f"{out}: the output must be a .json file; pass e.g. -o rearranged.json")
    output_file(out, "-o", "houses rearrange", force=force, inputs=[house_path])
    _, house = load_house_argument(house_path)
    new = rearrange_house(house, seed)
    save_house(new, out)
    record_file(out, "houses rearrange")
    old = {o.id: o.position for o in house.objects}
    moved = sum(1 for o in new.objects if o.id in old and old[o.id] != o.position)
    Console().print(f"wrote [bold]{out}[/]: {len(new.objects)} objects, {moved} moved")


@houses_app.command("export")
def export(
    dataset: Annotated[str, typer.Argument(metavar="DATASET", help="A house dataset FILE.jsonl or FILE.jsonl.gz (one "
                                           "house JSON per line), optionally sliced by 0-based line index as in "
                                           "Python: FILE.jsonl.gz:0:100 is lines 0 to 99.", show_default=False)],
    out: Annotated[Path, typer.Option("-o", "--out", help="Folder to write house-000042.json, ... to (named by "
                                      "line index).")],
    force: bool = FORCE_OPTION,
) -> None:
    """Split a house dataset (ProcTHOR-10K, SPOC: one house JSON per line) into a folder of house files."""
    from rich.console import Console

    from adaptenv.scene.dataset import dataset_documents, house_name, line_label, parse_dataset_spec
    from adaptenv.scene.house import parse_house, save_house

    ds = parse_dataset_spec(dataset)
    if ds is None:
        raise ConfigError(f"{dataset}: not a house dataset; pass a .jsonl or .jsonl.gz file, optionally sliced as "
                          "in FILE.jsonl.gz:0:100")
    if out.exists() and not out.is_dir():
        raise ConfigError(f"{out}: exists and is not a folder; pass a folder to -o")
    names = []
    with output_folder(out, "-o", "houses export", force=force, inputs=[ds.path]):
        for index, doc in dataset_documents(ds):
            names.append(house_name(index))
            save_house(parse_house(doc, line_label(ds.path, index)), out / f"{names[-1]}.json")
    Console().print(f"wrote {len(names)} house files to [bold]{out}[/] ({names[0]}.json to {names[-1]}.json)",
                    highlight=False)


def bench_houses(as_json: bool = JSON_OPTION,
                 houses: Annotated[int, typer.Option("--houses", min=5, help="Houses timed per room count.")] = 20,
                 ) -> None:
    """Median time to generate a 5-room and a 10-room procedural house."""
    from adaptenv.bench.houses import run

    run(as_json, houses)


def register(app: typer.Typer, bench: typer.Typer) -> None:
    app.add_typer(houses_app, name="houses")
    bench.command("houses")(bench_houses)
