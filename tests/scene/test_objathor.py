"""objathor's annotation file becomes the --assets table of an Objaverse-asset house (adaptenv assets from-objathor)."""

from __future__ import annotations

import gzip
import json

import pytest
from typer.testing import CliRunner

from adaptenv.cli import app
from adaptenv.errors import ConfigError
from adaptenv.scene.assets import ASSETS_ENV, load_catalog, read_asset_table
from adaptenv.scene.house import load_house, save_house
from adaptenv.scene.objathor import FALLBACK_TYPE, annotation_size, read_annotations, type_for_name
from tests.sim import helpers as H

SOFA, BED, BARREL, LAMP, NOSIZE = ("0a" * 16, "9f" * 16, "b1" * 16, "c2" * 16, "d3" * 16)


def box(x: float, y: float, z: float) -> dict:
    """``thor_metadata`` as objathor stores it: AI2-THOR's asset box as min/max corners (m)."""
    return {"assetMetadata": {"name": "x", "objectType": "Undefined", "primaryProperty": "Static",
                              "secondaryProperties": [],
                              "boundingBox": {"min": {"x": -x / 2, "y": 0.0, "z": -z / 2},
                                              "max": {"x": x / 2, "y": y, "z": z / 2}}}}


ANNOTATIONS = {
    SOFA: {"uid": SOFA, "category": "sectional couch", "synset": "sofa.n.01", "most_specific_lemma": "sofa",
           "ref_category": "Objaverse", "split": "train", "size": [200, 90, 85], "scale": 0.85,
           "thor_metadata": box(2.0, 0.85, 0.9)},
    BED: {"uid": BED, "category": "double bed", "synset": "bed.n.01", "ref_category": "Bed", "split": "val",
          "thor_metadata": box(1.4, 0.6, 2.1)},
    LAMP: {"uid": LAMP, "category": "reading light", "synset": "floor_lamp.n.01", "width": 40, "depth": 40,
           "height": 160},
    BARREL: {"uid": BARREL, "category": "wooden barrel", "synset": "barrel.n.02", "thor_metadata": box(0.6, 0.9, 0.6)},
    NOSIZE: {"uid": NOSIZE, "category": "chair", "synset": "chair.n.01", "thor_metadata": {}},
}


@pytest.fixture
def annotations_file(tmp_path):
    p = tmp_path / "annotations.json.gz"
    p.write_bytes(gzip.compress(json.dumps(ANNOTATIONS).encode()))
    return p


def test_names_map_to_catalog_types():
    assert [type_for_name(n) for n in ("sofa.n.01", "straight_chair.n.01", "ashcan.n.01", "television_receiver.n.01",
                                       "eames chair", "ObjaDiningTable", "Painting", "chest of drawers", "books")] == [
        "Sofa", "Chair", "GarbageCan", "Television", "Chair", "DiningTable", "Painting", "Dresser", "Book"]
    assert type_for_name("wooden barrel") is None and type_for_name("Objaverse") is None


def test_sizes_come_from_the_thor_box_else_the_cm_estimate():
    assert annotation_size(ANNOTATIONS[SOFA]) == (2.0, 0.85, 0.9)  # the box, not the annotator's cm
    assert annotation_size({"thor_metadata": {"assetMetadata": {"boundingBox": {"x": 1, "y": 2, "z": 3}}}}) == (1, 2, 3)
    assert annotation_size(ANNOTATIONS[LAMP]) == (0.4, 1.6, 0.4)
    assert annotation_size({"size": [120, 3, 70]}) == (1.2, 0.7, 0.03)  # [width, depth, height] cm
    assert annotation_size(ANNOTATIONS[NOSIZE]) is None


def test_cli_builds_a_table_an_objaverse_house_loads_with(annotations_file, tmp_path, monkeypatch):
    monkeypatch.setenv(ASSETS_ENV, "")
    table = tmp_path / "objaverse_assets.json"
    res = CliRunner().invoke(app, ["assets", "from-objathor", str(annotations_file), "-o", str(table), "--json"])
    assert res.exit_code == 0, res.output
    counts = json.loads(res.output)
    assert counts["written"] == 4 and counts["unmapped"] == 1 and counts["skipped_no_size"] == 1
    assert counts["mapped_by"] == {"ref_category": 1, "most_specific_lemma": 1, "synset": 1}
    rows = read_asset_table(table)
    assert {a: rows[a].object_type for a in rows} == {SOFA: "Sofa", BED: "Bed", LAMP: "FloorLamp",
                                                      BARREL: FALLBACK_TYPE}
    assert rows[SOFA].size == (2.0, 0.85, 0.9) and rows[BED].split == "val"
    assert "wooden barrel" in json.loads(table.read_text())["assets"][BARREL]["note"]

    monkeypatch.setenv(ASSETS_ENV, str(table))
    house = H.two_rooms(objects=[H.Obj(SOFA, 2.0, 0.6), H.Obj(BED, 6.0, 2.0), H.Obj(BARREL, 1.0, 3.0)],
                        agent=(2.0, 2.0, 0.0))
    path = save_house(house, tmp_path / "objaverse_house.json")
    monkeypatch.setenv(ASSETS_ENV, "")
    assert load_house(path, catalog=load_catalog(table))
    res = CliRunner().invoke(app, ["--assets", str(table), "validate", str(path)])
    assert res.exit_code == 0, res.output

    res = CliRunner().invoke(app, ["assets", "from-objathor", str(annotations_file), "-o", str(table),
                                   "--unmapped", "skip"])
    assert res.exit_code == 0, res.output
    assert BARREL not in read_asset_table(table) and "3 assets" in res.output


def test_one_asset_annotation_file_is_read(tmp_path):
    p = tmp_path / "annotations.json.gz"
    p.write_bytes(gzip.compress(json.dumps(ANNOTATIONS[BED]).encode()))
    assert list(read_annotations(p)) == [BED]


@pytest.mark.parametrize(("content", "words"), [
    (b"not json", "cannot read it as JSON"),
    (gzip.compress(b"{", mtime=0)[:10], "cannot read it as JSON"),
    (json.dumps({"assets": {"x": {"type": "Sofa", "size": [1, 1, 1]}}}).encode(), "not an objathor annotation file"),
    (json.dumps([1, 2]).encode(), "not an objathor annotation file"),
], ids=["not-json", "truncated-gzip", "an-asset-table", "a-list"])
def test_wrong_files_are_one_clear_error(tmp_path, content, words):
    p = tmp_path / "wrong.json"
    p.write_bytes(content)
    res = CliRunner().invoke(app, ["assets", "from-objathor", str(p), "-o", str(tmp_path / "t.json")])
    assert isinstance(res.exception, ConfigError)
    msg = str(res.exception)
    assert words in msg and str(p) in msg and "download_annotations" in msg and "\n" not in msg
    with pytest.raises(ConfigError, match="no such annotation file"):
        read_annotations(tmp_path / "missing.json.gz")
