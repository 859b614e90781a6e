"""Small helpers shared by the command modules."""

from __future__ import annotations

from pathlib import Path

import typer

from adaptenv.errors import ConfigError


def existing_file(path: Path, what: str = "file") -> Path:
    """Return the path or raise a one-sentence error naming it."""
    if not path.is_file():
        raise ConfigError(f"{path}: no such {what}; check the path")
    return path


def check_recorded_in(traj, world, trajectory: Path, house: Path) -> None:
    """Raise a one-sentence error when the trajectory ``traj`` was not recorded in ``world``."""
    from adaptenv.adapt.analysis import trajectory_mismatch

    if (why := trajectory_mismatch(traj, world)) is not None:
        raise ConfigError(f"{trajectory}: recorded in house {traj.house!r}, not in {house} ({why}); "
                          "pass the house the episode ran in")


JSON_OPTION = typer.Option(False, "--json", help="Print the figures as one JSON object instead of a table.")
