"""adaptenv.files: atomic writes that never follow a link, appends that refuse one, one writer per folder."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from adaptenv.errors import ConfigError
from adaptenv.files import LOCK, FolderLock, atomic_path, atomic_write_text, open_append


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
