"""Where numba keeps the compiled kernels (``cache=True``): a folder only this user can write, so that a second
process does not compile them again and no other user's files are ever loaded as code.

numba writes next to the sources (``__pycache__``) when it can, else under the user's cache folder
(``~/.cache/numba``), or first under ``NUMBA_CACHE_DIR`` when that is set; it loads the pickled index files it
finds there. :func:`configure` runs on ``import adaptenv``, before any kernel is defined, and never imports
numba itself:

- the folder numba would use must belong to this user and not be writable by group or others (:func:`unsafe`);
- when none of them is writable (a read-only install with a read-only home), or the one numba would use is not
  safe, ``NUMBA_CACHE_DIR`` points at ``$TMPDIR/adaptenv-numba-cache-<uid>``, made with mode 0o700;
- when that folder is not safe either (made by another user, or writable by others), nothing is cached on disk
  across processes: numba gets a fresh private folder (:func:`tempfile.mkdtemp`, removed at exit), and one line
  on stderr says so.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import shutil
import stat
import sys
import tempfile
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent
KERNEL_PACKAGES = ("sim", "agents", "adapt")
"""The sub-packages whose modules define cached kernels: numba caches each in its ``__pycache__``."""


def writable(folder: Path) -> bool:
    """Whether ``folder`` exists or can be made, and a file can be created in it (what numba checks)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


def unsafe(folder: Path) -> str | None:
    """Why code must not be loaded from ``folder`` (another user owns it, or others may write in it), or None."""
    if not hasattr(os, "getuid"):
        return None
    try:
        st = os.stat(folder)
    except OSError:
        return None  # not there yet: made by this user when used
    if not stat.S_ISDIR(st.st_mode):
        return "is not a folder"
    if st.st_uid != os.getuid():
        return f"belongs to another user (uid {st.st_uid})"
    if st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return f"is writable by {'others' if st.st_mode & stat.S_IWOTH else 'its group'} (mode {st.st_mode & 0o777:o})"
    return None


def user_cache() -> Path:
    """numba's user-wide cache folder on POSIX (``$XDG_CACHE_HOME/numba``, else ``~/.cache/numba``)."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "numba"


def fallback_dir() -> Path:
    """A per-user cache folder under the system's temporary directory."""
    return Path(tempfile.gettempdir()) / f"adaptenv-numba-cache-{os.getuid() if hasattr(os, 'getuid') else 'user'}"


def _usable(folder: Path) -> bool:
    return writable(folder) and unsafe(folder) is None


def cache_dir_needed(package: Path = PACKAGE, user: Path | None = None) -> Path | None:
    """The folder to give numba as ``NUMBA_CACHE_DIR``, or None when the place numba finds itself is writable
    and safe. The fallback is returned even when it is not safe: :func:`configure` checks it as it makes it."""
    configured = os.environ.get("NUMBA_CACHE_DIR")
    if configured and _usable(Path(configured)):
        return None
    if not configured:
        in_tree = [package / name / "__pycache__" for name in KERNEL_PACKAGES]
        if all(writable(p) for p in in_tree):
            return None if all(unsafe(p) is None for p in in_tree) else fallback_dir()
        user = user if user is not None else user_cache()
        if writable(user) and unsafe(user) is None:
            return None
    return fallback_dir()


def make_private(folder: Path) -> str | None:
    """Make ``folder`` with mode 0o700 unless it exists; why code must not be loaded from it, or None."""
    with contextlib.suppress(OSError):  # then unsafe() judges what is there, or writable() fails
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    return unsafe(folder)


def _private_temporary() -> str:
    """A fresh folder only this process knows (mode 0o700), removed when the process that made it exits ("" when
    none can be made)."""
    try:
        folder = tempfile.mkdtemp(prefix="adaptenv-numba-")
    except OSError:
        return ""
    owner = os.getpid()
    atexit.register(lambda: os.getpid() == owner and shutil.rmtree(folder, ignore_errors=True))
    return folder


def configure() -> None:
    """Point ``NUMBA_CACHE_DIR`` at a safe folder when the one numba would use is missing or not safe."""
    configured = os.environ.get("NUMBA_CACHE_DIR")
    if configured and (why := unsafe(Path(configured))):
        folder = _refuse(Path(configured), why)
    else:
        needed = cache_dir_needed()
        if needed is None:
            return
        if why := make_private(needed):
            folder = _refuse(needed, why)
        elif writable(needed):
            folder = str(needed)
        else:
            return  # nowhere to write: numba says so when it compiles
    if folder:
        os.environ["NUMBA_CACHE_DIR"] = folder
    else:
        os.environ.pop("NUMBA_CACHE_DIR", None)
    if "numba" in sys.modules:  # imported before adaptenv: numba read its config already
        sys.modules["numba"].config.CACHE_DIR = folder


def _refuse(folder: Path, why: str) -> str:
    """Say in one line on stderr that ``folder`` is not used and kernels are not cached; returns a private folder."""
    print(f"adaptenv: warning: the numba cache folder {folder} {why}, so nothing is loaded from it and compiled "
          "kernels are not cached across runs; remove it, or set NUMBA_CACHE_DIR to a folder only you can write",
          file=sys.stderr)
    return _private_temporary()
