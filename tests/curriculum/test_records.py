"""Run files are written atomically and are ordinary readable files."""

from __future__ import annotations

import stat

from adaptenv.curriculum.records import atomic_write_text


def test_atomic_write_replaces_whole_files_readable_by_others(tmp_path):
    path = atomic_write_text(tmp_path / "sub" / "a.txt", "one")
    atomic_write_text(path, "two")
    assert path.read_text() == "two"
    assert stat.S_IMODE(path.stat().st_mode) == 0o644
    assert [p.name for p in path.parent.iterdir()] == ["a.txt"]  # no temporary file left behind
