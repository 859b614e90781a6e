"""Where numba keeps the compiled kernels (``cache=True``), so that a second process does not compile them again.

numba writes next to the sources (``__pycache__``) when it can, else under the user's cache folder
(``~/.cache/numba``), or first under ``NUMBA_CACHE_DIR`` when that is set. When none of them is writable (a
read-only install with a read-only home), numba refuses to import a cached function at all; :func:`configure`
then points ``NUMBA_CACHE_DIR`` at a folder under the system's temporary directory. It runs on
``import adaptenv``, before any kernel is defined, and never imports numba itself.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent


def writable(folder: Path) -> bool:
    """Whether ``folder`` exists or can be made, and a file can be created in it (what numba checks)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


def user_cache() -> Path:
    """numba's user-wide cache folder on POSIX (``$XDG_CACHE_HOME/numba``, else ``~/.cache/numba``)."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "numba"


def fallback_dir() -> Path:
    """A per-user cache folder under the system's temporary directory."""
    return Path(tempfile.gettempdir()) / f"adaptenv-numba-cache-{os.getuid() if hasattr(os, 'getuid') else 'user'}"


def cache_dir_needed(package: Path = PACKAGE, user: Path | None = None) -> Path | None:
    """The folder to give numba as ``NUMBA_CACHE_DIR``, or None when numba finds a writable place itself."""
    configured = os.environ.get("NUMBA_CACHE_DIR")
    if configured and writable(Path(configured)):
        return None
    if writable(package / "sim" / "__pycache__") or writable(user if user is not None else user_cache()):
        return None
    return fallback_dir()


def configure() -> None:
    """Set ``NUMBA_CACHE_DIR`` to a writable fallback when numba would find no writable cache folder."""
    folder = cache_dir_needed()
    if folder is None or not writable(folder):
        return
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    if "numba" in sys.modules:  # imported before adaptenv: numba read its config already
        sys.modules["numba"].config.CACHE_DIR = str(folder)
