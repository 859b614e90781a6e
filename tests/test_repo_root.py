"""The repository root holds only what a newcomer expects: no stray, empty or scratch files."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ALLOWED = {".ci", ".gitignore", "LICENSE", "Makefile", "README.md", "configs", "constraints.txt", "docs", "examples",
           "pyproject.toml", "src", "tests", "tools"}
"""Every file and folder tracked at the root; a new one is added here on purpose, with a reason."""


def tracked_at_root() -> set[str]:
    """The root's entries that git tracks (first path component of every tracked file)."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs a git checkout")
    proc = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-z"], capture_output=True, text=True, timeout=60,
                          check=True)
    return {p.split("/", 1)[0] for p in proc.stdout.split("\0") if p}


def test_root_tracks_only_the_allowed_entries():
    extra = sorted(tracked_at_root() - ALLOWED)
    assert not extra, f"unexpected files at the repository root: {extra}; move them or add them to ALLOWED"


def test_no_empty_file_is_tracked_at_the_root():
    empty = sorted(name for name in tracked_at_root() if (ROOT / name).is_file() and (ROOT / name).stat().st_size == 0)
    assert not empty, f"empty files tracked at the repository root: {empty}"
