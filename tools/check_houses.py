"""Real-house conformance check: run every stage a researcher's houses go through and count what works.

Usage:
    python tools/check_houses.py HOUSES [HOUSES ...] [--episodes N] [--seed S] [--agent pretrained|none]
                                 [--assets FILE] [--skip-unknown-assets] [--check]

HOUSES is a folder of house JSON files, one house file, a dataset FILE.jsonl[.gz] (one house per line,
optionally sliced: FILE.jsonl.gz:0:100), or preset:NAME. For each set the script
runs, per house: load (parse and the semantic checks of ``adaptenv validate``), a save/load round
trip (the written document must parse back to the same JSON), compile and episode availability
(the ``load_house_set`` rule), then ``--episodes`` sampled episodes over the usable houses
(solvability, the shortest-path expert, and the pretrained agent), and prints one table of counts
and rates, then per set how many houses were read and how many were left out, and why. ``--check`` exits 1 when a house fails to load or round-trip, an episode cannot be
sampled in a usable house, or the expert solves fewer than ``--min-expert`` of the solvable
episodes (CI runs it on the procedural presets and tests/data; see docs/scene.md).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from rich.console import Console
from rich.table import Table

from adaptenv.agents.evaluate import run_episodes, sample_episodes
from adaptenv.agents.houses import SkippedHouse, usable_houses
from adaptenv.agents.network import configure_torch
from adaptenv.agents.policy import ExpertPolicy
from adaptenv.agents.registry import resolve_policy
from adaptenv.errors import AdaptenvError, HouseError
from adaptenv.scene.assets import skip_unknown_assets, use_assets
from adaptenv.scene.dataset import dataset_houses, parse_dataset_spec
from adaptenv.scene.house import House, parse_house, read_house_document, save_house
from adaptenv.scene.procedural import PRESETS, generate_preset
from adaptenv.scene.validate import validate_read_house
from adaptenv.sim.geodesic import is_solvable


@dataclass
class SetReport:
    """Counts of one house set, stage by stage."""

    spec: str
    houses: int = 0
    loaded: int = 0
    round_trip: int = 0
    usable: int = 0
    episodes: int = 0
    sampled: int = 0
    solvable: int = 0
    expert_success: int = 0
    agent_episodes: int = 0
    agent_success: int = 0
    failures: list[str] = field(default_factory=list)
    skipped: list[SkippedHouse] = field(default_factory=list)


def house_files(spec: str) -> list[tuple[str, House | Path | HouseError]]:
    """(name, house, file path, or the HouseError of a dataset line that is no house) of every house a spec names."""
    if spec.startswith("preset:"):
        name = spec.partition(":")[2]
        if name not in PRESETS:
            raise SystemExit(f"{spec}: unknown preset; use one of {', '.join('preset:' + p for p in PRESETS)}")
        return list(generate_preset(name))
    try:
        if (dataset := parse_dataset_spec(spec)) is not None:
            return list(dataset_houses(dataset, validate=False))  # load_one validates
    except AdaptenvError as exc:
        raise SystemExit(str(exc)) from None
    path = Path(spec)
    files = sorted(path.glob("*.json")) if path.is_dir() else [path]
    if not files or not all(f.is_file() for f in files):
        raise SystemExit(f"{spec}: no house JSON files there; pass a folder, a file, a FILE.jsonl.gz dataset or "
                         "preset:NAME")
    return [(f.stem, f) for f in files]


def load_one(item: House | Path | HouseError) -> House:
    """Parse and validate one house (HouseError lists its problems)."""
    if isinstance(item, HouseError):
        raise item
    if isinstance(item, House):
        problems = validate_read_house(item)
        house = item
    else:
        house = parse_house(read_house_document(item), str(item))
        problems = validate_read_house(house, file=str(item))
    if problems:
        raise HouseError(problems)
    return house


def round_trips(house: House, folder: Path) -> bool:
    """Whether saving and reloading the house gives back the same JSON document."""
    path = save_house(house, folder / "house.json")
    return parse_house(json.loads(path.read_text(encoding="utf-8"))).to_dict() == house.to_dict()


def check_set(spec: str, episodes: int, seed: int, agent) -> SetReport:
    """Run every stage over one house set."""
    rep = SetReport(spec)
    houses, names = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for name, item in house_files(spec):
            rep.houses += 1
            try:
                house = load_one(item)
            except AdaptenvError as exc:
                rep.failures.append(f"{name}: load: {exc}")
                continue
            rep.loaded += 1
            if round_trips(house, Path(tmp)):
                rep.round_trip += 1
            else:
                rep.failures.append(f"{name}: the saved house does not read back the same")
            houses.append(house)
            names.append(name)
    if not houses:
        rep.failures.append(f"none of the {rep.houses} houses read loaded, so none can be used")
        return rep
    try:
        _, worlds, rep.skipped = usable_houses(houses, names, spec=spec)
    except AdaptenvError as exc:
        rep.failures.append(str(exc))
        return rep
    rep.usable = len(worlds)
    eps = []
    for k in range(episodes):
        try:
            eps += sample_episodes(worlds, k + 1, seed, start=k)
        except AdaptenvError as exc:
            rep.failures.append(f"episode {k}: {exc}")
    rep.episodes, rep.sampled = episodes, len(eps)
    solvable = [(e, ep) for e, ep in eps if is_solvable(worlds[e], ep)]
    rep.solvable = len(solvable)
    if solvable:
        results, _ = run_episodes(worlds, solvable, ExpertPolicy())
        rep.expert_success = sum(r.success for r in results)
        rep.failures += [f"expert failed in {r.house} ({r.target_type}, episode seed {r.seed})"
                         for r in results if not r.success]
        if agent is not None:
            results, _ = run_episodes(worlds, solvable, agent)
            rep.agent_episodes, rep.agent_success = len(results), sum(r.success for r in results)
    return rep


def _rate(k: int, n: int) -> str:
    return f"{k}/{n} ({k / n:.1%})" if n else "0/0"


def print_table(reports: list[SetReport], console: Console) -> None:
    """One table: a row per stage, a column per house set (count/total and rate)."""
    table = Table(title="real-house conformance (counts and rates)")
    table.add_column("stage")
    for r in reports:
        table.add_column(f"{r.spec} ({r.houses} houses)", justify="right")
    rows = [("loaded and valid", lambda r: _rate(r.loaded, r.houses)),
            ("round trip", lambda r: _rate(r.round_trip, r.loaded)),
            ("usable (episodes exist)", lambda r: _rate(r.usable, r.loaded)),
            ("episodes sampled", lambda r: _rate(r.sampled, r.episodes)),
            ("solvable", lambda r: _rate(r.solvable, r.sampled)),
            ("expert success (solvable)", lambda r: _rate(r.expert_success, r.solvable)),
            ("agent success (solvable)", lambda r: _rate(r.agent_success, r.agent_episodes) if r.agent_episodes
             else "-")]
    for label, cell in rows:
        table.add_row(label, *[cell(r) for r in reports])
    console.print(table)
    for r in reports:
        console.print(f"{r.spec}: {counts_line(r)}", highlight=False)
        for s in r.skipped:
            console.print(f"{r.spec}: skipped {s.name}: {s.reason}", highlight=False)
        for f in r.failures[:10]:
            console.print(f"{r.spec}: {f}", highlight=False)
        if len(r.failures) > 10:
            console.print(f"{r.spec}: ... and {len(r.failures) - 10} more failure(s)", highlight=False)


def counts_line(r: SetReport) -> str:
    """How many houses a set read, and how many of them were left out at each stage (reasons follow)."""
    return (f"read {r.houses} house(s): {r.houses - r.loaded} left out at load (invalid or unreadable), "
            f"{len(r.skipped)} left out as unusable (no episode), {r.usable} usable")


def failed(reports: list[SetReport], min_expert: float) -> list[str]:
    """Why ``--check`` fails (empty when every set passes)."""
    out = []
    for r in reports:
        if r.loaded < r.houses or r.round_trip < r.loaded:
            out.append(f"{r.spec}: {r.houses - r.loaded} house(s) failed to load, "
                       f"{r.loaded - r.round_trip} to round-trip")
        if r.sampled < r.episodes:
            out.append(f"{r.spec}: {r.episodes - r.sampled} episode(s) could not be sampled in usable houses")
        if r.solvable and r.expert_success / r.solvable < min_expert:
            out.append(f"{r.spec}: the expert solved {r.expert_success / r.solvable:.1%} of solvable episodes, "
                       f"below --min-expert {min_expert:.1%}")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("houses", nargs="+", help="folders of house JSON files, house files, "
                        "datasets FILE.jsonl[.gz][:START:STOP], or preset:NAME")
    parser.add_argument("--episodes", type=int, default=100, help="episodes per set (default 100)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the episode draw (default 0)")
    parser.add_argument("--agent", default="pretrained",
                        help="policy to run besides the expert (any --policy spec), or none (default pretrained)")
    parser.add_argument("--assets", type=Path, action="append", default=[], help="user asset table(s)")
    parser.add_argument("--skip-unknown-assets", action="store_true",
                        help="leave out objects resting on others whose assets are unknown (as adaptenv's flag)")
    parser.add_argument("--check", action="store_true", help="exit 1 when a stage fails (for CI)")
    parser.add_argument("--min-expert", type=float, default=0.98,
                        help="with --check: least expert success on solvable episodes (default 0.98)")
    args = parser.parse_args(argv)
    if args.assets:
        use_assets(*args.assets)
    if args.skip_unknown_assets:
        skip_unknown_assets()
    configure_torch()  # one thread on a small machine: spinning OpenMP threads slow every small op
    agent = None if args.agent == "none" else resolve_policy(args.agent, seed=args.seed)
    console = Console(width=max(100, Console().width))
    reports = [check_set(spec, args.episodes, args.seed, agent) for spec in args.houses]
    print_table(reports, console)
    problems = failed(reports, args.min_expert) if args.check else []
    for p in problems:
        console.print(f"[red]check failed:[/] {p}", highlight=False)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
