"""File helpers every layer may use: atomic writes, appends that never follow a link, one writer per folder, and
bounded reads of the files a user hands over.

Every file adaptenv writes goes to a temporary name in its own folder and is then renamed over its name
(:func:`atomic_path`): a crash leaves the old file or the new one, never a mix, and a symbolic link of that name is
replaced by the file, never written through. Logs that grow line by line (``metrics.csv``) are opened with
:func:`open_append`, which refuses a link. :class:`FolderLock` keeps a second run from writing an output folder
that a first run is writing.

Every reader of a user's file goes through :func:`read_bytes` (and :func:`gunzip` for compressed ones): only a
regular file is read (a FIFO, a device such as ``/dev/zero`` or a folder is refused before a byte is read, so
nothing blocks or fills memory), and a file larger than its kind's limit (:mod:`adaptenv.limits`) is refused
from its size alone. :func:`loads_json` parses JSON no deeper than :data:`~adaptenv.limits.JSON_DEPTH_MAX`.
"""

from __future__ import annotations

import gzip
import io
import json
import os
import stat
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any, BinaryIO

try:  # POSIX; elsewhere no lock is taken
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]

from adaptenv.errors import ConfigError
from adaptenv.limits import JSON_DEPTH_MAX, MiB

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


class FileRefused(ConfigError):
    """A file adaptenv will not read: not a regular file, or larger than the limit of its kind."""

    def __init__(self, path: str | Path, reason: str):
        self.path, self.reason = str(path), reason
        super().__init__(f"{path}: {reason}")


class JSONTooDeep(ValueError):
    """A JSON document nests arrays and objects deeper than :data:`~adaptenv.limits.JSON_DEPTH_MAX`."""

    def __init__(self) -> None:
        super().__init__(f"it nests arrays and objects more than {JSON_DEPTH_MAX} deep, the most adaptenv reads")


_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def not_regular(mode: int) -> str | None:
    """What a file of ``st_mode`` ``mode`` is when it is not a regular file (``a FIFO (named pipe)``), else None."""
    if stat.S_ISREG(mode):
        return None
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def _size(n: int) -> str:
    return f"{n / MiB:,.1f} MiB" if n >= MiB else f"{n:,} bytes"


def too_large(size: int | None, limit: int, what: str) -> str:
    """The reason a ``what`` (a noun: ``house``) of ``size`` bytes (None: unknown, more than ``limit``) is
    refused."""
    got = f"{_size(size)}, " if size is not None else ""
    return f"{got}over the {_size(limit)} limit of the {what} (README, \"Limits\"); pass a smaller file or split it"


def open_regular(path: str | Path, what: str) -> BinaryIO:
    """``path`` opened for reading in binary, when it is a regular file; FileRefused (naming ``what``) for a FIFO, a
    device, a folder or a socket, OSError when it cannot be opened. Opened without blocking, so a FIFO is refused,
    never waited on."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        if (kind := not_regular(os.fstat(fd).st_mode)) is not None:
            raise FileRefused(path, f"is {kind}, not a regular file; pass the {what} as a file")
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_bytes(path: str | Path, limit: int, what: str) -> bytes:
    """The content of the regular file ``path``, at most ``limit`` bytes; FileRefused (naming ``what``) for a file
    of another kind (:func:`open_regular`) or a larger one, refused from its size before reading."""
    with open_regular(path, what) as f:
        size = os.fstat(f.fileno()).st_size
        if size > limit:
            raise FileRefused(path, too_large(size, limit, what))
        data = f.read(limit + 1)
    if len(data) > limit:  # it grew while being read
        raise FileRefused(path, too_large(None, limit, what))
    return data


def gunzip(raw: bytes, limit: int, what: str, path: str | Path) -> bytes:
    """``raw`` decompressed (gzip), at most ``limit`` bytes; FileRefused when it decompresses to more.
    Damaged data raises what :mod:`gzip` raises (OSError, EOFError, zlib.error)."""
    with gzip.GzipFile(fileobj=io.BytesIO(raw)) as g:
        data = g.read(limit + 1)
    if len(data) > limit:
        raise FileRefused(path, f"decompresses to {too_large(None, limit, what)}")
    return data


def json_depth(doc: Any, most: int = JSON_DEPTH_MAX) -> int:
    """How deep ``doc`` nests lists and dicts (a scalar is 0), counted up to ``most + 1``."""
    level = [doc] if isinstance(doc, (dict, list)) else []
    depth = 0
    while level and depth <= most:
        depth += 1
        level = [c for v in level for c in (v.values() if type(v) is dict else v)
                 if type(c) is dict or type(c) is list]
    return depth


def loads_json(text: str | bytes) -> Any:
    """``json.loads(text)`` of a document no deeper than JSON_DEPTH_MAX; JSONTooDeep (a ValueError) otherwise,
    json.JSONDecodeError for bad syntax."""
    try:
        doc = json.loads(text)
    except RecursionError:
        raise JSONTooDeep() from None
    if json_depth(doc) > JSON_DEPTH_MAX:
        raise JSONTooDeep()
    return doc


__all__ = ["BOOKKEEPING", "LOCK", "MANIFEST", "FileRefused", "FolderLock", "JSONTooDeep", "atomic_path",
           "atomic_write_bytes", "atomic_write_text", "gunzip", "json_depth", "loads_json", "not_regular",
           "open_append", "open_regular", "read_bytes", "too_large"]
