"""Every command that takes one house reads a house file or a one-house dataset slice (FILE.jsonl.gz:2:3)."""

from __future__ import annotations

import gzip
import json

import pytest
from typer.testing import CliRunner

from adaptenv.cli import app
from adaptenv.errors import ConfigError
from adaptenv.scene.dataset import load_one_house
from adaptenv.scene.house import save_house
from tests.sim import helpers as H


@pytest.fixture
def dataset(tmp_path):
    """A gzipped dataset of three houses; line index 1 is the corridor house."""
    houses = [H.one_room(), H.corridor_house(), H.two_rooms()]
    path = tmp_path / "houses.jsonl.gz"
    with gzip.open(path, "wt", encoding="utf-8") as f:
        f.write("".join(json.dumps(h.to_dict()) + "\n" for h in houses))
    return path


def test_the_resolver_reads_a_file_or_one_line(dataset, tmp_path):
    name, house = load_one_house(f"{dataset}:1:2")
    assert name == "house-000001" and house.to_dict() == H.corridor_house().to_dict()
    file = save_house(H.corridor_house(), tmp_path / "corridor.json")
    assert load_one_house(file)[0] == "corridor"
    with pytest.raises(ConfigError, match=r"selects more than one house.*:0:1"):
        load_one_house(f"{dataset}:0:3")
    with pytest.raises(ConfigError, match="no such house file"):
        load_one_house(tmp_path / "nope.json")


def test_render_rollout_analyze_and_audit_take_a_slice(dataset, tmp_path):
    runner = CliRunner()
    one = f"{dataset}:1:2"
    res = runner.invoke(app, ["render", one, "-o", str(tmp_path / "map.png"), "--size", "256"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "map.png").stat().st_size > 0
    traj = tmp_path / "traj.json"
    res = runner.invoke(app, ["rollout", one, "--policy", "expert", "-o", str(traj)])
    assert res.exit_code == 0, res.output
    assert json.loads(traj.read_text(encoding="utf-8"))["house"] == one
    res = runner.invoke(app, ["analyze", one, str(traj), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)["outcome"]["success"] is True
    res = runner.invoke(app, ["render", one, "-t", str(traj), "-o", str(tmp_path / "ep.png"), "--size", "256"])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["audit", one, one])
    assert res.exit_code == 0 and "0 moved object(s)" in res.output, res.output
    res = runner.invoke(app, ["adapt", one, "--trajectory", str(traj), "--steps", "1", "-o", str(tmp_path / "ad"),
                              "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "ad" / "summary.json").read_text())["house"] == one  # one house: OUT itself


def test_several_houses_are_refused_where_one_is_expected(dataset, tmp_path):
    res = CliRunner().invoke(app, ["render", f"{dataset}:0:2", "-o", str(tmp_path / "map.png")])
    assert res.exit_code != 0
    assert "selects more than one house" in str(res.exception) and not (tmp_path / "map.png").exists()
