"""Named house sets for experiments: pre-training houses, their rearranged twins, unseen houses."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from adaptenv.errors import ConfigError
from adaptenv.scene.assets import AssetCatalog, load_catalog
from adaptenv.scene.house import House
from adaptenv.scene.procedural.config import GenerationConfig
from adaptenv.scene.procedural.generate import child_seeds, generate_house, rearrange_house
from adaptenv.scene.procedural.variations import vary_house


@dataclass(frozen=True)
class PresetSpec:
    """A reproducible set of houses: how many, from which seed, how big (tune sizes here)."""

    n_houses: int
    """Number of houses (ignored by rearranged presets, which mirror their base preset)."""
    seed: int
    """Root seed: house i uses the i-th child seed."""
    room_range: tuple[int, int] = (2, 6)
    """Inclusive range of room counts."""
    rearrange_of: str | None = None
    """When set, the houses are ``rearrange_house`` of this preset's houses instead of new ones."""
    vary_of: str | None = None
    """When set, the houses are ``vary_house`` of this preset's houses (other assets, other materials)."""
    copies: int = 1
    """Rearranged and varied presets: children of each base house (house ``c * n_base + i`` is copy c of house i)."""
    split: str = "train"
    """ProcTHOR asset split the furniture comes from."""
    description: str = ""
    """One line for ``adaptenv houses generate --help`` and the docs."""
    overrides: tuple[tuple[str, Any], ...] = ()
    """Further ``GenerationConfig`` fields as (name, value) pairs (e.g. denser furniture)."""

    def config(self, base: GenerationConfig | None = None) -> GenerationConfig:
        """The generation config of this preset (room range, split and overrides applied to ``base``)."""
        return replace(base or GenerationConfig(), n_rooms=None, room_types=None, room_range=self.room_range,
                       split=self.split, **dict(self.overrides))


#: Generation overrides of the cluttered presets: three times the filler furniture, tighter margins.
CLUTTER = (("furniture_density", 3.0), ("edge_margin", 0.3), ("middle_margin", 0.2), ("passage", 0.45))

PRESETS: dict[str, PresetSpec] = {
    "pretrain-train": PresetSpec(24, 1000, description="houses the agent is pre-trained on"),
    "pretrain-rearranged": PresetSpec(24, 2000, rearrange_of="pretrain-train",
                                      description="the pretrain-train houses with their furniture rearranged"),
    # Several rearrangements of every pretrain-train house (new seeds): the rearranged-homes suites' houses.
    "suite-rearranged": PresetSpec(24, 6001, rearrange_of="pretrain-train", copies=10,
        description="ten rearrangements of each pretrain-train house, for the held-out suite rearranged"),
    "validation-rearranged": PresetSpec(24, 6101, rearrange_of="pretrain-train", copies=10,
        description="ten other rearrangements of each pretrain-train house (validation twin of suite-rearranged)"),
    "pretrain-unseen": PresetSpec(50, 3000, description="new houses from the same distribution, never trained on"),
    "tiny": PresetSpec(3, 7, room_range=(1, 3), description="three small houses for tests and CI"),
    # Held-out suite houses (agents/suites.py): root seeds no training preset or generator uses.
    "suite-large": PresetSpec(30, 5101, room_range=(7, 10), description="7-10 room houses for the held-out suites"),
    "suite-clutter": PresetSpec(30, 5201, room_range=(3, 6), overrides=CLUTTER,
        description="3-6 room houses with three times the filler furniture and tighter margins"),
    "suite-doors": PresetSpec(30, 5301, room_range=(5, 8), overrides=(
        ("open_kitchen_prob", 0.0), ("doorframe_prob", 0.0), ("extra_door_prob", 0.0)),
        description="5-8 room houses where every connection is a door (no open walls, frames or loops)"),
    "suite-closed": PresetSpec(30, 5601, room_range=(6, 9), overrides=(("closed_door_prob", 0.4),),
        description="6-9 room houses where 40% of the interior doors are shut (rooms behind them out of reach)"),
    # Validation houses (agents/suites.py, val-*): for choosing settings; never trained on, never reported as held-out.
    "validation": PresetSpec(50, 4000, description="validation houses of the training distribution"),
    "validation-large": PresetSpec(30, 5401, room_range=(7, 10), description="7-10 room validation houses"),
    "validation-clutter": PresetSpec(30, 5501, room_range=(3, 6), overrides=CLUTTER,
        description="cluttered 3-6 room validation houses (suite-clutter's settings)"),
    "validation-closed": PresetSpec(30, 5701, room_range=(6, 9), overrides=(("closed_door_prob", 0.4),),
        description="6-9 room validation houses with shut interior doors (suite-closed's settings)"),
    # Held-out houses furnished with assets no training preset uses (ProcTHOR's test split), its validation
    # twin (the val split) and the tail suite's 200 houses of the training distribution (agents/suites.py).
    "suite-unseen-assets": PresetSpec(40, 5801, split="test",
        description="2-6 room houses furnished with ProcTHOR's test-split assets (shapes no training house has)"),
    "validation-unseen-assets": PresetSpec(40, 5901, split="val",
        description="2-6 room validation houses furnished with ProcTHOR's val-split assets"),
    "suite-tail": PresetSpec(200, 5951, description="200 unseen houses of the training distribution (the tail suite)"),
    # The scarce-homes setting (docs/curriculum.md): N seed homes and what each training arm makes of them.
    # pretrain-train's first 6 houses are scarce-6's (house i of a preset uses the i-th child seed of its root).
    "scarce-6": PresetSpec(6, 1000, description="the first 6 pretrain-train houses: the scarce-homes set with N = 6"),
    "pretrain-swapped": PresetSpec(24, 7001, vary_of="pretrain-train", copies=10,
        description="ten variations of each pretrain-train house: other train-split assets, other materials"),
    "scarce-6-swapped": PresetSpec(6, 7001, vary_of="scarce-6", copies=10,
        description="ten variations of each scarce-6 house: other train-split assets, other materials"),
    "pretrain-rearranged10": PresetSpec(24, 7101, rearrange_of="pretrain-train", copies=10,
        description="ten training rearrangements of each pretrain-train house (seeds no suite uses)"),
    "scarce-6-rearranged": PresetSpec(6, 7101, rearrange_of="scarce-6", copies=10,
        description="ten training rearrangements of each scarce-6 house (seeds no suite uses)"),
    "fresh-240": PresetSpec(240, 7201, description="240 fresh houses of the training distribution (10 N for N = 24)"),
    "fresh-60": PresetSpec(60, 7201, description="the first 60 fresh-240 houses (10 N for N = 6)"),
    "oracle-large": PresetSpec(80, 7301, room_range=(7, 10),
        description="7-10 room houses with suite-large's settings and new seeds (the oracle arm's share for far)"),
    "oracle-unseen": PresetSpec(80, 7401, description="houses of long-unseen's distribution, new seeds (oracle)"),
    "oracle-test-assets": PresetSpec(80, 7501, split="test",
        description="houses with suite-unseen-assets' settings and new seeds (the oracle arm's share)"),
}


def preset_spec(name: str) -> PresetSpec:
    """The preset of this name; ConfigError lists the known names."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ConfigError(f"preset: unknown preset {name!r}; use one of {', '.join(PRESETS)}") from None


def preset_size(name: str) -> int:
    """How many houses the preset holds (a rearranged or varied preset: its base's count times its copies)."""
    spec = preset_spec(name)
    base = spec.rearrange_of or spec.vary_of
    return spec.n_houses if base is None else preset_size(base) * spec.copies


def generate_preset(name: str, catalog: AssetCatalog | None = None,
                    on_house: Callable[[int, int], None] | None = None, *,
                    count: int | None = None) -> list[tuple[str, House]]:
    """The preset's houses as (name, house) pairs, e.g. ``("pretrain-train_0003", house)``.

    ``on_house(i, total)`` is called after each house (for progress bars). ``count`` makes only the first
    ``count`` houses, the same as the whole preset's first ones (house i never depends on how many are made).
    """
    spec = preset_spec(name)
    catalog = catalog or load_catalog()
    total = preset_size(name) if count is None else min(count, preset_size(name))
    if spec.rearrange_of is not None or spec.vary_of is not None:
        n_base = preset_size(spec.rearrange_of or spec.vary_of)
        base = generate_preset(spec.rearrange_of or spec.vary_of, catalog, count=min(total, n_base))
        child = rearrange_house if spec.rearrange_of is not None else vary_house
        seeds = child_seeds(spec.seed, n_base * spec.copies)[:total]
        out = []
        for i, s in enumerate(seeds):
            out.append((f"{name}_{i:04d}", child(base[i % n_base][1], s, spec.config(), catalog)))
            if on_house is not None:
                on_house(i, len(seeds))
        return out
    cfg = spec.config()
    out = []
    for i, s in enumerate(child_seeds(spec.seed, spec.n_houses)[:total]):
        out.append((f"{name}_{i:04d}", generate_house(s, cfg, catalog)))
        if on_house is not None:
            on_house(i, total)
    return out
