"""Variations of a home that keep its layout: other assets of the same types, other materials.

After Phone2Proc (Deitke et al., CVPR 2023), which trains on procedural variations of one scanned
home: :func:`vary_house` keeps the rooms, walls, doors, windows and every object's place, and swaps
each floor object for another asset of the same type and asset split (where one fits the same
place) and draws the floor and wall materials anew. Both are real ProcTHOR edits: the result is a
house AI2-THOR loads (catalog asset ids, catalog materials).
"""

from __future__ import annotations

import numpy as np

from adaptenv.scene.assets import AssetCatalog, load_catalog, object_role
from adaptenv.scene.house import House
from adaptenv.scene.procedural.checks import (
    house_problems,
)
from adaptenv.scene.procedural.config import GenerationConfig, GenerationError
from adaptenv.scene.procedural.furniture import RoomFloor, _footprint_box, floor_assets
from adaptenv.scene.procedural.generate import _check_seed, kept_guarantees
from adaptenv.scene.procedural.structure import _FLOOR_MATERIALS, _WALL_MATERIALS, pick_name

CANDIDATES = 8
"""Other assets tried for each object before it keeps its own."""


def _overlaps(box: np.ndarray, others: np.ndarray) -> np.ndarray:
    """bool (K,): whether ``box`` overlaps each of ``others`` (K, 4) with positive area."""
    if not len(others):
        return np.zeros(0, dtype=bool)
    return ((np.minimum(box[2], others[:, 2]) - np.maximum(box[0], others[:, 0]) > 1e-6)
            & (np.minimum(box[3], others[:, 3]) - np.maximum(box[1], others[:, 1]) > 1e-6))


def swap_assets(house: House, rng: np.random.Generator, catalog: AssetCatalog, split: str) -> int:
    """Swap each floor object without children, in place, for another asset of its type and split whose
    footprint fits its room and meets no object the old one did not; returns the number swapped."""
    floors = [RoomFloor.from_room(r) for r in house.rooms]
    objs = [o for o in house.objects if o.assetId in catalog.assets
            and object_role(catalog.assets[o.assetId].object_type,
                            o.position.y - catalog.assets[o.assetId].size[1] / 2, False) == "floor"]
    boxes = np.array([_footprint_box(o, catalog.assets[o.assetId]) for o in objs]).reshape(-1, 4)
    swapped = 0
    for k in rng.permutation(len(objs)).tolist():
        obj = objs[k]
        if obj.children:
            continue
        old = catalog.assets[obj.assetId]
        room = next((f for f in floors if f.contains(boxes[k])[0]), None)
        pool = [a for a in floor_assets(catalog, old.object_type, split) if a.asset_id != old.asset_id]
        if room is None or not pool:
            continue
        others = np.delete(boxes, k, axis=0)
        before = _overlaps(boxes[k], others)
        for j in rng.permutation(len(pool))[:CANDIDATES].tolist():
            new = pool[j]
            box = _footprint_box(obj, new)  # the new asset in the old place
            if room.contains(box)[0] and not (_overlaps(box, others) & ~before).any():
                base = obj.position.y - old.size[1] / 2  # the object stands where it stood
                obj.assetId = new.asset_id
                obj.position = obj.position.model_copy(update={"y": round(base + new.size[1] / 2, 4)})
                boxes[k] = box
                swapped += 1
                break
    return swapped


def recolour(house: House, rng: np.random.Generator, catalog: AssetCatalog) -> None:
    """Draw each room's floor material and its walls' material anew, in place (ProcTHOR's material lists)."""
    for room in house.rooms:
        room.floorMaterial = {"name": pick_name(rng, _FLOOR_MATERIALS[room.roomType], catalog, "Wood")}
        material = {"name": pick_name(rng, _WALL_MATERIALS[room.roomType], catalog)}
        for wall in house.walls:
            if wall.roomId == room.id:
                wall.material = dict(material)


def vary_house(house: House, seed: int, cfg: GenerationConfig | None = None,
               catalog: AssetCatalog | None = None) -> House:
    """The same home with other assets of the same types (split ``cfg.split``) and new materials.

    Every object keeps its place and rotation; the target types reachable in the original stay
    reachable (an attempt that breaks any of :func:`house_problems` is drawn again). The input house is
    not modified.

    Raises:
        GenerationError: when ``cfg.max_attempts`` attempts all failed.
    """
    cfg = (cfg or GenerationConfig()).check()
    catalog = catalog or load_catalog()
    seed = _check_seed(seed)
    allowed, required = kept_guarantees(house, cfg, catalog)
    last = "no attempt was made"
    for attempt in range(cfg.max_attempts):
        rng_assets, rng_materials = (np.random.default_rng(s)
                                     for s in np.random.SeedSequence([seed, attempt]).spawn(2))
        new = house.model_copy(deep=True)
        swap_assets(new, rng_assets, catalog, cfg.split)
        recolour(new, rng_materials, catalog)
        problems = house_problems(new, cfg, catalog, required, allowed)
        if not problems:
            return new
        last = problems[0]
    raise GenerationError(f"seed {seed}: no valid variation after {cfg.max_attempts} attempts "
                          f"(last problem: {last}); try another seed")
