"""numba always gets a writable cache folder for its compiled kernels, so a second process does not recompile."""

from __future__ import annotations

import os
import sys

from adaptenv import _numba_cache as nc


def test_unwritable_sources_and_home_fall_back_to_a_temporary_folder(tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("")  # nothing can be made under a file, whoever runs the test
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    assert not nc.writable(blocker / "pkg")
    assert nc.cache_dir_needed(package=blocker / "pkg", user=blocker / "home") == nc.fallback_dir()
    monkeypatch.setattr(nc, "cache_dir_needed", lambda: tmp_path / "fallback")
    monkeypatch.setenv("NUMBA_CACHE_DIR", "")  # restored after the test, as is numba's config (left alone)
    monkeypatch.delitem(sys.modules, "numba", raising=False)
    nc.configure()
    assert os.environ["NUMBA_CACHE_DIR"] == str(tmp_path / "fallback") and (tmp_path / "fallback").is_dir()


def test_a_writable_place_leaves_numba_alone(tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    assert nc.cache_dir_needed(package=tmp_path / "pkg", user=blocker / "home") is None  # next to the sources
    assert nc.cache_dir_needed(package=blocker / "pkg", user=tmp_path / "home") is None  # the user's cache
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "mine"))
    assert nc.cache_dir_needed(package=blocker / "pkg", user=blocker / "home") is None  # the user's own choice
