"""File helpers: atomic writes that never follow a link, one writer per folder, bounded reads."""

from __future__ import annotations

import gzip
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from adaptenv import limits
from adaptenv.errors import ConfigError
from adaptenv.files import (
    LOCK,
    FileRefused,
    FolderLock,
    JSONTooDeep,
    atomic_path,
    atomic_write_text,
    gunzip,
    json_depth,
    loads_json,
    open_append,
    read_bytes,
)

README = Path(__file__).parents[1] / "README.md"


def test_an_atomic_write_replaces_a_link_and_leaves_its_target_alone(tmp_path):
    target = tmp_path / "user.json"
    target.write_text("the user's own file")
    out = tmp_path / "out"
    out.mkdir()
    (out / "house.json").symlink_to("../user.json")
    atomic_write_text(out / "house.json", "{}")
    assert not (out / "house.json").is_symlink() and (out / "house.json").read_text() == "{}"
    assert target.read_text() == "the user's own file"
    assert sorted(p.name for p in out.iterdir()) == ["house.json"]  # no temporary file left


def test_an_atomic_path_keeps_the_old_file_when_writing_fails(tmp_path):
    path = tmp_path / "map.png"
    path.write_bytes(b"old")
    with pytest.raises(RuntimeError), atomic_path(path) as tmp:
        assert tmp.suffix == ".png" and tmp.parent == tmp_path  # same folder, same suffix (image writers read it)
        tmp.write_bytes(b"half")
        raise RuntimeError
    assert path.read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == ["map.png"]


def test_an_append_refuses_a_link(tmp_path):
    (tmp_path / "user.csv").write_text("mine\n")
    (tmp_path / "metrics.csv").symlink_to("user.csv")
    with pytest.raises(ConfigError, match="metrics.csv: is a symbolic link"):
        open_append(tmp_path / "metrics.csv")
    assert (tmp_path / "user.csv").read_text() == "mine\n"
    with open_append(tmp_path / "log.csv") as f:
        f.write("a\n")
    assert (tmp_path / "log.csv").read_text() == "a\n"


def test_a_folder_has_one_writer_and_is_left_as_found(tmp_path):
    out = tmp_path / "new" / "out"
    first = FolderLock(out).acquire("-o out")
    assert FolderLock(out).holder() == os.getpid()
    with pytest.raises(ConfigError, match=rf"^-o out: another adaptenv run \(process id {os.getpid()}\)"):
        FolderLock(out).acquire("-o out")
    first.release()
    assert not (tmp_path / "new").exists()  # the folders it made, empty again, are gone
    assert FolderLock(out).holder() is None
    second = FolderLock(tmp_path).acquire("-o tmp")
    (tmp_path / "kept.txt").write_text("output")
    second.release()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.txt"]  # the lock file goes, the output stays


def test_a_lock_held_by_another_process_names_its_process_id(tmp_path):
    holder = subprocess.Popen([sys.executable, "-c", "import sys\nfrom adaptenv.files import FolderLock\n"
                               "lock = FolderLock(sys.argv[1]).acquire('x')\nprint('held', flush=True)\n"
                               "sys.stdin.read()\nlock.release()\n", str(tmp_path)],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                              env={**os.environ, "PYTHONPATH": str(Path(__file__).parents[1] / "src")})
    try:
        assert holder.stdout.readline().strip() == "held"
        assert FolderLock(tmp_path).holder() == holder.pid
        with pytest.raises(ConfigError, match=f"process id {holder.pid}"):
            FolderLock(tmp_path).acquire("-o out")
    finally:
        holder.communicate("")
    assert not (tmp_path / LOCK).exists()
    FolderLock(tmp_path).acquire("-o out").release()  # free again


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
