"""File helpers every layer may use: atomic writes, and bounded reads of the files a user hands over.

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
from pathlib import Path
from typing import Any, BinaryIO

from adaptenv.errors import ConfigError
from adaptenv.limits import JSON_DEPTH_MAX, MiB


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


def atomic_write_text(path: Path, text: str) -> Path:
    """Write a file so that a crash leaves either the old or the new content, never a mix."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; run files are ordinary readable files
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


__all__ = ["FileRefused", "JSONTooDeep", "atomic_write_text", "gunzip", "json_depth", "loads_json", "not_regular",
           "open_regular", "read_bytes", "too_large"]
