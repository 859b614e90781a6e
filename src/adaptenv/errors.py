"""One exception hierarchy for adaptenv; every message is a sentence a user can act on."""

from __future__ import annotations

from dataclasses import dataclass


class AdaptenvError(Exception):
    """Base class of every error adaptenv raises on purpose (the CLI prints these without a traceback)."""


@dataclass(frozen=True)
class Problem:
    """One problem found in a house: where it is (JSON path) and what is wrong, with the fix."""

    path: str
    message: str
    file: str | None = None

    def __str__(self) -> str:
        where = f"{self.file}: " if self.file else ""
        return f"{where}at {self.path}, {self.message}"


class HouseError(AdaptenvError):
    """A house file or document is malformed; carries every problem found."""

    def __init__(self, problems: list[Problem]):
        self.problems = problems
        first = str(problems[0]) if problems else "the house is invalid"
        more = len(problems) - 1
        suffix = f" ({more} more problem{'s' if more > 1 else ''}; run `adaptenv validate` to list them)" if more > 0 else ""
        super().__init__(first + suffix)


class ConfigError(AdaptenvError):
    """A command-line option or config file value is invalid."""


class RunsFailed(AdaptenvError):
    """Some runs of an experiment failed; the others ran to the end (each failure is one line of the message)."""


class TrainingDiverged(AdaptenvError):
    """Training made the network's weights NaN or infinite; the last finite checkpoint is kept."""


class PolicyError(AdaptenvError):
    """A user's policy (``--policy module:attribute``) broke the policy contract: an action that is none, or not one
    action per episode. The user's own exceptions are not these: they keep their traceback."""
