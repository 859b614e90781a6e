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


JSON_OPTION = typer.Option(False, "--json", help="Print the figures as one JSON object instead of a table.")
