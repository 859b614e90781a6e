"""Procedural houses: determinism, guarantees, rearranged variants, presets, format, CLI."""

from __future__ import annotations

import json
import sys
from functools import cache

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adaptenv.errors import ConfigError
from adaptenv.scene.assets import ROOM_TYPES, load_catalog
from adaptenv.scene.geometry import SceneGeometry
from adaptenv.scene.house import parse_house
from adaptenv.scene.procedural import (
    PRESETS,
    GenerationConfig,
    GenerationError,
    generate_house,
    generate_houses,
    generate_preset,
    house_problems,
    rearrange_house,
)
from adaptenv.scene.procedural.checks import Navigation, footprint_problems, reachable_target_types
from adaptenv.scene.procedural.generate import child_seeds
from adaptenv.scene.procedural.structure import grow_floor_plan, trace_room
from adaptenv.scene.validate import validate_house
from adaptenv.sim.spec import AGENT_RADIUS, TARGET_TYPES


@cache
def _house(seed: int, n_rooms: int):
    """Generated houses are reused across tests (never mutate them)."""
    return generate_house(seed, GenerationConfig(n_rooms=n_rooms))


def _dumps(house) -> str:
    return json.dumps(house.to_dict(), indent=1)


def _floor_types(house) -> set[str]:
    return {f.object_type for f in SceneGeometry.from_house(house).floor_objects}


# ------------------------------------------------------------------------------------------ determinism


def test_same_seed_gives_byte_identical_json():
    assert _dumps(generate_house(11, GenerationConfig(n_rooms=4))) == _dumps(generate_house(11, GenerationConfig(n_rooms=4)))


def test_different_seeds_give_different_houses():
    a, b = generate_house(1, GenerationConfig(n_rooms=4)), generate_house(2, GenerationConfig(n_rooms=4))
    assert a.to_dict() != b.to_dict()


def test_generate_houses_uses_child_seeds_independent_of_n():
    three = generate_houses(3, seed=5, cfg=GenerationConfig(n_rooms=2))
    two = generate_houses(2, seed=5, cfg=GenerationConfig(n_rooms=2))
    assert [_dumps(h) for h in two] == [_dumps(h) for h in three[:2]]
    assert _dumps(three[0]) != _dumps(three[1])


# ----------------------------------------------------------------------------------------- guarantees


@pytest.mark.parametrize("n_rooms", range(1, 11))
def test_every_room_count_gives_a_valid_house(n_rooms):
    house = _house(100 + n_rooms, n_rooms)
    assert len(house.rooms) == n_rooms
    assert {r.roomType for r in house.rooms} <= set(ROOM_TYPES)
    assert validate_house(house) == []
    assert house_problems(house, GenerationConfig(), load_catalog()) == []


@pytest.mark.parametrize("n_rooms", [1, 3, 6, 10])
def test_every_room_reachable_from_start(n_rooms):
    house = _house(200 + n_rooms, n_rooms)
    nav = Navigation.of(house, load_catalog(), AGENT_RADIUS)
    x, z, yaw = house.agent_pose()
    start = nav.component_at(x, z)
    assert start > 0
    assert yaw in (0.0, 90.0, 180.0, 270.0)
    assert x / 0.25 == pytest.approx(round(x / 0.25)) and z / 0.25 == pytest.approx(round(z / 0.25))
    g = nav.grid
    for k in range(len(g.room_ids)):
        assert ((g.room == k) & (nav.labels == start)).any(), g.room_ids[k]


@pytest.mark.parametrize("seed", range(4))
def test_target_types_present_and_reachable(seed):
    house = _house(300 + seed, 4)
    nav = Navigation.of(house, load_catalog(), AGENT_RADIUS)
    start = nav.component_at(*house.agent_pose()[:2])
    found = reachable_target_types(nav, start, 1.5)
    assert len(found) >= 3
    assert found <= set(TARGET_TYPES)


def test_televisions_stand_on_the_floor():
    catalog = load_catalog()
    tvs = [o for h in (_house(s, 5) for s in range(6)) for o in h.objects
           if catalog.asset(o.assetId).object_type == "Television"]
    assert tvs, "no television in six 5-room houses"
    for tv in tvs:
        bottom = tv.position.y - catalog.asset(tv.assetId).size[1] / 2
        assert abs(bottom) < 1e-3


def test_doors_connect_rooms_and_one_front_door_is_closed():
    house = _house(7, 6)
    front = [d for d in house.doors if d.id.startswith("door|1|")]
    assert len(front) == 1
    assert front[0].wall1.startswith("wall|exterior|") and front[0].openness == 0 and front[0].openable
    wall_ids = {w.id for w in house.walls}
    for d in house.doors:
        assert d.wall0 in wall_ids and d.wall1 in wall_ids
        lo, hi = sorted(v.x for v in d.holePolygon)
        assert lo > 0 and hi - lo > 0.9


def test_shut_interior_doors_close_rooms_off_and_block_the_agent():
    from adaptenv.scene.procedural.checks import closed_interior_doors, opened

    catalog = load_catalog()
    cfg = PRESETS["suite-closed"].config()
    houses = [generate_house(s, cfg, catalog) for s in range(6)]
    shut = [closed_interior_doors(h) for h in houses]
    assert sum(map(len, shut)) > 0 and all(house_problems(h, cfg, catalog) == [] for h in houses)
    h = next(h for h, ids in zip(houses, shut, strict=True) if ids)
    assert all(d.openness == 0 and d.openable for d in h.doors if d.id in closed_interior_doors(h))
    geometry, reopened = SceneGeometry.from_house(h), SceneGeometry.from_house(opened(h))
    assert sum(d.passable for d in reopened.doors) > sum(d.passable for d in geometry.doors), "a shut door blocks"
    assert closed_interior_doors(opened(h)) == []


def test_no_interior_door_is_shut_by_default():
    """(The option spends no random draw when it is 0: the pinned suite episodes of tests/agents/test_suites.py
    would change otherwise.)"""
    for seed in range(4):
        assert all(d.openness != 0 for d in generate_house(seed, GenerationConfig(n_rooms=6)).doors
                   if d.room0 != d.room1)


def test_walls_appear_once_per_room_plus_exterior_copies():
    house = _house(8, 5)
    segments: dict[tuple, list[str]] = {}
    for w in house.walls:
        floor = sorted((round(p.x, 3), round(p.z, 3)) for p in w.polygon if p.y == 0)
        segments.setdefault(tuple(floor), []).append(w.roomId)
    for rooms in segments.values():
        interior = [r for r in rooms if r != "exterior"]
        assert len(interior) in (1, 2)
        assert len(rooms) == 2  # two rooms, or one room and its exterior copy


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_rooms=st.integers(1, 10))
def test_footprints_never_overlap_and_stay_in_their_room(seed, n_rooms):
    house = generate_house(seed, GenerationConfig(n_rooms=n_rooms))
    geometry = SceneGeometry.from_house(house)
    assert footprint_problems(geometry) == []
    for f in geometry.floor_objects:
        room = f.object_id.split("|")[1]
        assert geometry.rooms[f"room|{room}"].buffer(1e-3).covers(f.polygon)


# ------------------------------------------------------------------------------------------ rearrange


def test_rearranged_house_keeps_structure_and_targets_but_moves_furniture():
    house = _house(21, 5)
    before = _dumps(house)
    variant = rearrange_house(house, seed=3)
    assert _dumps(house) == before, "rearrange_house must not modify its input"
    for key in ("rooms", "walls", "doors", "windows", "proceduralParameters"):
        assert variant.to_dict()[key] == house.to_dict()[key]
    old = {o.id: o for o in house.objects}
    moved = [o for o in variant.objects if o.id in old and o.position != old[o.id].position]
    assert len(moved) >= len(house.objects) // 2
    assert _floor_types(variant) & set(TARGET_TYPES) >= _floor_types(house) & set(TARGET_TYPES)
    assert house_problems(variant, GenerationConfig(), load_catalog()) == []
    assert _dumps(rearrange_house(house, seed=3)) == _dumps(variant)


def test_rearrange_keeps_fixtures_in_place():
    house = _house(22, 5)
    variant = rearrange_house(house, seed=1)
    catalog = load_catalog()
    fixed = {o.id: o.position for o in house.objects
             if catalog.asset(o.assetId).object_type in ("Toilet", "Sink", "CounterTop")}
    assert fixed
    new = {o.id: o.position for o in variant.objects}
    assert all(new[i] == p for i, p in fixed.items())


def test_rearrange_real_house_tolerates_its_tucked_chairs(real_house):
    variant = rearrange_house(real_house, seed=0)
    assert {r.id for r in variant.rooms} == {r.id for r in real_house.rooms}
    assert variant.doors == real_house.doors


# --------------------------------------------------------------------------------------------- presets


def test_presets_have_the_stated_sizes():
    assert PRESETS["pretrain-train"].n_houses == 24
    assert PRESETS["pretrain-unseen"].n_houses == 50
    assert PRESETS["pretrain-rearranged"].rearrange_of == "pretrain-train"
    for name in ("pretrain-train", "pretrain-unseen"):
        assert PRESETS[name].room_range == (2, 6)


def test_tiny_preset_generates_its_houses():
    named = generate_preset("tiny")
    assert len(named) == PRESETS["tiny"].n_houses == 3
    assert [n for n, _ in named] == ["tiny_0000", "tiny_0001", "tiny_0002"]
    lo, hi = PRESETS["tiny"].room_range
    assert all(lo <= len(h.rooms) <= hi for _, h in named)
    assert [_dumps(h) for _, h in named] == [_dumps(h) for _, h in generate_preset("tiny")]
    assert [(n, _dumps(h)) for n, h in generate_preset("tiny", count=2)] == [(n, _dumps(h)) for n, h in named[:2]]


def test_the_first_houses_of_a_rearranged_preset_are_those_of_the_whole_one():
    """House ``c * n_base + i`` is copy c of base house i, with the whole preset's seed of that house."""
    spec, catalog = PRESETS["scarce-6-rearranged"], load_catalog()
    homes = generate_preset("scarce-6", catalog, count=2)
    named = generate_preset("scarce-6-rearranged", catalog, count=7)
    seeds = child_seeds(spec.seed, 6 * spec.copies)
    assert [n for n, _ in named] == [f"scarce-6-rearranged_{i:04d}" for i in range(7)]
    for i in (0, 6):  # copy 0 and copy 1 of house 0
        assert _dumps(named[i][1]) == _dumps(rearrange_house(homes[0][1], seeds[i], spec.config(), catalog))


def test_unknown_preset_is_a_config_error():
    with pytest.raises(ConfigError, match="unknown preset"):
        generate_preset("nope")


# ---------------------------------------------------------------------------------------------- format


def test_json_has_schema_agent_and_only_catalog_names():
    catalog = load_catalog()
    doc = json.loads(_dumps(_house(31, 6)))
    assert set(doc) == {"rooms", "walls", "doors", "windows", "objects", "proceduralParameters", "metadata"}
    meta = doc["metadata"]
    assert meta["schema"] == "1.0.0"
    assert meta["agent"]["position"]["y"] == 0.95
    assert set(meta["agentPoses"]) == {"default", "arm", "locobot", "stretch"}
    assets = [o["assetId"] for o in doc["objects"]] + [d["assetId"] for d in doc["doors"] + doc["windows"]]
    assert all(a in catalog.assets for a in assets)
    materials = [r["floorMaterial"]["name"] for r in doc["rooms"]] + [w["material"]["name"] for w in doc["walls"]]
    materials.append(doc["proceduralParameters"]["ceilingMaterial"]["name"])
    assert set(materials) <= catalog.material_names
    assert doc["proceduralParameters"]["skyboxId"] in catalog.skyboxes
    assert parse_house(doc).to_dict() == doc


def test_room_polygons_are_simple_and_clockwise():
    for room in _house(32, 7).rooms:
        pts = np.array([(p.x, p.z) for p in room.floorPolygon])
        area = 0.5 * np.sum(pts[:, 0] * np.roll(pts[:, 1], -1) - np.roll(pts[:, 0], -1) * pts[:, 1])
        assert area < 0  # clockwise in (x, z), as ProcTHOR writes rooms


def test_trace_room_rejects_pinched_rooms():
    cells = np.array([[0, -1], [-1, 0]])
    assert trace_room(cells, 0) is None
    rng = np.random.default_rng(0)
    plan = next(p for p in (grow_floor_plan(rng, [4, 4, 2]) for _ in range(50)) if p is not None)
    assert all(trace_room(plan, k) is not None for k in range(3))


# ------------------------------------------------------------------------------------------------ config


@pytest.mark.parametrize("cfg", [GenerationConfig(n_rooms=0), GenerationConfig(n_rooms=11),
                                 GenerationConfig(room_types=("Kitchen", "Garage")), GenerationConfig(split="dev")])
def test_bad_config_is_rejected(cfg):
    with pytest.raises(ConfigError):
        generate_house(0, cfg)


def test_room_types_are_respected():
    house = generate_house(3, GenerationConfig(room_types=("Kitchen", "Bedroom", "Bathroom")))
    assert [r.roomType for r in house.rooms] == ["Kitchen", "Bedroom", "Bathroom"]


def test_impossible_config_raises_generation_error():
    with pytest.raises(GenerationError, match="no valid house"):
        generate_house(0, GenerationConfig(n_rooms=1, min_target_types=9, max_attempts=2))


# ------------------------------------------------------------------------------------------------- CLI


def test_cli_generate_writes_houses(tmp_path):
    from typer.testing import CliRunner

    from adaptenv.cli import app
    from adaptenv.cli._outputs import MANIFEST

    result = CliRunner().invoke(app, ["houses", "generate", "--n", "2", "--seed", "4", "--rooms", "2", "-o", str(tmp_path)])
    assert result.exit_code == 0, result.output
    files = sorted(p.name for p in tmp_path.iterdir())
    assert files == [MANIFEST, "house_0000.json", "house_0001.json"]  # the manifest: adaptenv wrote the houses
    house = parse_house(json.loads((tmp_path / "house_0000.json").read_text()))
    assert len(house.rooms) == 2
    assert "target types" in result.output

    out = tmp_path / "r.json"
    result = CliRunner().invoke(app, ["houses", "rearrange", str(tmp_path / "house_0000.json"), "--seed", "1",
                                      "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert len(parse_house(json.loads(out.read_text())).rooms) == 2


@pytest.mark.parametrize("args, message", [(["--rooms", "11"], "--rooms: expected 1 to 10 rooms, got 11"),
                                           (["--rooms", "Kitchen,Garage"], "unknown room type 'Garage'"),
                                           (["--preset", "huge"], "unknown preset 'huge'")])
def test_cli_rejects_bad_options_cleanly(tmp_path, monkeypatch, capsys, args, message):
    from adaptenv.cli import main

    monkeypatch.setattr(sys, "argv", ["adaptenv", "houses", "generate", *args, "-o", str(tmp_path / "out")])
    with pytest.raises(SystemExit) as exc:
        main()
    assert exc.value.code == 1
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()
