"""Unusable houses are skipped in one place (``load_house_set``), with a reason, or fail with --strict."""

from __future__ import annotations

import json
import logging

import pytest
from typer.testing import CliRunner

from adaptenv.agents.houses import load_house_set
from adaptenv.cli import app
from adaptenv.errors import ConfigError
from adaptenv.scene.house import save_house
from tests.sim import helpers as H


@pytest.fixture
def mixed_folder(tmp_path):
    """One usable house and three that cannot be used: no target, target seen from everywhere, bad JSON."""
    d = tmp_path / "houses"
    save_house(H.corridor_house(), d / "a_good.json")
    save_house(H.one_room(), d / "b_no_target.json")
    save_house(H.one_room((2.0, 3.6), objects=[H.Obj(H.LOW_TARGET, 1.0, 1.8)]), d / "c_trivial.json")
    (d / "d_broken.json").write_text("{not json", encoding="utf-8")
    return d


def test_load_house_set_skips_unusable_houses_with_reasons(mixed_folder, caplog):
    with caplog.at_level(logging.WARNING, logger="adaptenv.agents.houses"):
        hs = load_house_set(mixed_folder)
    assert hs.names == ["a_good"]
    reasons = {s.name: s.reason for s in hs.skipped}
    assert sorted(reasons) == ["b_no_target", "c_trivial", "d_broken"]
    assert "no ObjectNav target object" in reasons["b_no_target"]
    assert "GarbageCan" in reasons["c_trivial"] and "every reachable cell" in reasons["c_trivial"]
    assert "not valid JSON" in reasons["d_broken"]
    warned = [r.getMessage() for r in caplog.records]
    assert len(warned) == 3 and all(m.startswith("skipping house ") for m in warned)
    assert all("\n" not in m for m in warned)


def test_load_house_set_strict_and_all_unusable(mixed_folder, tmp_path):
    with pytest.raises(ConfigError, match="b_no_target cannot be used.*--strict"):
        load_house_set(mixed_folder, strict=True)
    for f in mixed_folder.glob("a_*.json"):
        f.unlink()
    with pytest.raises(ConfigError, match="none of the 3 houses"):
        load_house_set(mixed_folder)


def test_cli_evaluate_skips_and_counts(mixed_folder, tmp_path):
    out = tmp_path / "eval"
    res = CliRunner().invoke(app, ["evaluate", "--policy", "expert", "--houses", str(mixed_folder),
                                   "--episodes", "2", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "skipped 3 house(s)" in res.output
    summary = json.loads((out / "summary.json").read_text())
    assert sorted(summary["skipped_houses"]) == ["b_no_target", "c_trivial", "d_broken"]
    res = CliRunner().invoke(app, ["evaluate", "--policy", "expert", "--houses", str(mixed_folder),
                                   "--episodes", "2", "-o", str(tmp_path / "e2"), "--strict"])
    assert res.exit_code != 0
    assert isinstance(res.exception, ConfigError)


def test_cli_adapt_folder_skips(mixed_folder, tmp_path):
    out = tmp_path / "adapt"
    res = CliRunner().invoke(app, ["adapt", str(mixed_folder), "-o", str(out), "--steps", "1"])
    assert res.exit_code == 0, res.output
    doc = json.loads((out / "summary.json").read_text())
    assert doc["adapted"] == 1 and doc["skipped"] == 3
    assert (out / "a_good" / "house.json").is_file()
    res = CliRunner().invoke(app, ["adapt", str(mixed_folder), "-o", str(tmp_path / "a2"), "--strict"])
    assert res.exit_code != 0 and isinstance(res.exception, ConfigError)


def test_cli_rollout_on_one_unusable_house_keeps_its_error(mixed_folder, tmp_path):
    res = CliRunner().invoke(app, ["rollout", str(mixed_folder / "c_trivial.json"), "-o", str(tmp_path / "t.json")])
    assert res.exit_code != 0
    assert "no episode exists" in str(res.exception) and "GarbageCan" in str(res.exception)


def test_loop_and_experiment_check_house_sets_up_front(mixed_folder, tmp_path):
    from adaptenv.cli.curriculum import check_house_sets

    said = []
    assert check_house_sets([str(mixed_folder), str(mixed_folder)], False, said.append) == {str(mixed_folder): 3}
    assert len(said) == 1 and "skipping 3 house(s)" in said[0] and "b_no_target" in said[0]
    res = CliRunner().invoke(app, ["loop", "--houses", str(mixed_folder), "-o", str(tmp_path / "run"), "--strict"])
    assert res.exit_code != 0 and isinstance(res.exception, ConfigError)
    assert not (tmp_path / "run").exists()


def test_a_house_whose_only_targets_hang_on_the_wall_says_so(tmp_path):
    from adaptenv.scene.assets import load_catalog

    tv = next(a for a in load_catalog().assets.values() if a.object_type == "Television")
    house = H.one_room(objects=[H.Obj(tv.asset_id, 2.0, 0.2)])
    house.objects[0].position.y += 1.2  # mounted on the wall, its bottom well above the floor
    save_house(house, tmp_path / "wall_tv.json")
    with pytest.raises(ConfigError) as err:
        load_house_set(tmp_path)
    assert "only ObjectNav target objects are wall-mounted (Television)" in str(err.value)
    assert "has no ObjectNav target" not in str(err.value)
