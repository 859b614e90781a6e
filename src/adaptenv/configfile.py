"""Typed reading of JSON config files: one strict pydantic check per config, one ConfigError line per problem.

:func:`parse_config` validates JSON data against a dataclass or pydantic model in pydantic's strict JSON mode
(``"3"`` is not an integer, ``true`` not a number, a string not a list) with unknown keys refused, and turns the
first problem into one sentence: the file, the field path (``seeds[0]``, ``loop.iterations``), what is wrong
and the fix. Dataclasses opt in with ``__pydantic_config__ = STRICT``.
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import re
from functools import cache
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel, ConfigDict, TypeAdapter, ValidationError

from adaptenv.errors import ConfigError
from adaptenv.files import FileRefused, JSONTooDeep, loads_json, read_bytes
from adaptenv.limits import CONFIG_BYTES

T = TypeVar("T")

#: pydantic config of the dataclasses read from files: exact JSON types, unknown keys refused.
STRICT = ConfigDict(strict=True, extra="forbid")

_UNKNOWN = ("extra_forbidden", "unexpected_keyword_argument")
#: What a value should be, by pydantic error type (others use pydantic's own words).
_SHOULD = {
    "int_type": "a whole number", "int_parsing": "a whole number", "int_from_float": "a whole number",
    "float_type": "a number", "float_parsing": "a number", "string_type": "a string",
    "bool_type": "true or false", "bool_parsing": "true or false",
    "list_type": "a JSON array", "tuple_type": "a JSON array",
    "dict_type": "a JSON object", "dataclass_type": "a JSON object", "model_type": "a JSON object",
    "model_attributes_type": "a JSON object",
}


def read_json(path: str | Path, what: str, source: str | None = None, limit: int = CONFIG_BYTES) -> Any:
    """The JSON document in ``path``; ConfigError (``source``, default the path, and ``what`` the file should be)
    when it is missing, unreadable, not a regular file, larger than ``limit`` bytes, not JSON or nested deeper
    than :data:`~adaptenv.limits.JSON_DEPTH_MAX`."""
    p = Path(path)
    source = source or str(p)
    try:
        return loads_json(read_bytes(p, limit, what.split(" (")[0]).decode("utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{source}: no such file; pass the path of a JSON {what}") from None
    except FileRefused as exc:
        raise ConfigError(f"{source}: {exc.reason}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{source}: cannot read the {what} ({exc}); check the path") from None
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{source}: the {what} is not valid JSON (line {exc.lineno}, column {exc.colno}: "
                          f"{exc.msg}); fix the syntax") from None
    except JSONTooDeep as exc:
        raise ConfigError(f"{source}: the {what} is refused: {exc}; write it flatter") from None
    except ValueError as exc:  # an integer of more than 4300 digits
        raise ConfigError(f"{source}: the {what} is not valid JSON ({str(exc).split(';')[0]}); fix the number") \
            from None


def parse_config(kind: type[T], data: Any, source: str, *, prefix: str = "", fix: str = "fix that value") -> T:
    """``data`` as a ``kind`` (a dataclass with ``__pydantic_config__ = STRICT`` or a pydantic model), checked in
    strict JSON mode; raises one ConfigError ``source: field problem; fix`` (fields under ``prefix``)."""
    try:
        text = json.dumps(data, default=_plain)
        return _adapter(kind).validate_json(text, strict=True)
    except ValidationError as exc:
        raise ConfigError(describe(exc.errors(include_url=False)[0], kind, source, prefix, fix)) from None


def describe(err: dict[str, Any], kind: type, source: str, prefix: str = "", fix: str = "fix that value") -> str:
    """One sentence for a pydantic error: ``source: field what-is-wrong; fix``."""
    loc = tuple(err["loc"])
    field = field_path((*prefix.split("."), *loc) if prefix else loc)
    if err["type"] in _UNKNOWN:
        known = field_names(kind) if len(loc) == 1 else []
        close = difflib.get_close_matches(str(loc[-1]), known, n=1)
        hint = f"did you mean {close[0]!r}?" if close else (f"use {', '.join(known)}" if known else "remove it")
        return f"{source}: {field} is not a known field; {hint}"
    if err["type"] == "missing":
        return f"{source}: {field} is missing; add it"
    what = field or "the value"
    ctx = err.get("ctx") or {}
    if err["type"] in _SHOULD:
        problem = f"should be {_SHOULD[err['type']]}"
    elif err["type"] in ("too_short", "too_long"):
        most = "at least" if err["type"] == "too_short" else "at most"
        count = ctx.get("min_length" if err["type"] == "too_short" else "max_length")
        problem = f"should have {most} {count} items"
    else:
        msg = err["msg"]
        problem = msg.replace("Input should", "should", 1) if msg.startswith("Input should") else f"is invalid ({msg})"
    return f"{source}: {what} {problem}, got {_shown(err.get('input'))}; {fix}"


def field_path(loc: tuple[Any, ...]) -> str:
    """``('loop', 'iterations')`` -> ``loop.iterations``; ``('seeds', 0)`` -> ``seeds[0]``."""
    out = ""
    for part in loc:
        part = part if isinstance(part, int) else printable(str(part))
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else part)
    return out


def printable(text: str) -> str:
    """``text`` with line breaks and other control characters escaped (a key a user typed, kept on one line)."""
    return text if text.isprintable() else text.encode("unicode_escape").decode("ascii")


def field_names(kind: type) -> list[str]:
    """The field names a dataclass or pydantic model accepts."""
    if isinstance(kind, type) and issubclass(kind, BaseModel):
        return list(kind.model_fields)
    return [f.name for f in dataclasses.fields(kind)] if dataclasses.is_dataclass(kind) else []


@cache
def _adapter(kind: type) -> TypeAdapter:
    return TypeAdapter(kind)


def _plain(value: Any) -> Any:
    """JSON form of values json.dumps does not know (numpy scalars, paths)."""
    return value.item() if hasattr(value, "item") else str(value)


def _shown(value: Any) -> str:
    """A value as the user wrote it (JSON), cut short."""
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):
        text = repr(value)
    text = re.sub(r"\d{16,}", lambda m: f"{float(m.group()):.3g}", text)  # 10**30 as 1e+30, not 31 digits
    return text if len(text) <= 60 else text[:57] + "..."


__all__ = ["STRICT", "describe", "field_names", "field_path", "parse_config", "printable", "read_json"]
