"""House datasets (one house JSON per line, .jsonl or .jsonl.gz, sliced) load wherever a house set does,
and ``adaptenv houses export`` splits them into house files."""

from __future__ import annotations

import gzip
import json
import logging

import pytest
from typer.testing import CliRunner

from adaptenv.agents.houses import load_house_set
from adaptenv.cli import app
from adaptenv.errors import ConfigError, HouseError
from adaptenv.scene.dataset import dataset_lines, parse_dataset_spec
from adaptenv.scene.house import load_house
from tests.conftest import REAL_HOUSE
from tests.sim import helpers as H


def _lines() -> list[str]:
    """Four houses, one JSON document per line: a small usable one, one without a target, one whose target is seen
    from everywhere, and a real ProcTHOR-10K house."""
    docs = [H.corridor_house().to_dict(), H.one_room().to_dict(),
            H.one_room((2.0, 3.6), objects=[H.Obj(H.LOW_TARGET, 1.0, 1.8)]).to_dict(),
            json.loads(REAL_HOUSE.read_text(encoding="utf-8"))]
    return [json.dumps(d) for d in docs]


@pytest.fixture
def datasets(tmp_path):
    """The same four lines as .jsonl (with a blank last line) and as .jsonl.gz."""
    text = "\n".join(_lines()) + "\n\n"
    plain = tmp_path / "houses.jsonl"
    plain.write_text(text, encoding="utf-8")
    packed = tmp_path / "houses.jsonl.gz"
    with gzip.open(packed, "wt", encoding="utf-8") as f:
        f.write(text)
    return plain, packed


def test_jsonl_and_gz_load_with_python_slices(datasets):
    plain, packed = datasets
    full = load_house_set(packed)
    assert full.names == ["house-000000", "house-000003"]
    assert [s.name for s in full.skipped] == ["house-000001", "house-000002"]
    assert load_house_set(plain).names == full.names
    assert load_house_set(f"{packed}:3:").names == ["house-000003"]
    assert load_house_set(f"{plain}::2").names == ["house-000000"]
    assert load_house_set(f"{packed}:0:4:3").names == ["house-000000", "house-000003"]
    assert load_house_set(f"{packed}:2:100").names == ["house-000003"]  # a stop past the end stops at the end


def test_slice_past_the_end_and_bad_slices_are_clear_errors(datasets):
    _, packed = datasets
    with pytest.raises(ConfigError, match=r"selects no house \(.*has 5 lines\); pick line indices below 5"):
        load_house_set(f"{packed}:7:9")
    for bad, words in [(":5", "is not a slice START:STOP"), (":-2:", "non-negative"), (":3:1", "STOP 1 is not above"),
                       (":::0", "step is 0"), ("::0", "STOP 0 is not above START 0")]:
        with pytest.raises(ConfigError, match=words):
            parse_dataset_spec(f"{packed}{bad}")
    with pytest.raises(ConfigError, match="no such dataset file"):
        load_house_set(packed.with_name("missing.jsonl.gz"))


def test_bad_lines_are_named_by_line_number_and_reading_stops_at_the_slice_end(tmp_path, caplog):
    good, *_ = _lines()
    path = tmp_path / "d.jsonl"
    path.write_text("\n".join([good, good, "{not json", "[1, 2]"]) + "\n", encoding="utf-8")
    assert len(load_house_set(f"{path}:0:2").names) == 2  # line 3 is never read
    with pytest.raises(ConfigError, match=r"^\S*d.jsonl line 3 \(index 2\): not valid JSON .*one house JSON object per line$"):
        load_house_set(path)
    with pytest.raises(ConfigError, match=r"d.jsonl line 4 \(index 3\): a JSON list, not a house object"):
        load_house_set(f"{path}:3:")
    # a JSON object that is not a house: skipped like an invalid house file, its line named; an error with strict
    path.write_text("\n".join([good, json.dumps({"rooms": "none"})]) + "\n", encoding="utf-8")
    with caplog.at_level(logging.WARNING, logger="adaptenv.agents.houses"):
        hs = load_house_set(path)
    assert hs.names == ["house-000000"] and "d.jsonl line 2 (index 1): at " in hs.skipped[0].reason
    with pytest.raises(ConfigError, match=r"house-000001 cannot be used: \S*d.jsonl line 2 \(index 1\): "):
        load_house_set(path, strict=True)


def test_reading_is_streamed_line_by_line(datasets):
    _, packed = datasets
    lines = dataset_lines(parse_dataset_spec(f"{packed}:1:3"))
    assert next(lines)[0] == 1  # a generator: nothing is read before it is asked for
    assert [i for i, _ in lines] == [2]


def test_export_round_trips_and_a_single_house_loader_points_to_it(datasets, tmp_path):
    plain, packed = datasets
    out = tmp_path / "exported"
    res = CliRunner().invoke(app, ["houses", "export", f"{packed}:1:", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "wrote 3 house files" in res.output
    files = sorted(out.glob("*.json"))
    assert [f.name for f in files] == ["house-000001.json", "house-000002.json", "house-000003.json"]
    lines = plain.read_text(encoding="utf-8").splitlines()
    for f in files:
        assert json.loads(f.read_text(encoding="utf-8")) == json.loads(lines[int(f.stem[-6:])])
        load_house(f)
    assert load_house_set(out).names == load_house_set(f"{packed}:1:").names  # same names, same houses
    with pytest.raises(HouseError, match="house dataset .*adaptenv houses export"):
        load_house(packed)
    res = CliRunner().invoke(app, ["houses", "export", str(REAL_HOUSE), "-o", str(out)])
    assert isinstance(res.exception, ConfigError) and "not a house dataset" in str(res.exception)


def test_the_gymnasium_env_takes_a_dataset(datasets):
    import gymnasium as gym

    _, packed = datasets
    env = gym.make("adaptenv/ObjectNav-v0", houses=f"{packed}:0:1")
    obs, _ = env.reset(seed=0)
    assert env.unwrapped.world.name == "house_0" and obs["depth"].shape
    with pytest.raises(ConfigError, match="is one path, not a list of houses"):
        gym.make("adaptenv/ObjectNav-v0", houses=str(REAL_HOUSE))


def test_validate_checks_every_line_and_names_the_bad_one(tmp_path):
    doc = json.loads(_lines()[0])
    doc["doors"][0]["wall0"] = "nope"
    path = tmp_path / "d.jsonl"
    path.write_text("\n".join([_lines()[0], json.dumps(doc)]) + "\n", encoding="utf-8")
    res = CliRunner().invoke(app, ["validate", str(path)])
    assert res.exit_code == 1
    assert res.output.splitlines()[0].startswith(f"{path} line 2 (index 1): at doors[0].wall0, ")
    assert res.output.splitlines()[-1] == "1 problem in 1 of 2 houses"
    assert CliRunner().invoke(app, ["validate", f"{path}:0:1"]).output.strip() == "1 house valid"
    # a slice names its lines as a whole file does: line 2 is index 2 - 1 = 1 whatever the slice's START
    sliced = CliRunner().invoke(app, ["validate", f"{path}:1:2"])
    assert sliced.output.splitlines()[0].startswith(f"{path} line 2 (index 1): at doors[0].wall0, ")
