"""Typer callbacks that check the numbers a user types before any work (ranges in :mod:`adaptenv.limits`).

A callback raises a one-line ConfigError naming the flag as the user spelled it (``--seed``), so every
command refuses a bad number the same way: ``option = typer.Option(0, "--seed", callback=numbers.seed)``.
"""

from __future__ import annotations

import math

from adaptenv.limits import check_episodes, check_float, check_seed


def _flag(param) -> str:
    """The option's long name (``--seed``), else its first name."""
    return max(param.opts, key=len) if getattr(param, "opts", None) else f"--{param.name}"


def seed(ctx, param, value):
    """Callback: a seed from 0 to 2**32 - 1."""
    return value if value is None else check_seed(value, _flag(param))


def episodes(ctx, param, value):
    """Callback: an episode count from 1 to what fits in memory."""
    return value if value is None else check_episodes(value, _flag(param))


def episodes_or_none(ctx, param, value):
    """Callback: 0 (none), or an episode count from 1 to what fits in memory."""
    return value if value in (None, 0) else check_episodes(value, _flag(param))


def finite(ctx, param, value):
    """Callback: a finite number (not inf: click's ranges refuse nan but take inf), at least the option's ``min``."""
    if value is None:
        return value
    lo = getattr(param, "min", getattr(getattr(param, "type", None), "min", None))
    return check_float(value, _flag(param), lo=-math.inf if lo is None else lo)
