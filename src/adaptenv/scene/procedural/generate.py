"""The generation pipeline: named stages run in order, checked, retried with derived seeds.

Each stage is ``stage(house, *, rng, catalog, cfg)`` and edits the house in place; every stage gets
its own child generator spawned from ``SeedSequence([seed, attempt])``, so replacing one stage
does not change the random draws of the others, and the same seed always gives byte-identical
JSON.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from adaptenv.errors import ConfigError
from adaptenv.scene.assets import AssetCatalog, load_catalog
from adaptenv.scene.house import SCHEMA_VERSION, House, Metadata
from adaptenv.scene.procedural.checks import (
    Navigation,
    choose_start,
    house_problems,
    overlapping_pairs,
    reachable_target_types,
    stage_agent_pose,
)
from adaptenv.scene.procedural.config import GenerationConfig, GenerationError, StageFailed
from adaptenv.scene.procedural.doors import stage_doors, stage_windows
from adaptenv.scene.procedural.furniture import replace_movables, stage_floor_objects
from adaptenv.scene.procedural.structure import stage_lights, stage_structure, stage_walls
from adaptenv.vocabulary import TARGET_TYPES


class Stage(Protocol):
    """One generation step; edits the house in place (raise StageFailed to retry the attempt)."""

    def __call__(self, house: House, *, rng: np.random.Generator, catalog: AssetCatalog,
                 cfg: GenerationConfig) -> None: ...


STAGES: tuple[tuple[str, Stage], ...] = (
    ("structure", stage_structure),
    ("walls", stage_walls),
    ("doors", stage_doors),
    ("windows", stage_windows),
    ("lights", stage_lights),
    ("floor_objects", stage_floor_objects),
    ("agent_pose", stage_agent_pose),
)
"""The default pipeline, in order."""


def _check_seed(seed: int) -> int:
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"seed: expected a non-negative integer, got {seed!r}")
    return int(seed)


def child_seeds(seed: int, n: int) -> list[int]:
    """``n`` independent integer seeds derived from one root seed."""
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(_check_seed(seed)).spawn(n)]


def generate_house(seed: int, cfg: GenerationConfig | None = None, catalog: AssetCatalog | None = None,
                   stages: Sequence[tuple[str, Stage]] = STAGES) -> House:
    """Generate one ProcTHOR-format house that meets every guarantee of :func:`house_problems`.

    Example:
        >>> house = generate_house(0, GenerationConfig(n_rooms=4))  # doctest: +SKIP
        >>> len(house.rooms)  # doctest: +SKIP
        4

    Raises:
        ConfigError: for an invalid config or seed.
        GenerationError: when ``cfg.max_attempts`` attempts all failed.
    """
    cfg = (cfg or GenerationConfig()).check()
    catalog = catalog or load_catalog()
    seed = _check_seed(seed)
    last = "no attempt was made"
    for attempt in range(cfg.max_attempts):
        rngs = [np.random.default_rng(s) for s in np.random.SeedSequence([seed, attempt]).spawn(len(stages))]
        house = House(rooms=[], metadata=Metadata(schema=SCHEMA_VERSION, warnings={}))
        try:
            for (name, stage), rng in zip(stages, rngs, strict=True):
                last_stage = name
                stage(house, rng=rng, catalog=catalog, cfg=cfg)
        except StageFailed as exc:
            last = f"stage {last_stage}: {exc}"
            continue
        house.metadata.roomSpecId = f"adaptenv-{len(house.rooms)}-room"
        problems = house_problems(house, cfg, catalog)
        if not problems:
            return house
        last = problems[0]
    raise GenerationError(f"seed {seed}: no valid house after {cfg.max_attempts} attempts (last problem: {last}); "
                          "try another seed, fewer rooms or a lower furniture density")


def generate_houses(n: int, seed: int, cfg: GenerationConfig | None = None, catalog: AssetCatalog | None = None,
                    on_house: Callable[[int, House], None] | None = None) -> list[House]:
    """``n`` houses; house i comes from the i-th child seed of ``seed`` (so house i never depends on n)."""
    if n < 0:
        raise ConfigError(f"n: expected a non-negative number of houses, got {n}")
    cfg = (cfg or GenerationConfig()).check()
    out = []
    for i, s in enumerate(child_seeds(seed, n)):
        out.append(generate_house(s, cfg, catalog))
        if on_house is not None:
            on_house(i, out[-1])
    return out


def kept_guarantees(house: House, cfg: GenerationConfig, catalog: AssetCatalog
                    ) -> tuple[frozenset[frozenset[int]], tuple[str, ...]]:
    """What a child of ``house`` must keep for :func:`house_problems`: the object pairs that already overlap (allowed
    to) and the target types reachable from the start."""
    nav = Navigation.of(house, catalog, cfg.agent_radius)
    allowed = frozenset(frozenset((i, j)) for i, j, _ in overlapping_pairs(nav.geometry))
    pose = house.agent_pose()
    start = nav.component_at(pose[0], pose[1]) if pose is not None else None
    required = tuple(sorted(reachable_target_types(nav, start, cfg.target_reach))) if start else ()
    return allowed, required


def rearrange_house(house: House, seed: int, cfg: GenerationConfig | None = None,
                    catalog: AssetCatalog | None = None) -> House:
    """The same house with its movable furniture placed anew (the "rearranged" variant).

    Rooms, walls, doors, windows, fixtures (counters, sinks, toilets) and wall decor stay; every
    movable floor object (with table-and-chairs groups kept together and children moving with their
    parents) gets a new place in its own room. The start pose stays if it is still navigable. The
    target types reachable in the original stay reachable; footprints that overlapped in the original
    (chairs tucked under a table in a real house) may still overlap. The input house is not modified.

    Raises:
        GenerationError: when ``cfg.max_attempts`` attempts all failed.
    """
    cfg = (cfg or GenerationConfig()).check()
    catalog = catalog or load_catalog()
    seed = _check_seed(seed)
    pose = house.agent_pose()
    allowed, required = kept_guarantees(house, cfg, catalog)
    priority = tuple(dict.fromkeys([t for types in cfg.priority_types.values() for t in types] + list(TARGET_TYPES)))
    last = "no attempt was made"
    for attempt in range(cfg.max_attempts):
        rng_objects, rng_pose = (np.random.default_rng(s) for s in np.random.SeedSequence([seed, attempt]).spawn(2))
        new = house.model_copy(deep=True)
        replace_movables(new, rng=rng_objects, catalog=catalog, cfg=cfg, priority=priority)
        keep = (pose[0], pose[1]) if pose is not None else None
        try:
            nav = Navigation.of(new, catalog, cfg.agent_radius)
            x, z = choose_start(rng_pose, nav, keep)
        except StageFailed as exc:
            last = str(exc)
            continue
        if keep is None or (x, z) != keep:
            new.set_agent_pose(x, z, float(rng_pose.integers(4) * 90.0))
        problems = house_problems(new, cfg, catalog, required, allowed)
        if not problems:
            return new
        last = problems[0]
    raise GenerationError(f"seed {seed}: no valid rearrangement after {cfg.max_attempts} attempts "
                          f"(last problem: {last}); try another seed")
