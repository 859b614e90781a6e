"""Resolve a ``--houses`` value (a folder, a file, ``preset:NAME`` or ``suite:NAME``) into named compiled worlds.

``suite:NAME`` (see :mod:`adaptenv.agents.suites`) loads the suite's houses and attaches its episode
floor to ``HouseSet.worlds``, so :func:`adaptenv.agents.evaluate.sample_episodes` draws the suite's
episodes from it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from adaptenv.agents.suites import SuiteWorlds, suite_spec
from adaptenv.errors import ConfigError
from adaptenv.scene.house import House, load_house
from adaptenv.scene.procedural import PRESETS, generate_preset
from adaptenv.sim.world import NavWorld, compile_world

HOUSES_HELP = ("Houses: a folder of house JSON files, one house file, preset:NAME (e.g. preset:pretrain-train) "
               "or suite:NAME (e.g. suite:long-unseen).")


@dataclass
class HouseSet:
    """Houses and their compiled worlds, aligned, with the spec they came from."""

    spec: str
    houses: list[House]
    worlds: list[NavWorld]

    @property
    def names(self) -> list[str]:
        return [w.name for w in self.worlds]


def load_house_set(spec: str | Path) -> HouseSet:
    """Load and compile the houses named by ``spec`` (see module docstring), in a stable order."""
    text = str(spec)
    if text.startswith("suite:"):
        suite = suite_spec(text.partition(":")[2])
        base = load_house_set(suite.houses)
        return HouseSet(text, base.houses, SuiteWorlds(base.worlds, suite.floor))
    if text.startswith("preset:"):
        name = text.partition(":")[2]
        if name not in PRESETS:
            raise ConfigError(f"--houses {text!r}: unknown preset; choose one of "
                              + ", ".join(f"preset:{p}" for p in PRESETS))
        pairs = generate_preset(name)
        names = [n for n, _ in pairs]
        houses = [h for _, h in pairs]
    else:
        path = Path(text)
        if path.is_dir():
            files = sorted(path.glob("*.json"))
            if not files:
                raise ConfigError(f"--houses {path}: the folder holds no *.json house files")
        elif path.is_file():
            files = [path]
        else:
            raise ConfigError(f"--houses {text!r}: no such folder or file; pass a folder of house JSON "
                              "files or preset:NAME")
        houses = [load_house(f) for f in files]
        names = [f.stem for f in files]
    return HouseSet(text, houses, compile_houses(houses, names))


def compile_houses(houses: Sequence[House | NavWorld], names: Sequence[str] | None = None) -> list[NavWorld]:
    """``compile_world`` each house (objects that are already NavWorlds pass through)."""
    names = list(names) if names is not None else [f"house-{i:03d}" for i in range(len(houses))]
    return [h if isinstance(h, NavWorld) else compile_world(h, n) for h, n in zip(houses, names, strict=True)]
