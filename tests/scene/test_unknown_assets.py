"""Objaverse-asset houses without an asset table: the error names the command that builds one, and
--skip-unknown-assets leaves out unknown objects resting on others while refusing unknown top-level ones."""

from __future__ import annotations

import json
import logging

import pytest
from typer.testing import CliRunner

from adaptenv.agents.houses import load_house_set
from adaptenv.cli import app
from adaptenv.errors import HouseError
from adaptenv.scene.assets import SKIP_UNKNOWN_ENV, load_catalog
from adaptenv.scene.house import load_house
from tests.conftest import CHILD_IDS, FLOOR_ID, REAL_HOUSE
from tests.conftest import objaverse_house_doc as objaverse_house


@pytest.fixture(autouse=True)
def _no_process_setting(monkeypatch):
    """Each test starts without --skip-unknown-assets (the CLI's flag sets it for the process)."""
    monkeypatch.setenv(SKIP_UNKNOWN_ENV, "0")  # restored (unset) after the test


def test_the_error_names_the_command_that_builds_the_table(tmp_path):
    path = tmp_path / "objaverse.json"
    path.write_text(json.dumps(objaverse_house(floor=False)), encoding="utf-8")
    with pytest.raises(HouseError) as err:
        load_house(path)
    assert "adaptenv assets from-objathor" in str(err.value) and "--skip-unknown-assets" in str(err.value)
    with pytest.raises(KeyError, match="adaptenv assets from-objathor"):
        load_catalog().asset(CHILD_IDS[0])


def test_skipping_leaves_out_unknown_children_and_counts_them(tmp_path):
    path = tmp_path / "objaverse.json"
    path.write_text(json.dumps(objaverse_house(floor=False)), encoding="utf-8")
    house = load_house(path, skip_unknown=True)
    assert sorted(house.dropped_children) == sorted([("Book|surface|2|0", CHILD_IDS[0]),
                                                     ("Ladle|surface|2|1", CHILD_IDS[1]),
                                                     ("RemoteControl|surface|3|18", CHILD_IDS[1])])
    ids = {o.id for o, _ in house.iter_objects()}
    assert "Book|surface|2|0" not in ids and "Egg|surface|2|4" in ids  # only the unknown ones go
    real = load_house(REAL_HOUSE)
    assert len(list(house.iter_objects())) == len(list(real.iter_objects())) - 3


def test_an_unknown_floor_object_is_refused_naming_object_and_asset(tmp_path):
    path = tmp_path / "objaverse.json"
    path.write_text(json.dumps(objaverse_house(floor=True)), encoding="utf-8")
    with pytest.raises(HouseError) as err:
        load_house(path, skip_unknown=True)
    text = str(err.value)
    assert "'Fridge|2|1'" in text and FLOOR_ID in text and "from-objathor" in text
    assert "more problem" not in text  # the children were left out, the one problem is the floor object


def test_a_house_set_counts_the_left_out_children_in_one_line(tmp_path, caplog):
    lines = [json.dumps(objaverse_house(floor=False)), json.dumps(objaverse_house(floor=True))]
    dataset = tmp_path / "objaverse.jsonl"
    dataset.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with caplog.at_level(logging.WARNING):
        hs = load_house_set(str(dataset), skip_unknown=True)
    assert hs.names == ["house-000000"] and hs.dropped_children == 3
    assert [s.name for s in hs.skipped] == ["house-000001"] and "'Fridge|2|1'" in hs.skipped[0].reason
    counted = [r.getMessage() for r in caplog.records if "left out" in r.getMessage()]
    assert counted == [f"--houses {dataset}: left out 3 objects resting on others in 1 of 2 houses, of 2 unknown "
                       "asset ids (--skip-unknown-assets; the agent never collides with them, and targets are floor "
                       "objects)"]
    with pytest.raises(Exception, match="from-objathor"):  # without the flag: no house can be used
        load_house_set(str(dataset), strict=True)


def test_the_cli_flag_works_before_or_after_the_command(tmp_path):
    path = tmp_path / "objaverse.json"
    path.write_text(json.dumps(objaverse_house(floor=False)), encoding="utf-8")
    runner = CliRunner()
    refused = runner.invoke(app, ["validate", str(path)])
    assert refused.exit_code == 1 and "adaptenv assets from-objathor" in refused.output
    for args in (["--skip-unknown-assets", "validate", str(path)], ["validate", str(path), "--skip-unknown-assets"]):
        res = runner.invoke(app, args)
        assert res.exit_code == 0, res.output
        assert "1 file valid" in res.output
        # what was left out is counted, as evaluate and the other --houses readers count it
        assert res.output.splitlines()[-1] == ("left out 3 objects resting on others, of 2 unknown asset ids "
                                               "(--skip-unknown-assets; the agent never collides with them, and "
                                               "targets are floor objects)")
    doc = json.loads(runner.invoke(app, ["validate", str(path), "--json", "--skip-unknown-assets"]).output)
    assert doc["valid"] and doc["left_out"] == {"objects": 3, "houses": 1, "asset_ids": sorted(set(CHILD_IDS[:2]))}
    dataset = tmp_path / "objaverse.jsonl"
    dataset.write_text(json.dumps(objaverse_house(floor=False)) + "\n" + json.dumps(objaverse_house(floor=False))
                       + "\n", encoding="utf-8")
    res = runner.invoke(app, ["validate", f"{dataset}:1:2", str(dataset), "--skip-unknown-assets"])
    assert res.exit_code == 0 and res.output.splitlines()[-2:] == [
        "3 houses valid", "left out 9 objects resting on others in 3 of 3 houses, of 2 unknown asset ids "
        "(--skip-unknown-assets; the agent never collides with them, and targets are floor objects)"]
