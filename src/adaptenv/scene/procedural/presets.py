"""Named house sets for experiments: pre-training houses, their rearranged twins, unseen houses."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

from adaptenv.errors import ConfigError
from adaptenv.scene.assets import AssetCatalog, load_catalog
from adaptenv.scene.house import House
from adaptenv.scene.procedural.config import GenerationConfig
from adaptenv.scene.procedural.generate import child_seeds, generate_house, rearrange_house


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
    split: str = "train"
    """ProcTHOR asset split the furniture comes from."""
    description: str = ""
    """One line for ``adaptenv houses generate --help`` and the docs."""

    def config(self, base: GenerationConfig | None = None) -> GenerationConfig:
        """The generation config of this preset (room range and split applied to ``base``)."""
        return replace(base or GenerationConfig(), n_rooms=None, room_types=None, room_range=self.room_range,
                       split=self.split)


PRESETS: dict[str, PresetSpec] = {
    "pretrain-train": PresetSpec(24, 1000, description="houses the agent is pre-trained on"),
    "pretrain-rearranged": PresetSpec(24, 2000, rearrange_of="pretrain-train",
                                      description="the pretrain-train houses with their furniture rearranged"),
    "pretrain-unseen": PresetSpec(50, 3000, description="new houses from the same distribution, never trained on"),
    "tiny": PresetSpec(3, 7, room_range=(1, 3), description="three small houses for tests and CI"),
}


def preset_spec(name: str) -> PresetSpec:
    """The preset of this name; ConfigError lists the known names."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ConfigError(f"preset: unknown preset {name!r}; use one of {', '.join(PRESETS)}") from None


def generate_preset(name: str, catalog: AssetCatalog | None = None,
                    on_house: Callable[[int, int], None] | None = None) -> list[tuple[str, House]]:
    """The preset's houses as (name, house) pairs, e.g. ``("pretrain-train_0003", house)``.

    ``on_house(i, total)`` is called after each house (for progress bars).
    """
    spec = preset_spec(name)
    catalog = catalog or load_catalog()
    if spec.rearrange_of is not None:
        base = generate_preset(spec.rearrange_of, catalog)
        seeds = child_seeds(spec.seed, len(base))
        out = []
        for i, ((_, house), s) in enumerate(zip(base, seeds, strict=True)):
            out.append((f"{name}_{i:04d}", rearrange_house(house, s, spec.config(), catalog)))
            if on_house is not None:
                on_house(i, len(base))
        return out
    cfg = spec.config()
    out = []
    for i, s in enumerate(child_seeds(spec.seed, spec.n_houses)):
        out.append((f"{name}_{i:04d}", generate_house(s, cfg, catalog)))
        if on_house is not None:
            on_house(i, spec.n_houses)
    return out
