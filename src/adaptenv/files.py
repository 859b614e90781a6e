"""File helpers every layer may use: atomic writes, appends that never follow a link, and one writer per folder.

Every file adaptenv writes goes to a temporary name in its own folder and is then renamed over its name
(:func:`atomic_path`): a crash leaves the old file or the new one, never a mix, and a symbolic link of that name is
replaced by the file, never written through. Logs that grow line by line (``metrics.csv``) are opened with
:func:`open_append`, which refuses a link. :class:`FolderLock` keeps a second run from writing an output folder
that a first run is writing.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

try:  # POSIX; elsewhere no lock is taken
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]

from adaptenv.errors import ConfigError

LOCK = ".adaptenv-lock"
"""The lock file a run keeps in its output folder while it writes there (holding its process id)."""
MANIFEST = ".adaptenv-outputs"
"""The manifest of an output folder (:mod:`adaptenv.cli._outputs`): no ``.json`` suffix, so that no folder reader
takes it for a house or a result."""
BOOKKEEPING = (LOCK, MANIFEST)
"""adaptenv's own bookkeeping files in an output folder: a folder holding only these counts as empty."""


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path in ``path``'s folder, with its suffix, to write; renamed over ``path`` when the block ends
    (removed if it raises). Parent folders are created."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}")
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; outputs are ordinary readable files
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write a file so that a crash leaves either the old or the new content, never a mix (nor a link followed)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    return Path(path)


def atomic_write_text(path: str | Path, text: str) -> Path:
    """:func:`atomic_write_bytes` of ``text`` in UTF-8."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def open_append(path: str | Path, binary: bool = False) -> IO:
    """Open ``path`` to append to it (created when missing), refusing a symbolic link in its place."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o644)
    except OSError:
        if path.is_symlink():
            raise ConfigError(f"{path}: is a symbolic link; adaptenv never writes through one: remove the link, "
                              "or pass another output") from None
        raise
    return os.fdopen(fd, "ab") if binary else os.fdopen(fd, "a", encoding="utf-8", newline="")


class FolderLock:
    """An exclusive lock on an output folder (``fcntl.flock`` on :data:`LOCK` in it), refused while another process
    holds it; :meth:`release` removes the lock file and the folders :meth:`acquire` created, when left empty."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
        self.path = self.folder / LOCK
        self._file: IO | None = None
        self._created: list[Path] = []
        self._pid = os.getpid()

    def holder(self) -> int | None:
        """The process id of the run holding the lock now, or None (no run, or no locks on this system); reads only."""
        if fcntl is None:
            return None
        try:
            fd = os.open(self.path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
        except OSError:
            return None
        with os.fdopen(fd, encoding="utf-8") as f:
            try:
                fcntl.flock(f, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except OSError:
                text = f.read().strip()
                return int(text) if text.isdigit() else 0
            return None

    def acquire(self, what: str) -> FolderLock:
        """Take the lock (creating the folder); ConfigError naming ``what`` and the holder's process id if held."""
        if fcntl is None:
            return self
        missing = [p for p in (self.folder, *self.folder.parents) if not p.exists()]
        self.folder.mkdir(parents=True, exist_ok=True)
        self._created = missing  # deepest first
        while True:
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o644)
            except OSError as exc:
                self._remove_created()
                raise ConfigError(f"{what}: cannot open its lock file {self.path} ({exc.strerror}); remove it if it "
                                  "is a link or a folder, or pass another output folder") from None
            f = os.fdopen(fd, "r+", encoding="utf-8")
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                f.seek(0)
                text = f.read().strip()
                f.close()
                self._remove_created()
                pid = text if text.isdigit() else "unknown"
                raise ConfigError(f"{what}: another adaptenv run (process id {pid}) is writing this folder; wait "
                                  "for it to end, or pass another output folder") from None
            try:  # the file may have been removed by the run that held it, between open and flock: take it anew
                same = os.stat(self.path).st_ino == os.fstat(f.fileno()).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            f.close()
        self._pid = os.getpid()
        f.seek(0)
        f.truncate()
        f.write(f"{self._pid}\n")
        f.flush()
        self._file = f
        return self

    def release(self) -> None:
        """Remove the lock file and unlock; then remove the folders acquire created, if they are empty. Only the
        process that took the lock releases it (a forked worker that inherited it leaves it alone)."""
        if os.getpid() != self._pid:
            return
        if self._file is not None:
            self.path.unlink(missing_ok=True)
            self._file.close()
            self._file = None
        self._remove_created()

    def _remove_created(self) -> None:
        for p in self._created:
            try:
                p.rmdir()
            except OSError:
                break
        self._created = []


__all__ = ["BOOKKEEPING", "LOCK", "MANIFEST", "FolderLock", "atomic_path", "atomic_write_bytes", "atomic_write_text", "open_append"]
