"""Procedural ProcTHOR-format houses: named generation stages, guarantees, rearranged variants, presets.

Example:
    >>> from adaptenv.scene.procedural import GenerationConfig, generate_house, rearrange_house
    >>> house = generate_house(7, GenerationConfig(n_rooms=5))  # doctest: +SKIP
    >>> variant = rearrange_house(house, seed=1)  # doctest: +SKIP

Every generated house loads in AI2-THOR >= 5.0 (catalog asset ids and material names only) and
meets the guarantees of :func:`house_problems`: every room reachable from the start for the
agent's disc, at least three reachable ObjectNav target types, no overlapping floor footprints,
every footprint inside its room, and a clean :func:`adaptenv.scene.validate.validate_house`.
"""

from adaptenv.scene.procedural.checks import house_problems, stage_agent_pose
from adaptenv.scene.procedural.config import GenerationConfig, GenerationError
from adaptenv.scene.procedural.doors import stage_doors, stage_windows
from adaptenv.scene.procedural.furniture import stage_floor_objects
from adaptenv.scene.procedural.generate import (
    STAGES,
    Stage,
    child_seeds,
    generate_house,
    generate_houses,
    rearrange_house,
)
from adaptenv.scene.procedural.presets import PRESETS, PresetSpec, generate_preset, preset_spec
from adaptenv.scene.procedural.structure import stage_lights, stage_structure, stage_walls

__all__ = [
    "PRESETS", "STAGES", "GenerationConfig", "GenerationError", "PresetSpec", "Stage", "child_seeds",
    "generate_house", "generate_houses", "generate_preset", "house_problems", "preset_spec", "rearrange_house",
    "stage_agent_pose", "stage_doors", "stage_floor_objects", "stage_lights", "stage_structure",
    "stage_walls", "stage_windows",
]
