"""The output rule of every command that writes: what the user owns stays theirs.

- A file or folder this command did not write is never replaced without ``--force`` (where a command has no
  ``--force``: never; pass a new path). ``--force`` replaces files of the same name and deletes nothing else.
- An output is never one of the same command's inputs, never holds one, and a file is never written into a
  folder the command reads.
- The command's own earlier output is replaced whole (its files are removed first, so two runs never mix) or,
  where the command resumes (``train --resume``, ``experiment``), continued.

adaptenv knows its own outputs from a manifest, :data:`MANIFEST` (JSON), that it keeps in each folder it
writes into: the command whose output the folder is, and every file a command wrote there with its SHA-256.
A file changed since it was written, or not listed, is the user's. Commands check every output before any
work (:func:`output_file`, :func:`output_folder`), then write inside ``with folder:`` and call
:func:`record_file` for each file they wrote.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from collections.abc import Callable, Iterable, Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import typer

from adaptenv.cli._common import writable_file, writable_folder
from adaptenv.errors import ConfigError

MANIFEST = ".adaptenv-outputs"
"""The manifest's name: no ``.json`` suffix, so that no folder reader takes it for a house or a result."""
FORCE = "--force"
FORCE_OPTION = typer.Option(False, FORCE, help="Replace an output adaptenv did not write (a file of yours, or one "
                            "changed since); only files of the same name are replaced, nothing else is deleted.")


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
    tmp = folder / f"{MANIFEST}.tmp-{os.getpid()}"
    tmp.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    os.replace(tmp, folder / MANIFEST)


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
    writable_file(path, flag)
    check_not_input(path, flag, inputs, folder=False)
    exists = path.exists() or path.is_symlink()
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
            if name != MANIFEST and not name.startswith(f"{MANIFEST}.tmp-"):
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
        for rel in self.remove:
            p = self.path / rel
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p)
            else:
                p.unlink(missing_ok=True)
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
                  inputs: Iterable[Path | str | None] = (), owns: Iterable[str] | None = None,
                  legacy: Callable[[Path], bool] | None = None, keep: bool = False,
                  force_flag: str | None = FORCE) -> OutputFolder:
    """Check before any work that ``command`` may write the folder ``path`` (given as ``flag``).

    A new or empty folder is fine. A folder the manifest gives to ``command`` (or one ``legacy`` recognises,
    written before manifests) is the command's own: with ``keep`` it is continued, otherwise its files are
    removed on ``with`` (the names in ``owns``, the top-level names the command writes, too). A file there that
    the command did not write is refused (only inside ``owns`` when given). Any other folder is refused;
    ``force`` writes into it anyway, replacing files of the same name (and the ``owns`` entries) only.
    """
    path = Path(path)
    writable_folder(path, flag)
    check_not_input(path, flag, inputs, folder=True)
    owned = set(owns) if owns is not None else None
    present = _files(path) if path.is_dir() else {}
    if not present:
        return OutputFolder(path, command, own=False, remove=[], keep=keep)
    doc = read_manifest(path)
    own = doc["folder"] == command or (legacy is not None and doc["folder"] is None and legacy(path))
    force_fix = f", or {force_flag} to write into it anyway (files of the same name are replaced)" if force_flag else ""
    if not own and not force:
        raise ConfigError(f"{flag} {path}: the folder is not empty and was not written by adaptenv {command}, so "
                          f"nothing in it is replaced; pass a new or empty folder{force_fix}")
    if keep:
        return OutputFolder(path, command, own=own, remove=[], keep=True)
    mine = [rel for rel in present if _is_own(path / rel, doc["files"].get(rel), command)]
    if doc["folder"] is None and own:  # written before manifests: the names the command writes are its own
        mine = [rel for rel in present if owned is not None and rel.split("/")[0] in owned]
    theirs = [rel for rel in present if rel not in mine
              and (owned is None or rel.split("/")[0] in owned)]
    if own and theirs and not force:
        raise ConfigError(f"{flag} {path}: {theirs[0]} in it was not written by adaptenv {command} (or was changed "
                          f"since), so the earlier output there is not replaced; move it away, pass a new or empty "
                          f"folder{force_fix}")
    remove = sorted(mine) + (sorted(theirs) if force and owned is not None else [])
    if owned is not None:  # whole sub-folders the command writes go too (their emptied folders included)
        remove = sorted({r.split("/")[0] if r.split("/")[0] in owned else r for r in remove})
    return OutputFolder(path, command, own=own, remove=remove, keep=False)


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
