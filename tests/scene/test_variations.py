"""Variations of a home: other assets of the same type and split in the same places, other materials."""

from __future__ import annotations

import pytest

from adaptenv.scene.assets import load_catalog
from adaptenv.scene.procedural import generate_preset
from adaptenv.scene.procedural.checks import house_problems
from adaptenv.scene.procedural.config import GenerationConfig
from adaptenv.scene.procedural.variations import vary_house


@pytest.fixture(scope="module")
def home():
    return generate_preset("tiny")[2][1]


def test_a_variation_keeps_every_place_and_type_and_swaps_assets_within_their_split(home):
    catalog = load_catalog()
    new = vary_house(home, 3, catalog=catalog)
    assert [o.id for o in new.objects] == [o.id for o in home.objects]
    swapped = 0
    for a, b in zip(home.objects, new.objects, strict=True):
        old, now = catalog.assets[a.assetId], catalog.assets[b.assetId]
        assert (b.position.x, b.position.z, b.rotation.y) == (a.position.x, a.position.z, a.rotation.y)
        assert now.object_type == old.object_type
        assert now.split in ("train", None)
        assert b.position.y - now.size[1] / 2 == pytest.approx(a.position.y - old.size[1] / 2, abs=1e-3)
        swapped += a.assetId != b.assetId
    assert swapped >= len(home.objects) // 2
    assert [r.floorMaterial for r in new.rooms] != [r.floorMaterial for r in home.rooms] or \
        [w.material for w in new.walls] != [w.material for w in home.walls]
    assert all(m["name"] in catalog.material_names for m in [r.floorMaterial for r in new.rooms])
    assert not house_problems(new, GenerationConfig(), catalog)


def test_variations_are_deterministic_and_leave_the_home_alone(home):
    before = home.model_dump_json()
    a, b, c = vary_house(home, 5), vary_house(home, 5), vary_house(home, 6)
    assert a.model_dump_json() == b.model_dump_json() != c.model_dump_json()
    assert home.model_dump_json() == before


def test_varied_presets_mirror_their_homes():
    homes = generate_preset("scarce-6")
    assert [h.model_dump_json() for _, h in homes] == [h.model_dump_json() for _, h in generate_preset("pretrain-train", count=6)]
