"""Small helpers shared by the command modules."""

from __future__ import annotations

import os
from pathlib import Path
from typing import NoReturn

import typer

from adaptenv.errors import ConfigError
from adaptenv.files import not_regular


def existing_file(path: Path, what: str = "file") -> Path:
    """Return the path or raise a one-sentence error naming it (a FIFO, a device or a folder is no file)."""
    if not path.is_file():
        try:
            kind = not_regular(path.stat().st_mode)
        except OSError:
            kind = None
        if kind is not None:
            raise ConfigError(f"{path}: is {kind}, not a regular file; pass the {what} as a file")
        raise ConfigError(f"{path}: no such {what}; check the path")
    return path


HOUSE_HELP = "A house JSON file (ProcTHOR format) or one line of a dataset, e.g. FILE.jsonl.gz:2:3 (line index 2)."
"""Help of every argument that names one house (read by :func:`load_house_argument`)."""


def load_house_argument(spec: Path | str, what: str = "house"):
    """(name, House) of a HOUSE argument: a house JSON file or a dataset slice of one house."""
    from adaptenv.scene.dataset import load_one_house

    return load_one_house(spec, what=what)


def _nearest_existing(path: Path) -> Path:
    """``path`` itself or its closest ancestor that exists (a path under a regular file stops at the file)."""
    return next((p for p in (path, *path.parents) if p.exists()), Path("."))


def _check_writable_base(folder: Path, flag: str, given: Path) -> None:
    """Raise a ConfigError naming ``flag`` unless ``folder`` can be created, or written in, by this user."""
    base = _nearest_existing(folder)
    if not base.is_dir():
        raise ConfigError(f"{flag} {given}: {base} is a file, not a folder; pass another {flag}")
    if not os.access(base, os.W_OK | os.X_OK):
        raise ConfigError(f"{flag} {given}: the folder {base} is not writable; pass a {flag} you can write to")


def writable_folder(path: Path, flag: str) -> Path:
    """Return ``path`` if it is, or can be created as, a folder this user can write in (checked before any work)."""
    _check_writable_base(Path(path), flag, path)
    return path


def writable_file(path: Path, flag: str) -> Path:
    """Return ``path`` if this user can create or overwrite the file there (checked before any work)."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"{flag} {path}: is a folder; pass a file name")
    if path.exists() and not os.access(path, os.W_OK):
        raise ConfigError(f"{flag} {path}: the file is not writable; pass a {flag} you can write to")
    _check_writable_base(path.parent, flag, path)
    return path


def interrupted(how: str = "") -> NoReturn:
    """After Ctrl-C: one line saying how to continue (when there is a way), then exit 130."""
    if how:
        from rich.console import Console

        Console(stderr=True, emoji=False).print(f"interrupted; {how}", highlight=False, soft_wrap=True)
    raise typer.Exit(130)


def check_recorded_in(traj, world, trajectory: Path, house: Path) -> None:
    """Raise a one-sentence error when the trajectory ``traj`` was not recorded in ``world`` (other targets, or a
    pose off its floor)."""
    from adaptenv.adapt.analysis import pose_outside, trajectory_mismatch

    if (why := trajectory_mismatch(traj, world)) is not None:
        raise ConfigError(f"{trajectory}: recorded in house {traj.house!r}, not in {house} ({why}); "
                          "pass the house the episode ran in")
    if (why := pose_outside(traj, world)) is not None:
        raise ConfigError(f"{trajectory}: {why} of {house}; pass the house the episode ran in, or record the "
                          "episode again")
    believe_poses(traj, world, trajectory)


def believe_poses(traj, world, trajectory: Path) -> None:
    """Replace the stored metrics of ``traj`` by those its poses give in ``world``; a stored figure that differs is
    said in one line on stderr (the trajectory is evidence, its stored verdict is not believed)."""
    from adaptenv.cli._usage import on_one_line
    from adaptenv.sim.metrics import recompute_metrics

    traj.metrics, differs = recompute_metrics(world, traj)
    if differs:
        typer.echo(on_one_line(f"{trajectory}: {'; '.join(differs)}; the recomputed figures are used"), err=True)


JSON_OPTION = typer.Option(False, "--json", help="Print the figures as one JSON object instead of a table.")
