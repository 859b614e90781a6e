"""Resolve a ``--houses`` value (a folder, a file, a dataset, ``preset:NAME`` or ``suite:NAME``) into named compiled worlds.

A dataset is a ``.jsonl`` or ``.jsonl.gz`` file of houses, one per line (ProcTHOR-10K, SPOC), optionally
sliced: ``train.jsonl.gz:0:100`` (see :mod:`adaptenv.scene.dataset`); its houses are named
``house-000042`` by line index and read line by line.

``suite:NAME`` (see :mod:`adaptenv.agents.suites`) loads the suite's houses and attaches its episode
floor to ``HouseSet.worlds``, so :func:`adaptenv.agents.evaluate.sample_episodes` draws the suite's
episodes from it.

This is the one place that decides whether a house can be used for ObjectNav episodes: a house
that does not load, validate or compile, or in which no target type has an episode (no target, or
every target visible from everywhere), is skipped with one warning line naming it and the reason,
and listed in ``HouseSet.skipped``; ``strict=True`` (``--strict``) turns the first such house into
an error instead. ``evaluate``, ``train``, ``loop`` and ``experiment`` all load houses here.

With ``skip_unknown`` (``--skip-unknown-assets``; default: the process setting) objects resting on others
whose asset is in neither the catalog nor an ``--assets`` table are left out, counted in one warning line
for the whole set; a house whose top-level object has an unknown asset is still skipped, naming it.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

from adaptenv.agents.suites import SuiteWorlds, suite_spec
from adaptenv.errors import AdaptenvError, ConfigError
from adaptenv.scene.dataset import dataset_houses, parse_dataset_spec
from adaptenv.scene.house import House, load_house
from adaptenv.scene.procedural import PRESETS, generate_preset
from adaptenv.scene.validate import dropped_children_line
from adaptenv.sim.spec import TARGET_TYPES
from adaptenv.sim.task import available_targets, trivial_targets
from adaptenv.sim.world import NavWorld, compile_world

log = logging.getLogger(__name__)

HOUSES_HELP = ("Houses: a folder of house JSON files, one house file, a dataset FILE.jsonl[.gz] with an optional "
               "slice FILE.jsonl.gz:0:100, preset:NAME (e.g. preset:pretrain-train) or suite:NAME (e.g. "
               "suite:long-unseen).")
STRICT_HELP = "Fail on the first house that cannot be used instead of skipping it with a warning."


@dataclass(frozen=True)
class SkippedHouse:
    """A house left out of a set: its name (file stem or preset name) and why, as one sentence."""

    name: str
    reason: str


@dataclass
class HouseSet:
    """Houses and their compiled worlds, aligned, with the spec they came from and the houses skipped."""

    spec: str
    houses: list[House]
    worlds: list[NavWorld]
    skipped: list[SkippedHouse] = field(default_factory=list)
    dropped_children: int = 0
    """Objects resting on others left out for their unknown assets (``--skip-unknown-assets``)."""

    @property
    def names(self) -> list[str]:
        return [w.name for w in self.worlds]


def unusable_reason(world: NavWorld) -> str | None:
    """Why no ObjectNav episode can be drawn in a compiled house, or None when one can."""
    if available_targets(world):
        return None
    trivial = trivial_targets(world)
    if trivial:
        return (f"every reachable cell already sees the {', '.join(trivial)} and no other target type is "
                "solvable, so no episode can start away from a target")
    present = sorted(set(world.object_types) & set(TARGET_TYPES))
    if not present:
        off_floor = off_floor_targets(world)
        if off_floor:
            return (f"the house's only ObjectNav target objects are {off_floor}, and only objects standing on the "
                    "floor are targets")
        return f"the house has no ObjectNav target object (none of {', '.join(TARGET_TYPES)})"
    return f"no target object ({', '.join(present)}) can be seen from the reachable floor"


def off_floor_targets(world: NavWorld) -> str:
    """The target-type objects that are not targets because they are off the floor, as a phrase ('' if none):
    e.g. 'wall-mounted (Television)' or 'resting on other furniture (HousePlant)'."""
    geometry = world.geometry
    kinds = (("wall-mounted", [f for f in geometry.footprints if f.role == "wall"]),
             ("resting on other furniture", [c for cs in geometry.children.values() for c in cs]))
    phrases = []
    for kind, objects in kinds:
        types = sorted({f.object_type for f in objects} & set(TARGET_TYPES))
        if types:
            phrases.append(f"{kind} ({', '.join(types)})")
    return " or ".join(phrases)


def usable_houses(houses: Sequence[House | NavWorld | BaseException], names: Sequence[str], *, strict: bool = False,
                  spec: str = "houses") -> tuple[list[House | NavWorld], list[NavWorld], list[SkippedHouse]]:
    """Compile houses and keep those with at least one episode: (houses, worlds, skipped).

    An entry of ``houses`` may be an exception (a load error), which is skipped with its message.
    Each skip logs one warning line once some house is kept (when none is, the one error names the first);
    ``strict`` raises ConfigError on the first one instead.
    """
    kept_h, kept_w, skipped = [], [], []
    for house, name in zip(houses, names, strict=True):
        reason, world = None, None
        if isinstance(house, BaseException):
            reason = str(house)
        else:
            try:
                world = house if isinstance(house, NavWorld) else compile_world(house, name)
                reason = unusable_reason(world)
            except AdaptenvError as exc:
                reason = str(exc)
        if reason is None:
            kept_h.append(house)
            kept_w.append(world)
            continue
        if strict:
            raise ConfigError(f"--houses {spec}: house {name} cannot be used: {reason} "
                              "(drop --strict to skip such houses with a warning)")
        skipped.append(SkippedHouse(name, reason))
    if not kept_w and not skipped:
        raise ConfigError(f"--houses {spec}: the set holds no house")
    if not kept_w:
        first = f"; the first, {skipped[0].name}: {skipped[0].reason}" if skipped else ""
        raise ConfigError(f"--houses {spec}: none of the {len(skipped)} houses can be used for ObjectNav "
                          f"episodes{first}")
    for s in skipped:
        log.warning("skipping house %s: %s", s.name, s.reason)
    return kept_h, kept_w, skipped


def load_house_set(spec: str | Path, *, strict: bool = False, skip_unknown: bool | None = None) -> HouseSet:
    """Load and compile the houses named by ``spec`` (see module docstring), in a stable order.

    Houses that cannot be used are skipped (``HouseSet.skipped``) unless ``strict``; ``skip_unknown``
    leaves out objects of unknown assets resting on others (default: the process setting).
    """
    text = str(spec)
    if text.startswith("suite:"):
        suite = suite_spec(text.partition(":")[2])
        base = load_house_set(suite.houses, strict=strict, skip_unknown=skip_unknown)
        return HouseSet(text, base.houses, SuiteWorlds(base.worlds, suite.floor), base.skipped,
                        base.dropped_children)
    if text.startswith("preset:"):
        name = text.partition(":")[2]
        if name not in PRESETS:
            raise ConfigError(f"--houses {text!r}: unknown preset; choose one of "
                              + ", ".join(f"preset:{p}" for p in PRESETS))
        pairs = generate_preset(name)
    elif (dataset := parse_dataset_spec(text)) is not None:
        pairs = list(dataset_houses(dataset, skip_unknown=skip_unknown))
    else:
        pairs = [(f.stem, _try_load(partial(load_house, skip_unknown=skip_unknown), f)) for f in _house_files(text)]
    names = [n for n, _ in pairs]
    houses = [h for _, h in pairs]
    read = [h for h in houses if isinstance(h, House)]
    if line := dropped_children_line(read, of=len(pairs)):
        log.warning("--houses %s: %s", text, line)
    houses, worlds, skipped = usable_houses(houses, names, strict=strict, spec=text)
    dropped = sum(len(h.dropped_children) for h in read)
    return HouseSet(text, houses, worlds, skipped, dropped)


def _house_files(text: str) -> list[Path]:
    """The house files of a folder (its ``*.json``, sorted) or of one file; ConfigError when there are none."""
    path = Path(text)
    if path.is_dir():
        files = sorted(path.glob("*.json"))
        if not files:
            raise ConfigError(f"--houses {path}: the folder holds no *.json house files")
        return files
    if path.is_file():
        return [path]
    raise ConfigError(f"--houses {text!r}: no such folder or file; pass a folder of house JSON files, a "
                      "FILE.jsonl.gz dataset or preset:NAME")


def _try_load(load, path: Path) -> House | AdaptenvError:
    """The loaded house, or the AdaptenvError that loading raised (skipped later, with its message)."""
    try:
        return load(path)
    except AdaptenvError as exc:
        return exc


def compile_houses(houses: Sequence[House | NavWorld], names: Sequence[str] | None = None) -> list[NavWorld]:
    """``compile_world`` each house (objects that are already NavWorlds pass through)."""
    names = list(names) if names is not None else [f"house-{i:03d}" for i in range(len(houses))]
    return [h if isinstance(h, NavWorld) else compile_world(h, n) for h, n in zip(houses, names, strict=True)]
