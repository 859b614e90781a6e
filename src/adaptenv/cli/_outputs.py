"""The output rule of every command that writes: what the user owns stays theirs.

- A file or folder this command did not write is never replaced without ``--force`` (where a command has no
  ``--force``: never; pass a new path). ``--force`` replaces regular files of the same name that the command writes
  and deletes nothing else; a symbolic link where an output goes is refused, with or without ``--force``.
- An output is never one of the same command's inputs, never holds one, and a file is never written into a
  folder the command reads.
- The command's own earlier output is replaced whole (its files are removed first, so two runs never mix) or,
  where the command resumes (``train --resume``, ``experiment``), continued.
- One run writes an output folder at a time: a second run is refused, naming the first's process id
  (:class:`adaptenv.files.FolderLock`, held until the command ends).

adaptenv knows its own outputs from a manifest, :data:`MANIFEST` (JSON), that it keeps in each folder it
writes into: the command whose output the folder is, and every file a command wrote there with its SHA-256.
The manifest is the only proof: a file changed since it was written, or not listed, is the user's, and a folder
without a manifest is the user's. Commands check every output before any work (:func:`output_file`,
:func:`output_folder`), then write inside ``with folder:`` and call :func:`record_file` for each file they wrote.
Files are written to a temporary name in their folder and renamed into place (:mod:`adaptenv.files`).
"""

from __future__ import annotations

import atexit
import hashlib
import json
import os
from collections.abc import Callable, Iterable, Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import typer

from adaptenv.cli._common import writable_file, writable_folder
from adaptenv.errors import ConfigError
from adaptenv.files import LOCK, MANIFEST, FolderLock, atomic_write_text

FORCE = "--force"
FORCE_OPTION = typer.Option(False, FORCE, help="Replace an output adaptenv did not write (a file of yours, or one "
                            "changed since); only regular files of the same name are replaced, nothing else is "
                            "deleted, and a symbolic link is never written through (it is refused).")


def sha256(path: Path) -> str:
    """The SHA-256 of a file's bytes, in hex."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def read_manifest(folder: Path) -> dict:
    """The manifest of ``folder`` ({"folder": command or None, "files": {relative path: {command, sha256}}});
    an empty one when it is missing or unreadable (then nothing there counts as adaptenv's)."""
    try:
        doc = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {"folder": None, "files": {}}
    files = doc.get("files") if isinstance(doc, dict) else None
    files = {k: v for k, v in files.items() if isinstance(v, dict)} if isinstance(files, dict) else {}
    folder_of = doc.get("folder") if isinstance(doc, dict) and isinstance(doc.get("folder"), str) else None
    return {"folder": folder_of, "files": files}


def _write_manifest(folder: Path, doc: dict) -> None:
    atomic_write_text(folder / MANIFEST, json.dumps(doc, indent=1, sort_keys=True) + "\n")


def _is_own(path: Path, entry: dict | None, command: str) -> bool:
    """Whether ``path`` is a regular file that ``command`` wrote, unchanged since (its manifest ``entry``)."""
    return (entry is not None and entry.get("command") == command and path.is_file() and not path.is_symlink()
            and entry.get("sha256") == sha256(path))


def _resolved(path: Path) -> Path:
    return Path(os.path.abspath(path)).resolve()


def check_not_input(out: Path, flag: str, inputs: Iterable[Path | str | None], *, folder: bool) -> None:
    """Refuse an output that is one of ``inputs``, holds one (a folder output) or lies in an input folder (a file)."""
    target = _resolved(out)
    for given in inputs:
        if given is None:
            continue
        inp = _resolved(Path(given))
        if inp == target:
            raise ConfigError(f"{flag} {out}: is also this command's input {given}; an output never replaces an "
                              f"input: pass another {flag}")
        if not inp.exists():
            continue
        if folder and target in inp.parents:
            raise ConfigError(f"{flag} {out}: holds this command's input {given}; pass an output folder that "
                              f"does not contain it")
        if not folder and inp.is_dir() and target.parent == inp:
            raise ConfigError(f"{flag} {out}: would be written into {given}, which this command reads; pass a "
                              f"{flag} outside it")


def output_file(path: Path, flag: str, command: str, *, force: bool = False,
                inputs: Iterable[Path | str | None] = (), name: str | None = None,
                force_flag: str | None = FORCE) -> Path:
    """Check before any work that ``command`` may write the file ``path`` (given as ``flag``); returns it.

    An existing file is replaced only when ``command`` wrote it and it has not changed since, or with
    ``force``; ``name`` replaces "FLAG PATH" at the start of the error (e.g. for a file written beside it).
    """
    path = Path(path)
    if path.is_symlink():
        raise ConfigError(f"{name or f'{flag} {path}'}: is a symbolic link; adaptenv never writes through a link, "
                          f"even with {FORCE}: remove the link, or pass another {flag}")
    writable_file(path, flag)
    check_not_input(path, flag, inputs, folder=False)
    exists = path.exists()
    if exists and not force and not _is_own(path, read_manifest(path.parent)["files"].get(path.name), command):
        fix = f"pass another {flag}" + (f", or {force_flag} to replace it" if force_flag else "")
        raise ConfigError(f"{name or f'{flag} {path}'}: the file exists and was not written by adaptenv "
                          f"{command} (or was changed since), so it is not replaced; {fix}")
    return path


def record_file(path: Path, command: str) -> None:
    """Note in the manifest of its folder that ``command`` wrote the file ``path`` (as it is now)."""
    path = Path(path)
    doc = read_manifest(path.parent)
    doc["files"][path.name] = {"command": command, "sha256": sha256(path)}
    _write_manifest(path.parent, doc)


def _files(folder: Path) -> dict[str, tuple[int, int]]:
    """Every file under ``folder`` but manifests (relative path -> (size, mtime)); links count as files."""
    found = {}
    for root, dirs, names in os.walk(folder):
        for name in names + [d for d in dirs if os.path.islink(os.path.join(root, d))]:
            p = Path(root, name)
            rel = p.relative_to(folder).as_posix()
            if name not in (MANIFEST, LOCK) and not name.startswith(f".{MANIFEST}."):
                st = p.lstat()
                found[rel] = (st.st_size, st.st_mtime_ns)
    return found


class OutputFolder:
    """A folder output, checked by :func:`output_folder`: ``with`` it, the earlier output is removed (unless
    continued) and, on the way out, the manifest lists what the command wrote."""

    def __init__(self, path: Path, command: str, own: bool, remove: list[str], keep: bool) -> None:
        self.path, self.command, self.own, self.remove, self.keep = path, command, own, remove, keep
        self._before: dict[str, tuple[int, int]] = {}

    def __enter__(self) -> OutputFolder:
        for rel in self.remove:  # only regular files the command wrote, unchanged since (never a folder or a link)
            p = self.path / rel
            if p.is_file() and not p.is_symlink():
                p.unlink()
        _prune_empty(self.path, {str(Path(r).parent) for r in self.remove})
        self._before = _files(self.path) if self.path.is_dir() else {}
        return self

    def __exit__(self, kind, exc, tb) -> None:
        self.record()

    def record(self) -> None:
        """Write the manifest when the command wrote anything: its files and the files it kept as its own."""
        if not self.path.is_dir():
            return
        now = _files(self.path)
        written = [rel for rel, stat in now.items() if self._before.get(rel) != stat]
        if not written:
            return
        old = read_manifest(self.path)["files"]
        if self.keep:  # a continued run (resumable, often large): the folder is marked, its files not hashed
            _write_manifest(self.path, {"folder": self.command, "files": old})
            return
        files = {rel: e for rel, e in old.items() if rel in now and rel not in written
                 and _is_own(self.path / rel, e, e.get("command", ""))}
        for rel in written:
            if not (self.path / rel).is_symlink():
                files[rel] = {"command": self.command, "sha256": sha256(self.path / rel)}
        _write_manifest(self.path, {"folder": self.command, "files": files})


def _prune_empty(top: Path, folders: set[str]) -> None:
    """Remove the now-empty sub-folders of ``top`` that held removed files (deepest first; ``top`` stays)."""
    for rel in sorted(folders, key=lambda r: -len(Path(r).parts)):
        p = top / rel
        while p != top and p.is_dir() and all(q.name == MANIFEST for q in p.iterdir()):
            (p / MANIFEST).unlink(missing_ok=True)
            p.rmdir()
            p = p.parent


def output_folder(path: Path, flag: str, command: str, *, force: bool = False,
                  inputs: Iterable[Path | str | None] = (), owns: Iterable[str] | None = None, keep: bool = False,
                  force_flag: str | None = FORCE, then: Callable[[], None] | None = None) -> OutputFolder:
    """Check before any work that ``command`` may write the folder ``path`` (given as ``flag``), and lock it.

    A new or empty folder is fine. A folder the manifest gives to ``command`` is the command's own: with ``keep``
    it is continued, otherwise the files the manifest lists as the command's (unchanged since) are removed on
    ``with``. A file there that the command did not write is refused (only inside ``owns``, the top-level names
    the command writes, when given). Any other folder is refused; ``force`` writes into it anyway, replacing
    regular files of the same name only, and is refused where a symbolic link stands (inside ``owns`` when given).
    ``then`` checks more (e.g. a resumed run's files) once the folder may be written, before it is locked
    (:func:`lock_folder`, until the command ends): a refusal touches nothing.
    """
    path = Path(path)
    writable_folder(path, flag)
    check_not_input(path, flag, inputs, folder=True)
    refuse_if_locked(path, flag)
    folder = _checked_folder(path, flag, command, force, owns, keep, force_flag)
    if then is not None:
        then()
    lock_folder(path, flag)
    return folder


def _checked_folder(path: Path, flag: str, command: str, force: bool, owns: Iterable[str] | None, keep: bool,
                    force_flag: str | None) -> OutputFolder:
    owned = set(owns) if owns is not None else None
    present = _files(path) if path.is_dir() else {}
    if not present:
        return OutputFolder(path, command, own=False, remove=[], keep=keep)
    doc = read_manifest(path)
    own = doc["folder"] == command
    force_fix = f", or {force_flag} to write into it anyway (files of the same name are replaced)" if force_flag else ""
    if not own and not force:
        raise ConfigError(f"{flag} {path}: the folder is not empty and was not written by adaptenv {command}, so "
                          f"nothing in it is replaced; pass a new or empty folder{force_fix}")
    scope = [rel for rel in present if owned is None or rel.split("/")[0] in owned]
    links = [rel for rel in scope if os.path.islink(path / rel)]
    if force and links:
        raise ConfigError(f"{flag} {path}: {links[0]} in it is a symbolic link; adaptenv never writes through a "
                          f"link, even with {FORCE}: remove the link, or pass a new or empty folder")
    if keep:
        return OutputFolder(path, command, own=own, remove=[], keep=True)
    mine = [rel for rel in present if _is_own(path / rel, doc["files"].get(rel), command)]
    theirs = [rel for rel in scope if rel not in mine]
    if own and theirs and not force:
        raise ConfigError(f"{flag} {path}: {theirs[0]} in it was not written by adaptenv {command} (or was changed "
                          f"since), so the earlier output there is not replaced; move it away, pass a new or empty "
                          f"folder{force_fix}")
    return OutputFolder(path, command, own=own, remove=sorted(mine), keep=False)


_HELD: dict[Path, FolderLock] = {}
"""The output folders this process has locked, by resolved path (released when the command ends)."""


def refuse_if_locked(path: Path, flag: str) -> None:
    """Refuse, without writing anything, an output folder another run is writing now (naming its process id)."""
    key = _resolved(Path(path))
    if key not in _HELD and (pid := FolderLock(path).holder()) is not None:
        raise ConfigError(f"{flag} {path}: another adaptenv run (process id {pid or 'unknown'}) is writing this "
                          "folder; wait for it to end, or pass another output folder")


def lock_folder(path: Path, flag: str) -> None:
    """Lock the output folder ``path`` (created if missing) for this process until :func:`release_folders`;
    refused in one line naming the process id of a run that holds it."""
    key = _resolved(Path(path))
    if key not in _HELD:
        _HELD[key] = FolderLock(path).acquire(f"{flag} {path}")


def release_folders() -> None:
    """Release every output folder this process locked (the command has ended)."""
    while _HELD:
        _HELD.popitem()[1].release()


atexit.register(release_folders)


def continued_folder(path: Path, flag: str, command: str) -> OutputFolder:
    """A run's own folder, continued as it is (``train --resume``), locked like :func:`output_folder`'s."""
    if Path(path).is_dir():  # a missing folder is refused by the command, in its own words
        refuse_if_locked(path, flag)
        lock_folder(path, flag)
    return OutputFolder(Path(path), command, own=True, remove=[], keep=True)


def _stat(path: Path) -> tuple[int, int] | None:
    try:
        st = path.lstat()
    except OSError:
        return None
    return st.st_size, st.st_mtime_ns


@contextmanager
def recording(files: Iterable[Path], folder: OutputFolder | None, command: str) -> Iterator[None]:
    """Write inside ``folder`` (when given) and record each of ``files`` that changed on the way out, however
    the command ends (files written before Ctrl-C are the command's own too)."""
    before = {Path(p): _stat(Path(p)) for p in files}
    try:
        with ExitStack() as stack:
            if folder is not None:
                stack.enter_context(folder)
            yield
    finally:
        for path, stat in before.items():
            if path.is_file() and _stat(path) != stat:
                record_file(path, command)


def command_line() -> str:
    """The command being run, as ``adaptenv ...`` (kept in run folders, datasets and checkpoint cards)."""
    import shlex
    import sys

    return shlex.join(["adaptenv", *sys.argv[1:]])
