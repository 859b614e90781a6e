"""Houses with assets the ProcTHOR catalog lacks (Objaverse-style ids) load with a user asset table,
and L/C counters have their true, non-rectangular footprints."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from shapely.geometry import Point
from typer.testing import CliRunner

from adaptenv.adapt.validation import NavRaster
from adaptenv.cli import app
from adaptenv.errors import ConfigError, HouseError
from adaptenv.scene.assets import (
    ASSETS_ENV,
    COUNTER_ARM_DEPTH,
    load_catalog,
    read_asset_table,
    use_assets,
)
from adaptenv.scene.geometry import SceneGeometry
from adaptenv.scene.house import load_house, save_house
from adaptenv.sim.geodesic import is_solvable
from adaptenv.sim.rollout import expert_policy, run_episode
from adaptenv.sim.spec import AGENT_RADIUS
from adaptenv.sim.task import sample_episode
from adaptenv.sim.world import compile_world
from tests.conftest import REAL_HOUSE
from tests.sim import helpers as H

SOFA, BED, TABLE = "0a1b2c3d4e5f4a5b8c9d0e1f2a3b4c5d", "9f8e7d6c5b4a49388271605f4e3d2c1b", "5e5e5e5e5e5e4e5e9e5e5e5e5e5e5e5e"


@pytest.fixture
def table_file(tmp_path):
    """An Objaverse-style asset table: hex ids, ProcTHOR types, boxes, one L-shaped outline."""
    doc = {"assets": {
        SOFA: {"type": "Sofa", "size": [2.0, 0.9, 0.9]},
        BED: {"objectType": "Bed", "boundingBox": {"x": 1.4, "y": 0.6, "z": 2.1}},
        TABLE: {"type": "DiningTable", "size": [1.6, 0.75, 1.6],
                "footprint": [[-0.8, -0.8], [0.8, -0.8], [0.8, 0.8], [0.2, 0.8], [0.2, -0.2], [-0.8, -0.2]]},
    }}
    p = tmp_path / "my_assets.json"
    p.write_text(json.dumps(doc), encoding="utf-8")
    return p


@pytest.fixture
def objaverse_house(tmp_path, table_file, monkeypatch):
    """Two rooms furnished only with table assets, written with the table in use, then the table dropped."""
    monkeypatch.setenv(ASSETS_ENV, "")
    use_assets(table_file)
    house = H.two_rooms(objects=[H.Obj(SOFA, 2.0, 0.6), H.Obj(BED, 6.0, 2.0), H.Obj(TABLE, 1.0, 3.0)],
                        agent=(2.0, 2.0, 0.0))
    path = save_house(house, tmp_path / "objaverse_house.json")
    monkeypatch.setenv(ASSETS_ENV, "")
    return path


def test_unknown_ids_give_one_error_naming_count_and_flag(objaverse_house):
    with pytest.raises(HouseError) as err:
        load_house(objaverse_house)
    msg = str(err.value)
    assert len(err.value.problems) == 1
    assert "3 assetIds" in msg and repr(SOFA) in msg and "--assets FILE" in msg


def test_objaverse_house_loads_simulates_and_is_solvable(objaverse_house, table_file, monkeypatch):
    house = load_house(objaverse_house, catalog=load_catalog(table_file))  # the API argument
    assert not os.environ.get(ASSETS_ENV)
    use_assets(table_file)  # every function from here on
    world = compile_world(load_house(objaverse_house), "objaverse")
    assert sorted(world.object_types) == ["Bed", "DiningTable", "Sofa"]
    table = world.geometry.footprint(next(o.id for o in house.objects if o.assetId == TABLE))
    assert table.polygon.area == pytest.approx(1.6 * 1.6 - 1.0 * 1.0, abs=1e-6)
    # The cut-out corner of the table's outline (local -x, +z) is free floor in the simulator.
    assert world.grid.blocked[world.grid.to_cell(0.6, 3.6)] == 0
    assert world.grid.blocked[world.grid.to_cell(1.5, 3.0)] == 1
    for seed in range(4):
        ep = sample_episode(world, seed)
        assert is_solvable(world, ep)
        assert run_episode(world, ep, expert_policy(), max_steps=600).metrics.success


def test_cli_assets_flag_validates_and_adapts(objaverse_house, table_file, tmp_path, monkeypatch):
    monkeypatch.setenv(ASSETS_ENV, "")
    res = CliRunner().invoke(app, ["validate", str(objaverse_house)])
    assert res.exit_code != 0
    res = CliRunner().invoke(app, ["--assets", str(table_file), "validate", str(objaverse_house)])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(app, ["--assets", str(table_file), "adapt", str(objaverse_house), "-o",
                                   str(tmp_path / "out"), "--steps", "2", "--json"])
    assert res.exit_code == 0, res.output
    assert load_house(tmp_path / "out" / "house.json", catalog=load_catalog(table_file))


def test_bad_tables_are_one_clear_error(tmp_path):
    p = tmp_path / "t.json"
    for doc, words in [({"assets": {"x": {"type": "Spaceship", "size": [1, 1, 1]}}}, "not a ProcTHOR object type"),
                       ({"assets": {"x": {"type": "Sofa", "size": [1, 1]}}}, "three positive extents"),
                       ({"assets": {"x": {"type": "Sofa", "size": [1, 1, 1], "footprint": [[0, 0]]}}}, "at least 3"),
                       ([], "expected a JSON object")]:
        p.write_text(json.dumps(doc), encoding="utf-8")
        with pytest.raises(ConfigError, match=words) as err:
            read_asset_table(p)
        assert str(p) in str(err.value)


def test_real_l_counter_outline_holds_its_children():
    """The L outline (derived from asset sizes) contains every object standing on the real L counter."""
    house = load_house(REAL_HOUSE, validate=False)
    geom = SceneGeometry.from_house(house)
    counter = next(o for o in house.objects if o.assetId.startswith("Countertop_L_"))
    fp = geom.footprint(counter.id)
    sx, sz = fp.size
    assert fp.polygon.area == pytest.approx(sx * sz - (sx - COUNTER_ARM_DEPTH) * (sz - COUNTER_ARM_DEPTH), rel=1e-6)
    assert fp.polygon.area < 0.8 * sx * sz
    outline = fp.polygon.buffer(0.02)
    assert counter.children and all(outline.covers(Point(c.position.x, c.position.z)) for c in counter.children)


@pytest.mark.parametrize("asset_id", ["Countertop_L_10x10", "Countertop_C_10x6"])
def test_wrapped_floor_of_l_and_c_counters_is_navigable(asset_id):
    """A big L or C counter against the back wall: the floor it wraps around is navigable and reachable."""
    size = load_catalog().asset(asset_id).size
    cx, cz = 4.5 - size[0] / 2, size[2] / 2 + 0.01
    house = H.one_room((5.0, 5.0), objects=[H.Obj(asset_id, cx, cz)])
    world = compile_world(house)
    d = COUNTER_ARM_DEPTH
    inside = (cx - size[0] / 2 + d + 0.45, cz + size[2] / 2 - 0.45) if asset_id.startswith("Countertop_C") else \
        (cx - 0.3, cz + size[2] / 2 - 0.45)
    comp, _ = world.grid.components(AGENT_RADIUS)
    r, c = world.grid.to_cell(*inside)
    assert world.grid.clearance[r, c] >= AGENT_RADIUS
    assert comp[r, c] == comp[world.grid.to_cell(1.0, 4.5)] != 0
    # The editing validator's raster agrees with the simulator's.
    geom = SceneGeometry.from_house(house)
    assert np.array_equal(NavRaster(geom).navigable(), world.grid.navigable(AGENT_RADIUS))
