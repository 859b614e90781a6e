"""Click's usage errors (a bad number, an unknown option, a missing argument) as one line naming the flag and the fix.

Typer prints a usage error as the command's usage, a hint and the message: three lines or more. The ``adaptenv``
group (:class:`adaptenv.cli._Root`) passes every usage error its commands raise through :func:`one_line`, which
turns it into a :class:`UsageLine`: one ``error:`` line, exit code 2. ``--help`` and a group called without a
command (which prints its help) are left as they are.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import typer

_exc = importlib.import_module(typer.BadParameter.__module__)
"""Click's exception module as this typer uses it (``click.exceptions``, or typer's own copy of click)."""
UsageError = _exc.UsageError
_HELP_SCREEN = getattr(_exc, "NoArgsIsHelpError", ())
"""A group called without a command: click shows its help (older clicks print it without raising)."""

_NUMBER_ERRORS = ("int_parsing", "int_from_float", "float_parsing", "finite_number")
"""Pydantic's error types (typer validates with pydantic) of text that is not the number an option takes."""
_BOUND_ERRORS = ("greater_than_equal", "greater_than", "less_than_equal", "less_than")
"""Pydantic's error types of a number outside an option's ``min`` and ``max``."""


def on_one_line(text: str) -> str:
    """``text`` with its line breaks and other control characters escaped (a path a user typed may hold them)."""
    return "".join(c if c.isprintable() or c == " " else c.encode("unicode_escape").decode("ascii") for c in text)


class UsageLine(UsageError):
    """A usage error already worded as one line; shown as ``error: LINE``."""

    def show(self, file=None) -> None:
        """Print the one line to stderr."""
        typer.echo(f"{typer.style('error:', fg='red', bold=True)} {on_one_line(self.message)}", file=file,
                   err=file is None)


def flag_of(param) -> str:
    """How the user names ``param``: an option's long name (``--seed``), an argument's metavar (``HOUSE``)."""
    opts = [o for o in (getattr(param, "opts", None) or []) if o.startswith("-")]
    if opts:
        return max(opts, key=len)
    name = param.metavar or (param.name or "value").upper()
    return name.strip("{}[].")


def _shown(value: Any) -> str:
    """A typed value as the line shows it: as given, or quoted when it holds spaces or control characters."""
    text = str(value)
    return text if text and text.isprintable() and " " not in text else repr(text)


def _range(param, whole: bool) -> str:
    """``"a whole number from 1 to 50"`` for an option's ``min`` and ``max``."""
    kind = "a whole number" if whole else "a number"
    lo, hi = getattr(param, "min", None), getattr(param, "max", None)
    if lo is not None and hi is not None:
        return f"{kind} from {lo:g} to {hi:g}"
    if lo is not None:
        return f"{kind} of at least {lo:g}"
    if hi is not None:
        return f"{kind} of at most {hi:g}"
    return kind


def _is_whole(param) -> bool:
    """Whether ``param`` takes whole numbers (its type, or the element type of a list)."""
    annotation = getattr(getattr(param, "type_descriptor", None), "annotation", None)
    return annotation is int or int in getattr(annotation, "__args__", ())


def _value_line(exc, flag: str) -> str | None:
    """The line of a value typer's validation refused (a number out of range, text where a number goes), or None."""
    errors = getattr(exc.__cause__, "errors", None)
    if not callable(errors) or not errors():
        return None
    first = errors()[0]
    kind, value = first.get("type", ""), first.get("input")
    if kind in _BOUND_ERRORS or kind in _NUMBER_ERRORS:
        whole = _is_whole(exc.param) or kind.startswith("int")
        wanted = _range(exc.param, whole)
        bounded = getattr(exc.param, "min", None) is not None or getattr(exc.param, "max", None) is not None
        fix = "pass a number in that range" if bounded else f"pass {wanted}"
        if isinstance(value, float) and not math.isfinite(value):
            fix = fix.replace("pass a number", "pass a finite number")
        return f"{flag} {_shown(value)}: must be {wanted}; {fix}"
    why = _sentence(str(first.get("msg", exc.message)).removeprefix("Value error, "))
    if why.startswith(f"{value!r} is not one of "):
        return f"{flag} {_shown(value)}: must be one of {why.split(' is not one of ', 1)[1]}; pass one of them"
    return f"{flag} {_shown(value)}: {why}; pass another {flag}"


def _sentence(text: str) -> str:
    """``text`` as the middle of a line: on one line, lower-case first letter, no final full stop."""
    text = " ".join(str(text).split()).rstrip(".")
    return text[:1].lower() + text[1:]


def usage_line(exc, where: str = "adaptenv") -> str:
    """One line for a usage error: what is wrong, naming the flag, and the fix (``where``: the command typed, when
    the error does not say)."""
    where = exc.ctx.command_path if getattr(exc, "ctx", None) is not None else where
    see = f"see {where} --help"
    param = getattr(exc, "param", None)
    if isinstance(exc, _exc.MissingParameter) and param is not None:
        flag = flag_of(param)
        if getattr(param, "param_type_name", "") == "argument":
            return f"{where} needs {flag}; give it after the command ({see})"
        return f"{flag} is required; pass {flag} {(param.metavar or 'VALUE').strip('<>')} ({see})"
    if isinstance(exc, _exc.BadParameter):
        hint = exc.param_hint if isinstance(exc.param_hint, (str, type(None))) else " / ".join(exc.param_hint)
        flag = flag_of(param) if param is not None else (hint or "a value")
        return _value_line(exc, flag) or f"{flag}: {_sentence(exc.message)}; {see}"
    if isinstance(exc, _exc.NoSuchOption):
        close = sorted(exc.possibilities or ())
        guess = f" (did you mean {' or '.join(close)}?)" if close else ""
        return f"{exc.option_name}: {where} has no such option{guess}; {see}"
    if isinstance(exc, _exc.BadOptionUsage) and "requires" in exc.message:
        return f"{exc.option_name} needs a value; pass {exc.option_name} VALUE ({see})"
    return f"{_sentence(exc.message)}; {see}"


def one_line(exc: Exception, where: str = "adaptenv") -> Exception:
    """``exc`` as a :class:`UsageLine` when it is a usage error other than a help screen, else ``exc`` itself."""
    if isinstance(exc, UsageError) and not isinstance(exc, (UsageLine, _HELP_SCREEN)):
        return UsageLine(usage_line(exc, where), exc.ctx)
    return exc


def typed_command(group, words: list[str]) -> str:
    """The command path the user typed: ``group``'s name and the subcommand names that start ``words``."""
    path, command = [group.name or "adaptenv"], group
    for word in words:
        command = getattr(command, "commands", {}).get(word)
        if command is None:
            break
        path.append(word)
    return " ".join(path)


@contextmanager
def usage_in_one_line(where: str = "adaptenv") -> Iterator[None]:
    """Re-raise a usage error raised inside the block as one line (:func:`one_line`); ``where`` names the command
    typed, for errors that do not say."""
    try:
        yield
    except UsageError as exc:
        line = one_line(exc, where)
        if line is exc:
            raise
        raise line from exc
