"""Appearance edits: swap one object's asset within its type and split, or give a room's floor or walls another material.

The single-edit form of the variations of :func:`~adaptenv.scene.procedural.variations.vary_house` (after
Phone2Proc): nothing moves, so an agent's routes stay, but what it sees changes. Both are real ProcTHOR edits
(catalog asset ids of the same asset split, catalog material names), recorded as
:class:`~adaptenv.adapt.edits.Edit` records that :func:`~adaptenv.adapt.edits.replay` rebuilds. An asset swap
is checked by :func:`~adaptenv.adapt.validation.validate_scene` against the scene before it (a bigger asset
that meets a neighbour, sticks out of its room or blocks a way is refused); a material change needs no
check beyond its names.

Example:
    >>> v = EditValidator(house)  # doctest: +SKIP
    >>> edit = swap_asset(v, "Sofa|2|1", swap_candidates(v.house, "Sofa|2|1", v.catalog)[0])  # doctest: +SKIP
    >>> edit = set_material(v, "room|2", "floor", "WoodFloorsCross")  # doctest: +SKIP
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from adaptenv.adapt.edits import Edit, apply_edit, material_name
from adaptenv.adapt.validation import EditValidator, ValidationProblem, validate_scene
from adaptenv.scene.assets import AssetCatalog, object_role
from adaptenv.scene.house import House
from adaptenv.scene.procedural.furniture import floor_assets
from adaptenv.scene.procedural.structure import _FLOOR_MATERIALS, _WALL_MATERIALS

Surface = Literal["floor", "wall"]
SURFACES: tuple[Surface, ...] = ("floor", "wall")


def swap_candidates(house: House, object_id: str, catalog: AssetCatalog) -> list[str]:
    """Asset ids ``object_id`` may be swapped for: floor assets of its type and asset split, its own excepted
    (none for an object off the floor, one carrying others, an unknown asset or one without a split)."""
    obj = next((o for o in house.objects if o.id == object_id), None)
    if obj is None or obj.children or obj.assetId not in catalog.assets:
        return []
    old = catalog.assets[obj.assetId]
    if old.split is None or object_role(old.object_type, obj.position.y - old.size[1] / 2, False) != "floor":
        return []
    return [a.asset_id for a in floor_assets(catalog, old.object_type, old.split) if a.asset_id != old.asset_id]


def propose_swap(validator: EditValidator, object_id: str, asset_id: str) -> tuple[Edit, House | None]:
    """Dry run of an asset swap on the validator's scene: the (not yet logged) Edit, accepted or with its problems,
    and the swapped house when it is valid."""
    house, catalog = validator.house, validator.catalog
    obj = next((o for o in house.objects if o.id == object_id), None)
    before = obj.assetId if obj is not None else None
    problems: list[ValidationProblem | str] = []
    if obj is None or asset_id not in swap_candidates(house, object_id, catalog):
        problems.append(f"{object_id}: {asset_id!r} is not an asset of its type and split it can be swapped for; "
                        "pick one of swap_candidates")
    elif catalog.assets[before].object_type in validator.fixed_types:
        problems.append(f"target_moved: {object_id} is an instance of the episode's target and keeps its asset; "
                        "swap another object")
    y_after, new = None, None
    if not problems:
        old, asset = catalog.assets[before], catalog.assets[asset_id]
        y_after = round(obj.position.y - old.size[1] / 2 + asset.size[1] / 2, 4)  # it rests where the old one did
        edit = Edit(object_id=object_id, asset_id=asset_id, asset_before=before, y_after=y_after)
        new = apply_edit(house, edit)
        problems += validate_scene(new, episode_targets=sorted(validator.need_targets), start=validator.start,
                                   original=house, catalog=catalog)
    ok = not problems
    edit = Edit(object_id=object_id, asset_id=asset_id, asset_before=before, y_after=y_after, accepted=ok,
                stop_reason="reached" if ok else "invalid", problems=[str(p) for p in problems])
    return edit, new if ok else None


def swap_asset(validator: EditValidator, object_id: str, asset_id: str, *, source: str = "manual",
               intent: str = "") -> Edit:
    """Swap ``object_id``'s asset for ``asset_id`` (same type and split, same place) when the scene stays valid; log
    the edit either way and return it."""
    edit, new = propose_swap(validator, object_id, asset_id)
    edit = edit.model_copy(update={"source": source, "intent": intent})
    if new is not None and edit.changed:
        validator.adopt(new)
    validator.log.append(edit)
    return edit


def material_choices(room_type: str, surface: Surface, catalog: AssetCatalog) -> list[str]:
    """Materials ProcTHOR gives a room type's floor or walls, those the catalog knows (else its Wood or Wall group)."""
    wanted = (_FLOOR_MATERIALS if surface == "floor" else _WALL_MATERIALS).get(room_type, ())
    known = catalog.material_names
    return [n for n in wanted if n in known] or sorted(catalog.materials.get("Wood" if surface == "floor" else "Wall",
                                                                          ()))


def set_material(validator: EditValidator, room_id: str, surface: Surface, material: str, *, source: str = "manual",
                 intent: str = "") -> Edit:
    """Give room ``room_id``'s floor or walls the catalog material ``material``; log the edit and return it (refused:
    an unknown room, surface or material)."""
    house = validator.house
    room = next((r for r in house.rooms if r.id == room_id), None)
    walls = [w for w in house.walls if w.roomId == room_id]
    before = None if room is None else material_name(room, "floorMaterial") if surface == "floor" else \
        material_name(walls[0], "material") if walls else ""
    problems = []
    if room is None:
        problems.append(f"material edit: the house has no room {room_id!r}; pick one of its rooms")
    if surface not in SURFACES:
        problems.append(f"material edit of {room_id}: surface {surface!r} is neither floor nor wall")
    if material not in validator.catalog.material_names:
        problems.append(f"material edit of {room_id}: {material!r} is not a catalog material; pick one of "
                        "material_choices")
    ok = not problems
    edit = Edit(object_id=room_id, material=material, material_before=before,
                surface=surface if surface in SURFACES else None, accepted=ok, stop_reason="reached" if ok else "invalid",
                problems=problems, source=source, intent=intent)
    apply_edit(house, edit, in_place=True)  # nothing moves: the validator's caches stay true
    validator.log.append(edit)
    return edit


def random_appearance_edit(validator: EditValidator, rng: np.random.Generator, *, source: str = "random",
                           intent: str = "random appearance edit") -> Edit | None:
    """One random appearance edit (validated and logged): half the time an object's asset swapped for a random
    candidate, else a random room's floor or walls given a random material of its type; None when none applies."""
    house = validator.house
    if rng.random() < 0.5:
        ids = [o.id for o in house.objects if swap_candidates(house, o.id, validator.catalog)]
        if ids:
            oid = ids[int(rng.integers(len(ids)))]
            pool = swap_candidates(house, oid, validator.catalog)
            return swap_asset(validator, oid, pool[int(rng.integers(len(pool)))], source=source, intent=intent)
    if not house.rooms:
        return None
    room = house.rooms[int(rng.integers(len(house.rooms)))]
    surface = SURFACES[int(rng.integers(2))]
    names = material_choices(room.roomType, surface, validator.catalog)
    if not names:
        return None
    return set_material(validator, room.id, surface, names[int(rng.integers(len(names)))], source=source,
                        intent=intent)
