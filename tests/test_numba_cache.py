"""numba always gets a writable cache folder for its compiled kernels, so a second process does not recompile, and
never one another user can write, so no one else's files run as code."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

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


# -- nothing is loaded from a cache folder another user can write -----------------------------------

KERNEL = "import numba\n\n\n@numba.njit(cache=True)\ndef twice(x):\n    return 2 * x\n"


class Payload:
    """Unpickling this runs code: it creates the file ``marker``."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def plant(folder: Path, module: Path, marker: Path) -> None:
    """Plant, where numba looks for ``module``'s kernel index, an index whose unpickling creates ``marker``."""
    from numba.core.caching import _CacheLocator

    sub = folder / _CacheLocator.get_suitable_cache_subpath(str(module))
    sub.mkdir(parents=True)
    abi = getattr(sys, "abiflags", "")
    (sub / f"{module.stem}.twice-4.py{sys.version_info[0]}{sys.version_info[1]}{abi}.nbi").write_bytes(
        pickle.dumps(Payload(marker)))


@pytest.mark.parametrize("how", ["foreign", "world-writable"])
def test_a_planted_numba_cache_folder_runs_no_code(tmp_path, how):
    (tmp_path / "kernels").mkdir()
    module = tmp_path / "kernels" / "tinykernel.py"
    module.write_text(KERNEL)
    planted = tmp_path / "planted"
    planted.mkdir()
    plant(planted, module, tmp_path / "pwned")
    if how == "foreign":
        for p in [planted, *planted.rglob("*")]:
            os.chown(p, 54321, 54321)
    else:
        planted.chmod(0o777)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(planted), "PYTHONPATH": os.pathsep.join(
        [str(tmp_path / "kernels"), str(Path(nc.__file__).parents[1])])}
    script = "import adaptenv, os, tinykernel; assert tinykernel.twice(2) == 4; print(os.environ['NUMBA_CACHE_DIR'])"
    run = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert not (tmp_path / "pwned").exists()
    used = run.stdout.strip()
    assert used != str(planted) and Path(used).name.startswith("adaptenv-numba-") and not Path(used).exists()
    [line] = run.stderr.strip().splitlines()
    assert str(planted) in line and "NUMBA_CACHE_DIR" in line
    if how == "foreign":
        return
    # the same process without adaptenv's check: numba unpickles the planted index (the test can fail)
    control = subprocess.run([sys.executable, "-c", "import tinykernel; tinykernel.twice(2)"], env=env,
                             capture_output=True, text=True, timeout=120)
    assert (tmp_path / "pwned").exists(), control.stderr


def test_a_foreign_fallback_folder_is_refused_and_a_new_one_is_made_private(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    monkeypatch.setattr(nc, "cache_dir_needed", lambda: nc.fallback_dir())
    monkeypatch.setenv("NUMBA_CACHE_DIR", "")
    monkeypatch.delitem(sys.modules, "numba", raising=False)
    nc.configure()  # a new fallback: made with mode 0o700 and used
    fallback = nc.fallback_dir()
    assert os.environ["NUMBA_CACHE_DIR"] == str(fallback) and fallback.stat().st_mode & 0o777 == 0o700
    assert capsys.readouterr().err == ""
    os.chown(fallback, 54321, 54321)  # the same name, made by another user
    monkeypatch.setenv("NUMBA_CACHE_DIR", "")
    nc.configure()
    used = Path(os.environ["NUMBA_CACHE_DIR"])
    assert used != fallback and used.stat().st_uid == os.getuid() and used.stat().st_mode & 0o777 == 0o700
    [line] = capsys.readouterr().err.splitlines()
    assert f"{fallback} belongs to another user (uid 54321)" in line
    assert nc.unsafe(fallback) and nc.unsafe(tmp_path / "missing") is None


def test_a_writable_in_tree_cache_that_others_may_write_is_not_used(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    for name in nc.KERNEL_PACKAGES:
        (tmp_path / "pkg" / name / "__pycache__").mkdir(parents=True)
    (tmp_path / "pkg" / "sim" / "__pycache__").chmod(0o777)
    assert nc.cache_dir_needed(package=tmp_path / "pkg", user=tmp_path / "home") == nc.fallback_dir()
