"""House datasets: one ProcTHOR house JSON per line, plain (``.jsonl``) or gzip-compressed (``.jsonl.gz``).

ProcTHOR-10K and SPOC ship their houses this way. A dataset spec is the file, optionally followed by a
slice of its line indices with Python's slice semantics (``START:STOP`` or ``START:STOP:STEP``, 0-based,
STOP excluded, bounds non-negative): ``train.jsonl.gz:0:100`` is lines 0-99, ``train.jsonl.gz:100:``
line 100 to the end, ``train.jsonl.gz:::10`` every tenth line. The file is read line by line and reading
stops at the slice's end, so a slice of a large file costs only its own lines. The house on line index
``i`` is named ``house-{i:06d}`` (line ``i + 1`` in an editor). Blank lines are skipped; a slice that
selects no house (e.g. one starting past the end) is an error that gives the file's line count.

A line that is not JSON, or JSON but not an object, is an error naming its line number; a line that is
a JSON object but not a valid house comes back as the :class:`~adaptenv.errors.HouseError` naming its
line, for the caller to report or skip like an invalid house file.
"""

from __future__ import annotations

import gzip
import io
import json
import logging
import re
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from adaptenv.errors import ConfigError, HouseError
from adaptenv.files import FileRefused, loads_json, not_regular, open_regular, too_large
from adaptenv.limits import DATASET_LINE_BYTES
from adaptenv.scene.house import House, load_house, parse_house
from adaptenv.scene.validate import dropped_children_line, validate_read_house

log = logging.getLogger(__name__)

_SPEC = re.compile(r"^(?P<path>.*?\.jsonl(?:\.gz)?)(?::(?P<slice>.*))?$", re.IGNORECASE)


@dataclass(frozen=True)
class DatasetSlice:
    """A house dataset file and the slice of its line indices to read."""

    path: Path
    start: int = 0
    stop: int | None = None
    step: int = 1

    @property
    def spec(self) -> str:
        """The spec as a user writes it: the file, then ``:START:STOP[:STEP]`` when it is sliced."""
        if (self.start, self.stop, self.step) == (0, None, 1):
            return str(self.path)
        stop = "" if self.stop is None else str(self.stop)
        return f"{self.path}:{self.start}:{stop}" + (f":{self.step}" if self.step != 1 else "")


def parse_dataset_spec(spec: str | Path) -> DatasetSlice | None:
    """The dataset a spec names (``FILE.jsonl[.gz][:START:STOP[:STEP]]``), or None when it names none."""
    m = _SPEC.match(str(spec))
    if m is None:
        return None
    path, text = Path(m["path"]), m["slice"]
    if text is None:
        return DatasetSlice(path)
    parts = text.split(":")
    if len(parts) not in (2, 3) or not all(p.strip().isdigit() for p in parts if p.strip()):
        raise ConfigError(f"{spec}: {text!r} is not a slice START:STOP or START:STOP:STEP of non-negative line "
                          f"indices; write e.g. {path}:0:100 (lines 0 to 99)")
    start, stop, step = (int(p) if p.strip() else None for p in parts + [""] * (3 - len(parts)))
    if step == 0:
        raise ConfigError(f"{spec}: the slice step is 0; use a step of 1 or more")
    ds = DatasetSlice(path, start or 0, stop, step or 1)
    if ds.stop is not None and ds.stop <= ds.start:
        raise ConfigError(f"{spec}: the slice selects no line (STOP {ds.stop} is not above START {ds.start}); "
                          "give a STOP above START")
    return ds


def house_name(index: int) -> str:
    """The name of the house on line index ``index`` (also its file stem in ``adaptenv houses export``)."""
    return f"house-{index:06d}"


def line_label(path: Path, index: int) -> str:
    """How errors name the line of index ``index``: 1-based, as editors count, with the 0-based index that slices
    (FILE.jsonl.gz:START:STOP) and house names (house-000002) use, e.g. ``train.jsonl line 3 (index 2)``."""
    return f"{path} line {index + 1} (index {index})"


@contextmanager
def _open_text(path: Path) -> Iterator[IO[str]]:
    """The regular file ``path`` as UTF-8 text, decompressed on the fly when it is gzip (by its magic bytes, not its
    name); opened without blocking, so a FIFO or a device is refused (FileRefused), never waited on or read."""
    with open_regular(path, "dataset") as raw:
        gzipped = raw.read(2) == b"\x1f\x8b"
        raw.seek(0)
        with io.TextIOWrapper(gzip.GzipFile(fileobj=raw) if gzipped else raw, encoding="utf-8") as text:
            yield text


def _lines(f: IO[str], path: Path) -> Iterator[str]:
    """The lines of ``f``, each at most :data:`~adaptenv.limits.DATASET_LINE_BYTES` long (FileRefused otherwise)."""
    index = 0
    while line := f.readline(DATASET_LINE_BYTES + 1):
        if len(line) > DATASET_LINE_BYTES:
            raise FileRefused(line_label(path, index), f"the line is {too_large(None, DATASET_LINE_BYTES, 'dataset line')}")
        index += 1
        yield line


def dataset_lines(ds: DatasetSlice) -> Iterator[tuple[int, str]]:
    """(line index, text) of every non-blank line the slice selects, read lazily; stops at the slice's end."""
    if not ds.path.exists():
        raise ConfigError(f"{ds.spec}: no such dataset file; pass a .jsonl or .jsonl.gz file of houses, one per line")
    total, found = 0, 0
    try:
        with _open_text(ds.path) as f:
            for index, line in enumerate(_lines(f, ds.path)):
                total = index + 1
                if index >= ds.start and (index - ds.start) % ds.step == 0 and line.strip():
                    found += 1
                    yield index, line
                if ds.stop is not None and total >= ds.stop:
                    break
    except FileRefused:
        raise
    except (OSError, EOFError, UnicodeDecodeError, zlib.error) as exc:
        raise ConfigError(f"{line_label(ds.path, total)}: cannot read the dataset there ({exc}); the file must be "
                          "UTF-8 JSON lines, gzip-compressed or not, and complete") from None
    if not found and total == 0:
        raise ConfigError(f"{ds.spec}: the dataset is empty (no lines); pass a dataset with one house JSON a line")
    if not found and total > ds.start:
        raise ConfigError(f"{ds.spec}: the slice selects only blank lines; pick lines that hold houses")
    if not found:
        raise ConfigError(f"{ds.spec}: the slice selects no house ({ds.path} has {total} lines); pick line indices "
                          f"below {total}")


def dataset_documents(ds: DatasetSlice) -> Iterator[tuple[int, dict[str, Any]]]:
    """(line index, parsed JSON object) of the selected lines; ConfigError names a line that is not one."""
    for index, line in dataset_lines(ds):
        try:
            doc = loads_json(line)
        except json.JSONDecodeError as exc:
            raise ConfigError(f"{line_label(ds.path, index)}: not valid JSON ({exc.msg} at column {exc.colno}); "
                              "a house dataset holds one house JSON object per line") from None
        except ValueError as exc:  # nested too deeply, or an integer of more than 4300 digits
            raise ConfigError(f"{line_label(ds.path, index)}: refused ({str(exc).split(';')[0]}); a house dataset "
                              "holds one house JSON object per line") from None
        if not isinstance(doc, dict):
            raise ConfigError(f"{line_label(ds.path, index)}: a JSON {type(doc).__name__}, not a house object; a "
                              "house dataset holds one house JSON object per line")
        yield index, doc


def dataset_houses(ds: DatasetSlice, *, validate: bool = True, catalog: Any = None,
                   skip_unknown: bool | None = None) -> Iterator[tuple[str, House | HouseError]]:
    """(name, House) per selected line; a line that is no valid house gives its HouseError in place of the house.

    ``validate``, ``catalog`` and ``skip_unknown`` are :func:`~adaptenv.scene.house.load_house`'s.
    """
    for index, doc in dataset_documents(ds):
        label = line_label(ds.path, index)
        try:
            house = parse_house(doc, label)
            problems = validate_read_house(house, file=label, catalog=catalog, skip_unknown=skip_unknown,
                                           validate=validate)
            item = HouseError(problems) if problems else house
        except HouseError as exc:
            item = exc
        yield house_name(index), item


def load_one_house(spec: str | Path, *, validate: bool = True, catalog: Any = None,
                   skip_unknown: bool | None = None, what: str = "house") -> tuple[str, House]:
    """(name, house) of a HOUSE argument: a house JSON file (named by its stem) or a dataset slice that
    selects one house, e.g. ``train.jsonl.gz:2:3`` (named ``house-000002``).

    ``validate``, ``catalog`` and ``skip_unknown`` are :func:`~adaptenv.scene.house.load_house`'s; child
    objects left out for unknown assets are logged in one line. ConfigError when the spec names no file or a
    slice of several houses; HouseError when the house is invalid.
    """
    ds = parse_dataset_spec(spec)
    if ds is None:
        path = Path(spec)
        if not path.is_file():
            kind = not_regular(path.stat().st_mode) if path.exists() else None
            why = "is a folder, not a" if path.is_dir() else f"is {kind}, not a" if kind else "no such"
            raise ConfigError(f"{spec}: {why} {what} file; pass a house JSON file or one line of a dataset, "
                              "e.g. FILE.jsonl.gz:2:3")
        name, house = path.stem, load_house(path, validate=validate, catalog=catalog, skip_unknown=skip_unknown)
    else:
        name, house = _one_dataset_house(ds, validate=validate, catalog=catalog, skip_unknown=skip_unknown)
    if line := dropped_children_line([house]):
        log.warning("%s: %s", name, line)
    return name, house


def _one_dataset_house(ds: DatasetSlice, **load: Any) -> tuple[str, House]:
    """The one house a dataset slice selects; ConfigError when it selects several."""
    found: list[tuple[str, House | HouseError]] = []
    for item in dataset_houses(ds, **load):
        found.append(item)
        if len(found) > 1:
            first = int(found[0][0].rpartition("-")[2])
            raise ConfigError(f"{ds.spec}: the slice selects more than one house, and this command takes one; "
                              f"pick one line, e.g. {ds.path}:{first}:{first + 1}")
    name, house = found[0]
    if isinstance(house, HouseError):
        raise house
    return name, house
