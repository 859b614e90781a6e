"""Appearance edits: an asset swapped within its type and split, a room's material changed; replay, validity, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from adaptenv.adapt.appearance import (
    material_choices,
    propose_swap,
    set_material,
    swap_asset,
    swap_candidates,
)
from adaptenv.adapt.edits import EditLog, edit_counts, replay
from adaptenv.adapt.generators.random_perturbation import random_single_edits
from adaptenv.adapt.validation import EditValidator
from adaptenv.scene.procedural import GenerationConfig, generate_house
from adaptenv.scene.validate import validate_house


@pytest.fixture(scope="module")
def house():
    return generate_house(11, GenerationConfig(n_rooms=3))


def _swappable(v: EditValidator) -> list[tuple[str, list[str]]]:
    return [(o.id, pool) for o in v.house.objects if (pool := swap_candidates(v.house, o.id, v.catalog))]


def test_a_swap_keeps_place_type_and_split_and_replays_to_a_valid_house(house):
    v = EditValidator(house)
    edit = None
    for oid, pool in _swappable(v):
        for asset in pool[:4]:
            edit = swap_asset(v, oid, asset, source="test")
            if edit.accepted:
                break
        if edit is not None and edit.accepted:
            break
    assert edit is not None and edit.accepted and edit.changed and edit.is_swap
    old, new = v.catalog.assets[edit.asset_before], v.catalog.assets[edit.asset_id]
    assert (old.object_type, old.split) == (new.object_type, new.split)
    a, b = house.object_by_id(edit.object_id), v.house.object_by_id(edit.object_id)
    assert (a.position.x, a.position.z, a.yaw) == (b.position.x, b.position.z, b.yaw)
    assert b.position.y - new.size[1] / 2 == pytest.approx(a.position.y - old.size[1] / 2, abs=1e-3)
    child = replay(house, EditLog.from_json(v.log.to_json()))
    assert child.to_dict() == v.house.to_dict()
    assert validate_house(child) == []
    assert edit_counts([edit], house, child)["objects_changed"] == 1


def test_a_swap_that_collides_is_refused_and_changes_nothing(house):
    v = EditValidator(house)
    refused = None
    for oid, pool in _swappable(v):  # the biggest candidate of each object until one meets something
        big = max(pool, key=lambda a: v.catalog.assets[a].size[0] * v.catalog.assets[a].size[2])
        edit, new = propose_swap(v, oid, big)
        if not edit.accepted:
            refused = (oid, big, edit)
            break
    assert refused is not None, "no swap in this house collides; pick another house"
    oid, big, edit = refused
    assert new is None and any("overlap" in p or "sticks out" in p or "crosses" in p or "reach" in p
                               or "blocked" in p or "doorway" in p for p in edit.problems)
    logged = swap_asset(v, oid, big)
    assert not logged.accepted and v.house.to_dict() == house.to_dict()
    assert not swap_asset(v, oid, "NotAnAsset_123").accepted


def test_material_edits_use_catalog_names_and_replay(house):
    v = EditValidator(house)
    room = house.rooms[0]
    names = material_choices(room.roomType, "floor", v.catalog)
    wall_names = material_choices(room.roomType, "wall", v.catalog)
    assert names and set(names) <= v.catalog.material_names
    e1 = set_material(v, room.id, "floor", names[-1])
    e2 = set_material(v, room.id, "wall", wall_names[0])
    bad = set_material(v, room.id, "floor", "Plaid Velvet 9000")
    assert e1.accepted and e2.accepted and not bad.accepted and bad.problems
    assert v.house.rooms[0].floorMaterial["name"] == names[-1]
    assert {w.material["name"] for w in v.house.walls if w.roomId == room.id} == {wall_names[0]}
    child = replay(house, v.log)
    assert child.to_dict() == v.house.to_dict() and validate_house(child) == []
    assert house.rooms[0].floorMaterial == generate_house(11, GenerationConfig(n_rooms=3)).rooms[0].floorMaterial


def test_random_edits_with_appearance_are_deterministic_and_valid(house):
    a, log_a = random_single_edits(house, 4, np.random.default_rng(3), appearance=1.0)
    b, log_b = random_single_edits(house, 4, np.random.default_rng(3), appearance=1.0)
    assert log_a == log_b and a.to_dict() == b.to_dict()
    kept = [e for e in log_a if e.accepted and e.changed]
    assert len(kept) == 4 and all(e.is_swap or e.is_material for e in kept)
    assert replay(house, log_a).to_dict() == a.to_dict() and validate_house(a) == []
    c, log_c = random_single_edits(house, 2, np.random.default_rng(5))
    d, log_d = random_single_edits(house, 2, np.random.default_rng(5), appearance=0.0)
    assert log_c == log_d and not any(e.is_swap or e.is_material for e in log_c)  # the default draws moves only
