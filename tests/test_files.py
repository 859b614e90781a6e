"""Bounded reads (adaptenv.files): only regular files, each kind up to its limit, JSON up to JSON_DEPTH_MAX deep."""

from __future__ import annotations

import gzip
import json
import os
from pathlib import Path

import pytest

from adaptenv import limits
from adaptenv.files import FileRefused, JSONTooDeep, gunzip, json_depth, loads_json, read_bytes

README = Path(__file__).parents[1] / "README.md"


def test_a_regular_file_is_read_whole(tmp_path):
    (tmp_path / "a.json").write_bytes(b'{"a": [1]}')
    assert read_bytes(tmp_path / "a.json", 10, "thing") == b'{"a": [1]}'


@pytest.mark.parametrize("make, kind", [(os.mkfifo, "a FIFO"), (os.mkdir, "a folder")])
def test_a_fifo_or_a_folder_is_refused_without_reading(tmp_path, make, kind):
    make(tmp_path / "x")
    with pytest.raises(FileRefused, match=f"is {kind}.*not a regular file; pass the thing as a file"):
        read_bytes(tmp_path / "x", 10, "thing")


def test_a_device_is_refused():
    with pytest.raises(FileRefused, match="/dev/zero: is a character device"):
        read_bytes("/dev/zero", 10, "thing")


def test_a_file_over_its_limit_is_refused_from_its_size(tmp_path):
    with open(tmp_path / "big", "wb") as f:
        f.truncate(2 * limits.MiB + 1)
    with pytest.raises(FileRefused, match=r"2\.0 MiB, over the 2\.0 MiB limit of the thing \(README"):
        read_bytes(tmp_path / "big", 2 * limits.MiB, "thing")
    assert read_bytes(tmp_path / "big", 3 * limits.MiB, "thing") == bytes(2 * limits.MiB + 1)


def test_a_gzip_bomb_stops_at_the_limit(tmp_path):
    raw = gzip.compress(bytes(10_000))
    assert len(gunzip(raw, 10_000, "thing", "p")) == 10_000
    with pytest.raises(FileRefused, match="p: decompresses to over the 9,999 bytes limit of the thing"):
        gunzip(raw, 9_999, "thing", "p")


def test_json_depth_is_capped_deep_or_very_deep():
    ok = "[" * limits.JSON_DEPTH_MAX + "]" * limits.JSON_DEPTH_MAX
    assert json_depth(loads_json(ok)) == limits.JSON_DEPTH_MAX
    for depth in (limits.JSON_DEPTH_MAX + 1, 100_000):
        with pytest.raises(JSONTooDeep, match=f"more than {limits.JSON_DEPTH_MAX} deep"):
            loads_json("[" * depth + "]" * depth)
    assert json_depth(json.loads('{"a": {"b": [1, {"c": 2}]}}')) == 4 and json_depth(3) == 0


def test_the_readme_states_the_limits():
    text = README.read_text(encoding="utf-8")
    rows = {"house JSON": limits.HOUSE_BYTES, "one line of a house dataset": limits.DATASET_LINE_BYTES,
            "experiment config, LLM config": limits.CONFIG_BYTES, "`--assets` table": limits.ASSET_TABLE_BYTES,
            "trajectory": limits.TRAJECTORY_BYTES, "AI2-THOR log": limits.AI2THOR_LOG_BYTES,
            "a loop's `state.json`": limits.STATE_BYTES, "objathor annotations": limits.ANNOTATIONS_BYTES}
    for name, size in rows.items():
        shown = f"{size // limits.MiB} MiB" if size < 1024 * limits.MiB else f"{size // (1024 * limits.MiB)} GiB"
        assert any(line.startswith(f"| {name}") and line.endswith(f"| {shown} |") for line in text.splitlines()), name
    assert f"at most {limits.JSON_DEPTH_MAX} deep" in text
