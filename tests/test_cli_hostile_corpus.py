"""The hostile corpus: what a user types and the files they hand over, against every command that reads them.

Each case runs the real console entry point in-process and must end in its exit code (1 for adaptenv's own
refusals, 2 for click's usage errors) and exactly ONE line on stderr, ``error: ...``, that names the flag, file
or field; no file anywhere in the case's folders may change (every file and folder is compared, modification time,
size and inode, before and after). The expensive part of each command is replaced by a stand-in that raises, so a case
the checks let through fails at once instead of running for minutes.

The tables are built once: numbers from the command tree itself (every numeric option of every command), and
files and outputs by hand. :func:`test_the_corpus_is_counted_and_every_case_is_one_line` counts the cases and
measures the share that end in one line from the runs themselves.
"""

from __future__ import annotations

import contextlib
import gzip
import io
import json
import os
import sys
import tempfile
import warnings
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import pytest
import torch
import typer.main

from adaptenv.cli import app, main
from adaptenv.files import MANIFEST, FolderLock

HOUSE = Path(__file__).parent / "data" / "procthor-10k-train-1.json"
CONFIG = Path(__file__).parents[1] / "configs" / "experiment-small.json"
CORPUS_MIN = 238
"""The corpus holds at least this many cases (the count is asserted, not assumed)."""


class WorkStarted(Exception):
    """Raised by a stand-in for the expensive part of a command: the command got past its checks."""


def refuse_work(*args, **kwargs):
    raise WorkStarted


WORK = ["adaptenv.agents.evaluate.evaluate", "adaptenv.agents.memory.evaluate", "adaptenv.agents.train.SequenceBuffer",
        "adaptenv.agents.ppo.train_ppo", "adaptenv.curriculum.loop.run_loop",
        "adaptenv.curriculum.experiment.run_experiment", "adaptenv.scene.procedural.generate_houses",
        "adaptenv.cli.adapt._adapt_one", "adaptenv.sim.rollout.run_episode",
        *[f"adaptenv.bench.{name}.run" for name in ("sim", "expert", "render", "houses", "adapt", "plausibility",
                                                      "train", "executor", "adapt_edits")]]
"""The expensive entry points the commands call once their checks pass (module.attribute)."""


@dataclass(frozen=True)
class Case:
    """One hostile input: ``adaptenv ARGS`` must end in exit ``code`` and one line holding every one of ``words``.

    In ``args`` and ``words``, ``{in}`` is the folder of the user's files (:func:`user_files`) and ``{out}`` the
    case's own empty folder, also the working directory. ``report`` is True for ``adaptenv validate``, whose
    problems are its output: the one line is then its one problem on stdout (above the count), stderr empty.
    ``users_code`` marks a case where the user's own Python code raises: its traceback is theirs and is shown
    whole, so the case is counted but is not one line (README, "Errors"). ``output`` names the case's output
    folder where a command that streams its input may already have written (and recorded as its own) the part
    before the damage; nothing outside it may change. ``setup`` is the user's own files made in the case's folder
    before the run, (path, text), where a text ``-> TARGET`` makes a symbolic link to TARGET: after the run each is
    byte-identical (a link the same link). ``held`` names a folder of the case that another run is writing (holds
    locked) while this one runs; ``{pid}`` in ``words`` is that run's process id. ``works`` marks a case that must
    get past its checks and do its work for real (no stand-ins): exit 0, no error line, the user's files kept.
    """

    id: str
    args: tuple[str, ...]
    words: tuple[str, ...]
    code: int = 1
    report: bool = False
    users_code: bool = False
    output: str = ""
    setup: tuple[tuple[str, str], ...] = ()
    held: str = ""
    works: bool = False


@dataclass(frozen=True)
class Outcome:
    """What one run did: exit code, stderr lines, whether any file changed, and what escaped main()."""

    code: int | None
    lines: tuple[str, ...]
    touched: tuple[str, ...]
    escaped: str = ""
    out: tuple[str, ...] = ()
    changed: tuple[str, ...] = ()
    """The user's files of the case's ``setup`` that are not byte-identical after the run (or no longer the link)."""
    work: str = ""
    """The case's own folder (``{out}``)."""

    def line(self, case: Case) -> str | None:
        """The one line the case must end in, or None when there is not exactly one."""
        if case.report and not self.lines:
            problems = self.out[:-1] if self.out and self.out[-1].startswith("1 problem in 1 of 1") else self.out
            return problems[0] if len(problems) == 1 else None
        return self.lines[0] if len(self.lines) == 1 and self.lines[0].startswith("error: ") else None

    def outside(self, case: Case) -> tuple[str, ...]:
        """The changed files outside the case's output folder (all of them when it has none)."""
        return tuple(p for p in self.touched if not case.output or "/" + case.output + "/" not in p + "/")

    def one_line(self, case: Case, words: tuple[str, ...]) -> bool:
        """Whether the run is what the case demands: its exit code, one line with every word, no file changed."""
        line = self.line(case)
        return (not self.escaped and self.code == case.code and line is not None and "Traceback" not in line
                and all(w in line for w in words) and not self.outside(case) and not self.changed)


def fill(line: str, **values: str) -> str:
    """``line`` with each ``{name}`` of ``values`` replaced (``{in}`` and ``{out}`` are left for the run)."""
    for name, value in values.items():
        line = line.replace("{" + name + "}", value)
    return line


def case(id: str, args: str, *words: str, code: int = 1, report: bool = False) -> Case:
    """A case from a command line (split on spaces; the paths here hold none)."""
    return Case(id, tuple(args.split()), words, code, report)


# -- numbers: every numeric option of every command --------------------------------------------------------

def _commands(command, path: tuple[str, ...] = ()):
    """(words after ``adaptenv``, click command) of every leaf command."""
    if hasattr(command, "commands"):
        for name, sub in command.commands.items():
            yield from _commands(sub, (*path, name))
    else:
        yield path, command


def _numeric(param) -> type | None:
    """int or float when ``param`` takes numbers (a list of them included), else None."""
    annotation = param.type_descriptor.annotation
    for kind in (int, float):
        if annotation is kind or kind in getattr(annotation, "__args__", ()):
            return kind
    return None


CHECKED_IN_COMMAND = ("train", "ppo")
"""Commands whose numbers are checked by their config (adaptenv.limits) inside the command, not by click."""


def number_cases() -> list[Case]:
    """Per numeric option: text where a number goes; below its minimum, above its maximum; NaN for a float; -1 for
    the options a config checks. The flag is typed as its long name, the line must name it."""
    out = []
    for path, command in _commands(typer.main.get_command(app)):
        name = " ".join(path)
        for param in command.params:
            kind = _numeric(param)
            if kind is None:
                continue
            flag = max(param.opts, key=len)
            at = f"{name} {flag}"
            out.append(Case(f"{at} text", (*path, flag, "twelve"), (f"{flag} twelve:",), 2))
            callback = getattr(param.callback, "__name__", "")
            if param.min is not None:
                low = param.min - 1 if kind is int else param.min - 0.5
                out.append(Case(f"{at} below", (*path, flag, f"{low:g}"), (f"{flag} {low:g}:",), 2))
            if param.max is not None:
                high = param.max + 1
                out.append(Case(f"{at} above", (*path, flag, f"{high:g}"), (f"{flag} {high:g}:",), 2))
            if kind is float:
                out.append(Case(f"{at} nan", (*path, flag, "nan"), (f"{flag} nan:",), 2 if param.min is not None or
                                param.max is not None else 1))
                if callback == "finite" or name in CHECKED_IN_COMMAND:
                    # a finite maximum is click's range: it refuses inf itself, as a usage error
                    out.append(Case(f"{at} inf", (*path, flag, "inf"), (f"{flag} inf:",), 2 if param.max is not None
                                    else 1))
            if name in CHECKED_IN_COMMAND or callback in ("seed", "episodes"):
                out.append(Case(f"{at} -1", (*path, flag, "-1"), (f"{flag} -1",), 1))
            if callback in ("seed", "episodes", "episodes_or_none"):
                out.append(Case(f"{at} huge", (*path, flag, str(2**64)), (f"{flag} {2**64}:",), 1))
    return out


NUMBERS = number_cases()


# -- the user's files ------------------------------------------------------------------------------------

def _house_doc() -> dict:
    return json.loads(HOUSE.read_text(encoding="utf-8"))


def _checkpoint(path: Path) -> bytes:
    from adaptenv.agents.checkpoint import save_checkpoint
    from adaptenv.agents.network import NavNet, NetConfig

    torch.manual_seed(0)
    return save_checkpoint(path, NavNet(NetConfig(hidden=32, feature_dim=32))).read_bytes()


def _record(folder: Path) -> None:
    """t.json: an expert's episode in house.json; log.jsonl: the same poses as an AI2-THOR event log."""
    from typer.testing import CliRunner

    result = CliRunner().invoke(app, ["rollout", str(HOUSE), "--policy", "expert", "-o", str(folder / "t.json")])
    assert result.exit_code == 0, result.output
    steps = json.loads((folder / "t.json").read_text(encoding="utf-8"))["steps"]
    events = [{"action": "Pass" if k == 0 else "MoveAhead",
               "agent": {"position": {"x": s["pose"]["x"], "y": 0.9, "z": s["pose"]["z"]},
                         "rotation": {"x": 0, "y": s["pose"]["yaw"], "z": 0}}} for k, s in enumerate(steps[:3])]
    (folder / "log.jsonl").write_text("".join(json.dumps(e) + "\n" for e in events), encoding="utf-8")
    (folder / ".adaptenv-outputs").unlink(missing_ok=True)


def user_files(folder: Path) -> Path:
    """A user's folder of damaged, wrong and foreign files, and files of their own where outputs could go."""
    text = HOUSE.read_text(encoding="utf-8")
    doc = _house_doc()
    files: dict[str, bytes | str] = {
        "house.json": text, "empty.json": "", "trunc.json": text[: len(text) // 2], "list.json": "[1, 2]",
        "text.json": "hello, not JSON", "binary.json": b"\x00\xff\xfe garbage \x80", "null.json": "null",
        "deep.json": "[" * 100_000 + "]" * 100_000, "bom.json": "\ufeff" + text,
        "nan.json": text.replace('"x": ', '"x": NaN, "_": ', 1),
        "norooms.json": json.dumps({**doc, "rooms": []}), "noobjects.json": json.dumps({**doc, "objects": []}),
        "nowalls.json": json.dumps({**doc, "walls": "none"}), "house.txt": text,
        "d.jsonl": json.dumps(doc) + "\n" + json.dumps(doc) + "\n", "bad.jsonl": json.dumps(doc) + "\n{broken\n",
        "empty.jsonl": "", "d.jsonl.gz": gzip.compress((json.dumps(doc) + "\n").encode()),
        "trunc.jsonl.gz": gzip.compress((json.dumps(doc) + "\n").encode())[:3000],
        "junk.jsonl.gz": b"\x00\xff\xfe not gzip, not text \x80" * 10,
        "junk.pt": b"not a torch file", "pickle.pt": b"\x80\x04 a pickle header, then junk", "empty.pt": b"", "list.pt": b"", "house.pt": text,
        "t-empty.json": "", "t-text.json": "not a trajectory", "t-list.json": "[]", "t-obj.json": "{}",
        "t-steps.json": json.dumps({"house": "h", "steps": "many"}),
        "exp-empty.json": "", "exp-text.json": "{methods: none}", "exp-list.json": "[]",
        "exp-unknown.json": json.dumps({"bogus": 1}), "exp-types.json": json.dumps({"seeds": "zero"}),
        "exp-nan.json": '{"seeds": [0], "loop": {"finetune_lr": NaN}}',
        "exp-neg.json": json.dumps({"seeds": [-1]}), "exp-method.json": json.dumps({"methods": ["magic"]}),
        "exp-iter.json": json.dumps({"loop": {"iterations": 0}}),
        "llm-text.json": "model = gpt", "llm-unknown.json": json.dumps({"modle": "x"}),
        "llm-list.json": "[]", "llm-types.json": json.dumps({"max_tokens": "many"}),
        "assets-text.json": "not a table", "assets-list.json": "[1]",
        "assets-neg.json": json.dumps({"assets": {"a1": {"object_type": "Chair", "bbox": [-1, 1, 1]}}}),
        "assets-nan.json": '{"assets": {"a1": {"object_type": "Chair", "bbox": [NaN, 1, 1]}}}',
        "assets-empty.json": "",
        "log-empty.jsonl": "", "log-text.jsonl": "not json\n", "log-list.jsonl": "[1, 2]\n",
        "log-obj.jsonl": "{}\n", "log-nan.jsonl": '{"position": {"x": NaN, "y": 0.9, "z": 1}, "rotation": 0}\n',
        "ann-empty.json": "", "ann-trunc.json.gz": gzip.compress(b'{"a": {"category": "chair"}}' * 50)[:40],
        "ann-plain.json.gz": '{"a": {"category": "chair"}}', "ann-text.json": "uid,category",
        "my_policy.py": "raise RuntimeError(\"my policy's own bug\")\n", "mine.png": "my picture", "mine.json": "{\"my\": \"notes\"}", "mine.pt": "my weights", "card.json": "{}",
        "minedir/notes.txt": "my notes", "minedir2/notes.txt": "my notes",
        "run-bad/run.json": "{", "run-bad/iterations.jsonl": "garbage\n",
        "exp-dir/experiment.json": "[", "file-not-dir": "just a file",
    }
    for name, data in files.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data if isinstance(data, bytes) else data.encode("utf-8"))
    _record(folder)
    ckpt = _checkpoint(folder / "good.pt")
    (folder / "trunc.pt").write_bytes(ckpt[: len(ckpt) // 2])
    torch.save([1, 2, 3], folder / "list.pt")
    (folder / "dir.json").mkdir()
    (folder / "loop.json").symlink_to(folder / "loop.json")
    (folder / "run-empty").mkdir()
    return folder


# -- files: the cases ------------------------------------------------------------------------------------

H = "{in}/house.json"
TINY_TRAIN = ("--frames 64 --num-envs 4 --rollout-steps 16 --chunk-len 8 --batch-chunks 2 --buffer-frames 64 "
              "--calibrate-episodes 0 --eval-every 0 --final-eval-episodes 0")
"""train settings of one 64-frame block (the default block is 16,384 frames)."""
HOUSE_FILES = [("empty", "empty.json", "{in}/empty.json"), ("truncated", "trunc.json", "{in}/trunc.json"),
               ("list", "list.json", "{in}/list.json"), ("text", "text.json", "{in}/text.json"),
               ("binary", "binary.json", "{in}/binary.json"), ("null", "null.json", "{in}/null.json"),
               ("deep", "deep.json", "{in}/deep.json"), ("nan", "nan.json", "{in}/nan.json"),
               ("no-rooms", "norooms.json", "{in}/norooms.json"), ("walls-text", "nowalls.json", "{in}/nowalls.json"),
               ("folder", "dir.json", "{in}/dir.json"), ("missing", "nope.json", "{in}/nope.json"),
               ("dataset-truncated-gz", "trunc.jsonl.gz", "{in}/trunc.jsonl.gz"),
               ("dataset-not-gz", "junk.jsonl.gz", "{in}/junk.jsonl.gz"),
               ("dataset-bad-line", "bad.jsonl", "{in}/bad.jsonl:1:2"),
               ("dataset-empty", "empty.jsonl", "{in}/empty.jsonl"),
               ("slice-beyond", "d.jsonl", "{in}/d.jsonl:5:6"), ("slice-text", "d.jsonl", "{in}/d.jsonl:a:b"),
               ("slice-backwards", "d.jsonl", "{in}/d.jsonl:2:1"), ("slice-two-houses", "d.jsonl", "{in}/d.jsonl:0:2")]
"""(id, the name the line must hold, the HOUSE argument) of a house that is not one."""
HOUSE_READERS = {
    "render": "render {house} -o {out}/map.png", "rollout": "rollout {house} -o {out}/t.json",
    "rearrange": "houses rearrange {house} -o {out}/r.json", "analyze": "analyze {house} {in}/t.json",
    "audit": "audit {house} " + H, "adapt": "adapt {house} -o {out}/a",
    "ai2thor": "trajectory from-ai2thor {in}/log.jsonl --house {house} -o {out}/t.json",
}
HOUSE_CASES = [case(f"{reader} house {hid}", fill(line, house=arg), name)
               for reader, line in HOUSE_READERS.items() for hid, name, arg in HOUSE_FILES
               if not (reader in ("adapt",) and hid == "slice-two-houses")]

HOUSE_SETS = [("folder-of-nothing", "run-empty", "{in}/run-empty"), ("missing", "nope", "{in}/nope"),
              ("empty", "empty.json", "{in}/empty.json"), ("text", "text.json", "{in}/text.json"),
              ("dataset-truncated-gz", "trunc.jsonl.gz", "{in}/trunc.jsonl.gz"),
              ("dataset-empty", "empty.jsonl", "{in}/empty.jsonl"), ("unknown-preset", "preset:nope", "preset:nope"),
              ("unknown-suite", "suite:nope", "suite:nope")]
"""(id, what the line must hold, the --houses value) of a house set that is not one."""
SET_READERS = {"evaluate": "evaluate --houses {houses} -n 1 -o {out}/ev",
               "memory-check": "memory-check --houses {houses} -n 1",
               "train": "train --houses {houses} " + TINY_TRAIN + " -o {out}/p.pt",
               "loop": "loop --houses {houses} --heldout tiny=preset:tiny -o {out}/l"}
SET_CASES = [case(f"{reader} --houses {sid}", fill(line, houses=arg), name)
             for reader, line in SET_READERS.items() for sid, name, arg in HOUSE_SETS]

POLICIES = [("junk", "junk.pt"), ("pickle-header", "pickle.pt"), ("empty", "empty.pt"), ("truncated", "trunc.pt"), ("list", "list.pt"),
            ("house-as-policy", "house.json"), ("text-as-checkpoint", "house.pt"), ("missing", "nope.pt")]
POLICY_READERS = {"evaluate": "evaluate --houses preset:tiny -n 1 -o {out}/ev --policy {p}",
                  "rollout": "rollout " + H + " -o {out}/t.json --policy {p}",
                  "adapt": "adapt " + H + " -o {out}/a --policy {p}",
                  "memory-check": "memory-check --houses preset:tiny -n 1 --policy {p}",
                  "train-init": "train --houses preset:tiny " + TINY_TRAIN + " -o {out}/p.pt --init {p}",
                  "loop": "loop --houses preset:tiny --heldout tiny=preset:tiny -o {out}/l --policy {p}"}
POLICY_CASES = [case(f"{reader} policy {pid}", fill(line, p=f"{{in}}/{name}"), name)
                for reader, line in POLICY_READERS.items() for pid, name in POLICIES]
POLICY_CASES += [case(f"{reader} policy {pid}", fill(line, p=spec), spec)
                 for reader, line in POLICY_READERS.items() if reader != "train-init"
                 for pid, spec in (("no-module", "nosuch_module_xyz:policy"), ("no-attribute", "json:no_such_thing"),
                                   ("unknown-name", "pretrained-nope"))]

TRAJECTORIES = ["t-empty.json", "t-text.json", "t-list.json", "t-obj.json", "t-steps.json", "house.json",
                "nope.json", "dir.json"]
TRAJ_READERS = {"analyze": "analyze " + H + " {t}", "render": "render " + H + " -t {t} -o {out}/map.png",
                "adapt": "adapt " + H + " --trajectory {t} -o {out}/a"}
TRAJ_CASES = [case(f"{reader} trajectory {t}", fill(line, t=f"{{in}}/{t}"), t)
              for reader, line in TRAJ_READERS.items() for t in TRAJECTORIES]

CONFIGS = ["exp-empty.json", "exp-text.json", "exp-list.json", "exp-unknown.json", "exp-types.json", "exp-nan.json",
           "exp-neg.json", "exp-method.json", "exp-iter.json", "nope.json", "dir.json"]
CONFIG_CASES = [case(f"experiment --config {c}", f"experiment --config {{in}}/{c} -o {{out}}/x", c) for c in CONFIGS]

LLM_CONFIGS = ["llm-text.json", "llm-unknown.json", "llm-list.json", "llm-types.json", "nope.json"]
LLM_READERS = {"adapt": "adapt " + H + " -o {out}/a --llm-config {c}", "analyze": "analyze " + H +
               " {in}/t.json --llm-config {c}",
               "loop": "loop --houses preset:tiny --heldout tiny=preset:tiny -o {out}/l --llm-config {c}"}
LLM_CASES = [case(f"{reader} --llm-config {c}", fill(line, c=f"{{in}}/{c}"), c)
             for reader, line in LLM_READERS.items() for c in LLM_CONFIGS]

ASSET_TABLES = ["assets-text.json", "assets-list.json", "assets-neg.json", "assets-nan.json", "assets-empty.json",
                "nope.json", "dir.json"]
ASSET_CASES = [case(f"--assets {t} {where}", fill(line, t=f"{{in}}/{t}"), t)
               for t in ASSET_TABLES for where, line in (("before render", "--assets {t} render " + H + " -o {out}/m.png"),
                                                         ("after validate", "validate " + H + " --assets {t}"))]

LOGS = ["log-empty.jsonl", "log-text.jsonl", "log-list.jsonl", "log-obj.jsonl", "log-nan.jsonl", "nope.jsonl"]
LOG_CASES = [case(f"from-ai2thor log {log}", f"trajectory from-ai2thor {{in}}/{log} --house {H} -o {{out}}/t.json",
                  log) for log in LOGS]

ANNOTATIONS = ["ann-empty.json", "ann-trunc.json.gz", "ann-plain.json.gz", "ann-text.json", "nope.json", "dir.json"]
ANNOTATION_CASES = [case(f"from-objathor {a}", f"assets from-objathor {{in}}/{a} -o {{out}}/table.json", a)
                    for a in ANNOTATIONS]

REPORT_CASES = [case(f"report {r}", f"report {{in}}/{r} -o {{out}}/rep", r)
                for r in ("run-empty", "run-bad", "exp-dir", "nope", "file-not-dir", "house.json")]

VALIDATE_CASES = [case(f"validate {name}", f"validate {{in}}/{name}", name, report=True)
                  for name in ("nope.json", "dir.json", "d.jsonl:a:b", "trunc.jsonl.gz", "empty.json", "trunc.json",
                               "list.json", "binary.json", "deep.json", "nan.json", "junk.jsonl.gz")]

OUTPUT_CASES = [
    case("render over my picture", "render " + H + " -o {in}/mine.png", "-o {in}/mine.png", "--force"),
    case("render over its input", "render " + H + " -o " + H + " --force", "-o " + H, "input"),
    case("render into a file's folder", "render " + H + " -o {in}/file-not-dir/m.png", "file-not-dir"),
    case("rollout over my notes", "rollout " + H + " -o {in}/mine.json", "-o {in}/mine.json", "--force"),
    case("rollout render over its trajectory", "rollout " + H + " -o {out}/t.json --render {out}/t.json",
         "--render", "input"),
    case("rollout render over my picture", "rollout " + H + " -o {out}/t.json --render {in}/mine.png",
         "--render {in}/mine.png", "--force"),
    case("rearrange over its input", "houses rearrange " + H + " -o " + H + " --force", "-o " + H, "input"),
    case("rearrange over my notes", "houses rearrange " + H + " -o {in}/mine.json", "-o {in}/mine.json", "--force"),
    case("generate into my folder", "houses generate --n 1 -o {in}/minedir", "-o {in}/minedir", "--force"),
    case("generate into a file", "houses generate --n 1 -o {in}/mine.json", "{in}/mine.json", "-o"),
    case("export into my folder", "houses export {in}/d.jsonl -o {in}/minedir", "-o {in}/minedir", "--force"),
    case("export into its input's folder", "houses export {in}/d.jsonl -o {in}", "-o {in}", "input"),
    case("adapt into my folder", "adapt " + H + " -o {in}/minedir", "-o {in}/minedir", "--force"),
    case("adapt into its input's folder", "adapt " + H + " -o {in} --force", "-o {in}", "input"),
    case("evaluate into my folder", "evaluate --houses preset:tiny -n 1 -o {in}/minedir", "-o {in}/minedir",
         "--force"),
    case("evaluate into a file", "evaluate --houses preset:tiny -n 1 -o {in}/mine.json", "{in}/mine.json"),
    case("memory-check into my folder", "memory-check --houses preset:tiny -n 1 -o {in}/file-not-dir",
         "{in}/file-not-dir"),
    case("train over my weights", "train --houses preset:tiny " + TINY_TRAIN + " -o {in}/mine.pt", "{in}/mine.pt",
         "--force"),
    case("train card over my notes", "train --houses preset:tiny " + TINY_TRAIN + " -o {in}/card.pt",
         "its card {in}/card.json"),
    case("train run-dir my folder", "train --houses preset:tiny " + TINY_TRAIN + " -o {out}/p.pt --run-dir {in}/minedir",
         "--run-dir {in}/minedir", "--force"),
    case("ppo over my weights", "ppo --houses preset:tiny -o {in}/mine.pt", "{in}/mine.pt", "--force"),
    case("loop into my folder", "loop --houses preset:tiny -o {in}/minedir", "-o {in}/minedir"),
    case("loop resume of my folder", "loop --houses preset:tiny -o {in}/minedir2 --resume", "-o {in}/minedir2"),
    case("experiment into my folder", f"experiment --config {CONFIG} -o {{in}}/minedir", "{in}/minedir"),
    case("report into my folder", "report {in}/run-bad -o {in}/minedir", "-o {in}/minedir"),
    case("report over its input", "report {in}/run-bad -o {in}/run-bad --force", "-o {in}/run-bad", "input"),
    case("demo into my folder", "demo -o {in}/minedir", "-o {in}/minedir", "new or empty folder"),
    case("demo into a file", "demo -o {in}/mine.json", "{in}/mine.json"),
    case("assets over my notes", "assets from-objathor {in}/ann-text.json -o {in}/mine.json", "{in}/mine.json"),
    case("ai2thor over my notes", "trajectory from-ai2thor {in}/log-obj.jsonl --house " + H + " -o {in}/mine.json",
         "{in}/mine.json"),
    case("ai2thor over its log", "trajectory from-ai2thor {in}/log-obj.jsonl --house " + H +
         " -o {in}/log-obj.jsonl --force", "{in}/log-obj.jsonl"),
]


def made(id: str, args: str, *words: str, setup: dict[str, str], output: str = "", works: bool = False) -> Case:
    """A case run among the user's own files and links ``setup`` (path -> text, or "-> TARGET" for a link)."""
    return Case(id, tuple(args.split()), words, 0 if works else 1, output=output, setup=tuple(setup.items()),
                works=works)


USER = {"user.json": "my own notes, outside the output", "mine.png": "my own picture"}
"""The user's files beside an output folder, that a link inside it points to."""
USERS_RUN_DIR = {"D/state.pt": "my state", "D/config.json": '{"mine": true}', "D/notes.txt": "my notes",
                 "D/tb/mine.txt": "my log"}
"""A folder of the user's that happens to hold train's names (an older rule took any folder with a state.pt for
train's own)."""
LOOP_OWN = json.dumps({"folder": "loop", "files": {}})
LINK_CASES = [
    made("generate --force through a link", "houses generate --n 1 --rooms 2 -o {out}/out --force",
         "-o {out}/out", "house_0000.json", "symbolic link", setup={**USER, "out/house_0000.json": "-> ../user.json"}),
    made("rollout --force through links", "rollout " + H + " -o {out}/t.json --render {out}/t.png --force",
         "-o {out}/t.json", "symbolic link", setup={**USER, "t.json": "-> user.json", "t.png": "-> mine.png"}),
    made("rollout --force render through a link", "rollout " + H + " -o {out}/t.json --render {out}/t.png --force",
         "--render {out}/t.png", "symbolic link", setup={**USER, "t.png": "-> mine.png"}),
    made("train --force run-dir through a link", "train --houses preset:tiny " + TINY_TRAIN +
         " -o {out}/p.pt --run-dir {out}/D --force", "--run-dir {out}/D", "config.json", "symbolic link",
         setup={**USER, "D/config.json": "-> ../user.json"}),
    made("report --force through a link", "report {in}/run-bad -o {out}/rep --force", "-o {out}/rep", "index.html",
         "symbolic link", setup={**USER, "rep/index.html": "-> ../user.json"}),
    made("train run-dir of the user's with a state.pt", "train --houses preset:tiny " + TINY_TRAIN +
         " -o {out}/p.pt --run-dir {out}/D", "--run-dir {out}/D", "not written by adaptenv train", "--force",
         setup=USERS_RUN_DIR),
    made("demo into a folder with the old demo marker", "demo -o {out}/D", "-o {out}/D",
         "not written by adaptenv demo", setup={"D/.adaptenv-demo": "", "D/houses/train/myhouse.json":
                                                 HOUSE.read_text(encoding="utf-8")}),
    made("loop resume of a level outside its run", "loop --houses preset:tiny --heldout tiny=preset:tiny -o {out}/D "
         "--resume", "state.json", "'../../victim'",
         setup={f"D/{MANIFEST}": LOOP_OWN, "victim.json": HOUSE.read_text(encoding="utf-8"),
                "D/state.json": json.dumps({"config": {}, "state": {"iteration": 0, "pool": ["../../victim"]}})}),
    made("loop resume of a buffer level outside its run", "loop --houses preset:tiny --heldout tiny=preset:tiny "
         "-o {out}/D --resume", "state.json", "state.buffer", "'/tmp/victim'",
         setup={f"D/{MANIFEST}": LOOP_OWN, "D/state.json": json.dumps(
             {"config": {}, "state": {"iteration": 0, "buffer": {"level_ids": ["/tmp/victim"], "scores": [0.5],
                                                                  "last_seen": [0], "parent_ids": [None],
                                                                  "n_inserted": 1}}})}),
    made("loop resume of a gallery scene outside its run", "loop --houses preset:tiny --heldout tiny=preset:tiny "
         "-o {out}/D --resume", "iterations.jsonl", "'../x'",
         setup={f"D/{MANIFEST}": LOOP_OWN, "D/state.json": json.dumps({"config": {}, "state": {"iteration": 0}}),
                "D/iterations.jsonl": json.dumps({"iteration": 0, "env_steps": 0, "grad_updates": 0, "edits": 0,
                                                  "gallery": [{"scene": "../x"}]}) + "\n"}),
]
"""Outputs where a link or the user's own files stand: a link is never written through, even with --force; a folder
is adaptenv's only by its manifest; a resumed run reads only its own levels."""

WRITERS = {"houses generate": "houses generate --n 1 -o {out}/busy", "evaluate":
           "evaluate --houses preset:tiny -n 1 -o {out}/busy",
           "train": "train --houses preset:tiny " + TINY_TRAIN + " -o {out}/p.pt --run-dir {out}/busy",
           "loop": "loop --houses preset:tiny --heldout tiny=preset:tiny -o {out}/busy",
           "experiment": f"experiment --config {CONFIG} -o {{out}}/busy", "report": "report {in}/run-bad -o {out}/busy",
           "demo": "demo -o {out}/busy", "adapt": "adapt " + H + " -o {out}/busy"}
BUSY_CASES = [Case(f"{name} into a folder another run writes", tuple(line.split()),
                   ("{out}/busy", "another adaptenv run", "process id {pid}"), held="busy")
              for name, line in WRITERS.items()]
"""A second run into an output folder while a first one writes it: refused, naming the first's process id."""

KEPT_CASES = [
    made("train --force keeps the user's other files", "train --houses preset:tiny " + TINY_TRAIN +
         " -o {out}/D/p.pt --run-dir {out}/D --force", setup={k: v for k, v in USERS_RUN_DIR.items()
                                                                           if k in ("D/notes.txt", "D/tb/mine.txt")},
         output="D", works=True),
    made("report --force keeps the user's picture", "report {out}/run -o {out}/rep --force",
         setup={"run/run.json": json.dumps({"method": "dr", "seed": 0}), "run/iterations.jsonl": json.dumps(
             {"iteration": 0, "env_steps": 0, "grad_updates": 0, "edits": 0,
              "heldout": {"tiny": {"success": 0.5, "spl": 0.4, "episodes": 2}}}) + "\n",
                "rep/img/mine.png": "my own picture", "rep/notes.txt": "my notes"}, output="rep", works=True),
    made("generate --force keeps the user's other files", "houses generate --n 1 --rooms 2 -o {out}/out --force",
         setup={"out/notes.txt": "my notes", "out/sub/house_0000.json": "my house"}, output="out", works=True),
]
"""--force as promised: the command runs, replaces only files of the names it writes, and deletes nothing else."""

USAGE_CASES = [
    case("unknown command", "frobnicate", "frobnicate", code=2),
    case("unknown subcommand", "houses frobnicate", "frobnicate", "adaptenv houses --help", code=2),
    case("unknown option", "render " + H + " --colour red", "--colour", code=2),
    case("unknown global option", "--verbose render " + H, "--verbose", code=2),
    case("option without value", "evaluate --houses", "--houses", code=2),
    case("required option missing", "houses generate --n 1", "--out", code=2),
    case("required argument missing", "render", "HOUSE", code=2),
    case("extra argument", "render " + H + " " + H, "unexpected extra argument", code=2),
    case("bad choice", "bench executor --kind carrier-pigeon", "--kind carrier-pigeon", code=2),
    case("every zero", "memory-check --houses preset:tiny --every 0", "--every 0"),
    case("every negative", "memory-check --houses preset:tiny --every -8", "--every -8"),
    case("rooms text", "houses generate --rooms many -o {out}/h", "--rooms"),
    case("rooms eleven", "houses generate --rooms 11 -o {out}/h", "--rooms"),
    case("n zero", "houses generate --n 0 -o {out}/h", "--n"),
    case("preset unknown", "houses generate --preset nope -o {out}/h", "--preset"),
    case("heldout without name", "loop --houses preset:tiny --heldout preset:tiny -o {out}/l", "--heldout"),
    case("highlight unknown", "render " + H + " --highlight Nope|1|2 -o {out}/m.png", "Nope|1|2"),
    case("rollout unknown target", "rollout " + H + " --target Unicorn -o {out}/t.json", "Unicorn"),
    case("generator unknown", "adapt " + H + " --generator magic -o {out}/a", "magic"),
]

ODD_TEXT = [
    Case("render house with a line break", ("render", "{in}/no\nsuch.json", "-o", "{out}/m.png"), ("no\\nsuch.json",)),
    Case("render house named empty", ("render", "", "-o", "{out}/m.png"), ("is a folder, not a house file",)),
    Case("render -o empty", ("render", H, "-o", ""), ("-o",)),
    Case("render house /dev/null", ("render", "/dev/null", "-o", "{out}/m.png"), ("/dev/null",)),
    Case("render house symlink loop", ("render", "{in}/loop.json", "-o", "{out}/m.png"), ("loop.json",)),
    Case("rollout policy with a line break", ("rollout", H, "--policy", "my\npolicy", "-o", "{out}/t.json"),
         ("my\\npolicy",)),
    Case("rollout policy named empty", ("rollout", H, "--policy", "", "-o", "{out}/t.json"), ("--policy",)),
    Case("rollout target with a tab", ("rollout", H, "--target", "Be\td", "-o", "{out}/t.json"), ("Be\\td",)),
    Case("evaluate houses with a line break", ("evaluate", "--houses", "{in}/a\nb", "-n", "1"), ("a\\nb",)),
    Case("evaluate houses empty", ("evaluate", "--houses", "", "-n", "1"), ("--houses",)),
    Case("evaluate policy control character", ("evaluate", "--houses", "preset:tiny", "-n", "1", "--policy",
                                               "p\x1b[31m.pt"), ("\\x1b",)),
    Case("validate path with a line break", ("validate", "{in}/x\ny.json"), ("x\\ny.json",), report=True),
    Case("assets table /dev/null", ("--assets", "/dev/null", "validate", H), ("/dev/null",)),
    Case("seed in hex", ("rollout", H, "--seed", "0x10", "-o", "{out}/t.json"), ("--seed 0x10",), 2),
    Case("seed empty", ("rollout", H, "--seed", "", "-o", "{out}/t.json"), ("--seed",), 2),
    Case("episodes in e-notation", ("evaluate", "--houses", "preset:tiny", "-n", "1e3"), ("--episodes 1e3",), 2),
    Case("size with a unit", ("render", H, "--size", "512px"), ("--size 512px",), 2),
    Case("every with text", ("memory-check", "--houses", "preset:tiny", "--every", "often"), ("--every often",), 2),
]
"""Text no one means to type: line breaks, control characters, empty values, special files."""

DATASETS = [("empty", "{in}/empty.jsonl", "empty.jsonl"), ("truncated-gz", "{in}/trunc.jsonl.gz", "trunc.jsonl.gz"),
            ("not-gz", "{in}/junk.jsonl.gz", "junk.jsonl.gz"), ("bad-line", "{in}/bad.jsonl", "bad.jsonl line 2"),
            ("missing", "{in}/nope.jsonl", "nope.jsonl"), ("slice-beyond", "{in}/d.jsonl:7:9", "d.jsonl:7:9"),
            ("slice-text", "{in}/d.jsonl:x:", "d.jsonl:x:"), ("house-file", H, "house.json")]
EXPORT_CASES = [Case(f"export dataset {did}", ("houses", "export", arg, "-o", "{out}/h"), (word,), output="h")
                for did, arg, word in DATASETS]
"""houses export streams the dataset: the houses before a damaged line are written, and recorded as its own."""

CHOICES = [
    case("adapt analyzer unknown", "adapt " + H + " --analyzer oracle -o {out}/a", "--analyzer", "oracle"),
    case("adapt door-edits builtin", "adapt " + H + " --door-edits -o {out}/a", "--door-edits"),
    case("adapt relocate-targets learned", "adapt " + H + " --generator learned --relocate-targets -o {out}/a",
         "--relocate-targets"),
    case("adapt trajectory with a dataset", "adapt {in}/d.jsonl --trajectory {in}/t.json -o {out}/a", "d.jsonl",
         "pick one line"),
    case("adapt target not in trajectory", "adapt " + H + " --trajectory {in}/t.json --target Unicorn -o {out}/a",
         "--target Unicorn"),
    case("audit adapted empty", "audit " + H + " {in}/empty.json", "empty.json"),
    case("audit adapted text", "audit " + H + " {in}/text.json", "text.json"),
    case("audit adapted missing", "audit " + H + " {in}/nope.json", "nope.json"),
    case("audit original missing", "audit {in}/nope.json " + H, "nope.json"),
    case("ai2thor target unknown", "trajectory from-ai2thor {in}/log.jsonl --house " + H +
         " --target Unicorn -o {out}/t.json", "Unicorn"),
    case("ai2thor without --house", "trajectory from-ai2thor {in}/log.jsonl -o {out}/t.json", "--house", code=2),
    case("objathor unmapped unknown", "assets from-objathor {in}/ann-text.json --unmapped maybe -o {out}/t.json",
         "--unmapped"),
    case("loop method unknown", "loop --method magic -o {out}/l", "method 'magic'"),
    case("loop heldout empty name", "loop --heldout =preset:tiny -o {out}/l", "--heldout"),
    case("loop executor unknown", "loop --executor carrier-pigeon -o {out}/l", "--executor", "carrier-pigeon"),
    case("loop finetune-algo unknown", "loop --finetune-algo sgd -o {out}/l", "finetune_algo", "sgd"),
    case("loop policy without network", "loop --houses preset:tiny --policy expert -o {out}/l", "--policy", "expert"),
    case("experiment executor unknown", f"experiment --config {CONFIG} --executor carrier-pigeon -o {{out}}/x",
         "--executor", "carrier-pigeon"),
    case("evaluate wipe a memoryless policy", "evaluate --houses preset:tiny -n 1 --policy expert --wipe-every 8",
         "expert"),
    case("memory-check a memoryless policy", "memory-check --houses preset:tiny -n 1 --policy expert", "expert"),
    case("rollout policy random seed text", "rollout " + H + " --policy random:x -o {out}/t.json", "random:x"),
    case("train init without network", "train --houses preset:tiny " + TINY_TRAIN + " -o {out}/p.pt --init expert",
         "--init", "expert"),
    case("generate split unknown", "houses generate --n 1 --split secret -o {out}/h", "--split", "secret"),
    case("generate rooms range text", "houses generate --n 1 --rooms 3-x -o {out}/h", "--rooms"),
    case("render highlight colour unknown", "render " + H + " --highlight Fridge|2|1=ultraviolet -o {out}/m.png",
         "ultraviolet"),
]
"""Names and words a command takes from a fixed set, and combinations of flags that cannot go together."""

FILES = (HOUSE_CASES + SET_CASES + POLICY_CASES + TRAJ_CASES + CONFIG_CASES + LLM_CASES + ASSET_CASES + LOG_CASES
         + ANNOTATION_CASES + REPORT_CASES + VALIDATE_CASES + OUTPUT_CASES + LINK_CASES + BUSY_CASES + USAGE_CASES
         + ODD_TEXT + EXPORT_CASES + CHOICES)
USERS_CODE = [Case(f"{command[0]} policy of the user's raising", (*command, "--policy", "{in}/my_policy.py:policy"),
                   ("RuntimeError: my policy's own bug",), users_code=True)
              for command in (("rollout", H, "-o", "{out}/t.json"), ("evaluate", "--houses", "preset:tiny", "-n", "1"),
                              ("adapt", H, "-o", "{out}/a"))]
"""A ``--policy module:attribute`` whose module raises: the user's own code, whose traceback they need."""

CORPUS = NUMBERS + FILES + USERS_CODE


# -- running a case ----------------------------------------------------------------------------------------

def snapshot(*folders: Path) -> dict[str, tuple[int, int, int]]:
    """Every file and folder under ``folders``: (modification time in ns, size, inode); a write, a replacement or a
    new entry changes it."""
    return {str(p): (s.st_mtime_ns, s.st_size, s.st_ino) for folder in folders
            for p in sorted(folder.rglob("*")) if (s := p.lstat())}


_GET_COMMAND = typer.main.get_command


@cache
def _command():
    """adaptenv's click command, built once (typer builds it anew on every call, 0.1 s each)."""
    return _GET_COMMAND(app)


def _get_command(typer_app):
    return _command() if typer_app is app else _GET_COMMAND(typer_app)


def _console_warning_filters() -> None:
    """The warnings a fresh ``adaptenv`` process prints (Python's default filters; pytest's are replaced)."""
    warnings.resetwarnings()
    warnings.simplefilter("always")
    for category in (DeprecationWarning, PendingDeprecationWarning, ImportWarning, ResourceWarning):
        warnings.filterwarnings("ignore", category=category)


def run_case(c: Case, inputs: Path, root: Path) -> Outcome:
    """Run one case through the console entry point, in a fresh folder under ``root``."""
    work = Path(tempfile.mkdtemp(prefix="case-", dir=root))
    args = [a.replace("{in}", str(inputs)).replace("{out}", str(work)) for a in c.args]
    made = make_users_files(work, c.setup)
    held = FolderLock(work / c.held).acquire("the other run") if c.held else None
    before = snapshot(inputs, work)
    err, out, code, escaped = io.StringIO(), io.StringIO(), None, ""
    with pytest.MonkeyPatch.context() as m:
        m.setattr(sys, "argv", ["adaptenv", *args])
        m.chdir(work)
        m.setattr(typer.main, "get_command", _get_command)
        for target in WORK if not c.works else ():
            m.setattr(target, refuse_work, raising=False)
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out), warnings.catch_warnings(record=True) as shown:
            _console_warning_filters()
            try:
                main()
                code = 0
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else 1
            except BaseException as exc:  # noqa: BLE001  (a traceback, or work that started: the case fails)
                escaped = f"{type(exc).__name__}: {exc}"
    err.write("".join(f"{w.category.__name__}: {w.message}\n" for w in shown))  # a console prints them on stderr
    after = snapshot(inputs, work)
    if held is not None:
        held.release()
    touched = tuple(sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k)))
    return Outcome(code, tuple(err.getvalue().splitlines()), touched, escaped, tuple(out.getvalue().splitlines()),
                   changed=tuple(k for k, v in made.items() if users_file(work / k) != v), work=str(work))


def users_file(path: Path) -> tuple[str, bytes | str] | None:
    """What a file of the user's is: ("link", its target) or ("file", its bytes); None when it is gone."""
    if path.is_symlink():
        return "link", os.readlink(path)
    return ("file", path.read_bytes()) if path.is_file() else None


def make_users_files(folder: Path, setup: tuple[tuple[str, str], ...]) -> dict[str, tuple[str, bytes | str] | None]:
    """Make a case's own files of the user's in ``folder`` (see :class:`Case`); returns what each one is."""
    for rel, text in setup:
        path = folder / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        if text.startswith("-> "):
            path.symlink_to(text[3:])
        else:
            path.write_text(text, encoding="utf-8")
    return {rel: users_file(folder / rel) for rel, _ in setup}


@pytest.fixture(scope="module")
def corpus_dirs(tmp_path_factory) -> tuple[Path, Path]:
    """(the user's files, the root of the case folders), shared by the module's cases."""
    return user_files(tmp_path_factory.mktemp("user")), tmp_path_factory.mktemp("cases")


OUTCOMES: dict[str, Outcome] = {}
"""Each case's outcome, run once: by its own test, or by the counting test when run alone."""


def outcome(c: Case, dirs: tuple[Path, Path]) -> Outcome:
    if c.id not in OUTCOMES:
        OUTCOMES[c.id] = run_case(c, *dirs)
    return OUTCOMES[c.id]


def words_of(c: Case, dirs: tuple[Path, Path]) -> tuple[str, ...]:
    work = outcome(c, dirs).work
    return tuple(w.replace("{in}", str(dirs[0])).replace("{out}", work).replace("{pid}", str(os.getpid()))
                 for w in c.words)


def check(c: Case, dirs: tuple[Path, Path]) -> None:
    result = outcome(c, dirs)
    words = words_of(c, dirs)
    if c.users_code:  # the user's exception reaches Python, which prints its traceback
        assert all(result.escaped.startswith(w) for w in words) and not result.outside(c), result
        return
    assert not result.escaped, result.escaped
    assert result.code == c.code, (result.code, result.lines)
    line = result.line(c)
    assert line is not None, (result.lines, result.out)
    assert "Traceback" not in line and all(w in line for w in words), (words, line)
    assert not result.outside(c), result.touched
    assert not result.changed, result.changed


@pytest.mark.parametrize("c", NUMBERS, ids=[c.id for c in NUMBERS])
def test_a_number_is_refused_in_one_line_naming_its_flag(c, corpus_dirs):
    check(c, corpus_dirs)


@pytest.mark.parametrize("c", FILES, ids=[c.id for c in FILES])
def test_a_file_or_output_is_refused_in_one_line_naming_it(c, corpus_dirs):
    check(c, corpus_dirs)


@pytest.mark.parametrize("c", KEPT_CASES, ids=[c.id for c in KEPT_CASES])
def test_force_replaces_only_its_own_names_and_deletes_nothing(c, corpus_dirs):
    result = outcome(c, corpus_dirs)
    assert not result.escaped and result.code == 0, (result.escaped, result.code, result.lines)
    assert not any(line.startswith("error") for line in result.lines), result.lines
    assert not result.outside(c), result.touched
    assert not result.changed, result.changed


@pytest.mark.parametrize("c", USERS_CODE, ids=[c.id for c in USERS_CODE])
def test_a_policy_of_the_users_own_that_raises_shows_its_traceback(c, corpus_dirs):
    check(c, corpus_dirs)


def test_the_corpus_is_counted_and_every_case_is_one_line(corpus_dirs, record_property):
    ids = [c.id for c in CORPUS]
    assert len(ids) == len(set(ids)), "case ids repeat"
    ok = {c.id: outcome(c, corpus_dirs).one_line(c, words_of(c, corpus_dirs)) for c in CORPUS}
    share = sum(ok.values()) / len(ok)
    record_property("corpus_cases", len(ok))
    record_property("one_line_share", share)
    print(f"hostile corpus: {len(ok)} cases, {sum(ok.values())} end in one line ({share:.1%}); the others are a "
          f"user's own code raising: {sorted(k for k, v in ok.items() if not v)}")
    assert len(ok) >= CORPUS_MIN
    assert {k for k, v in ok.items() if not v} == {c.id for c in USERS_CODE}
    readme = (Path(__file__).parents[1] / "README.md").read_text(encoding="utf-8")
    assert f"{len(USERS_CODE)} cases of the hostile-input corpus" in readme  # where the docs say so


# -- evidence, bounds, waiting and contracts ----------------------------------------------------------------
# A trajectory is evidence, not a verdict: its metrics are recomputed from its poses and its house, and a pose that
# does not follow the one before by one action is refused. Only regular files are read, each kind up to its size
# limit, JSON up to JSON_DEPTH_MAX deep. A silent LLM server is said, attempt by attempt. A user's policy that breaks
# the contract (an action that is none, a wrong number of actions) is one line naming the policy, episode and value.

_CORPUS_USER_FILES = user_files


def _traj_doc(folder: Path) -> dict:
    return json.loads((folder / "t.json").read_text(encoding="utf-8"))


def _cut(doc: dict, n: int, **metrics) -> dict:
    """The first ``n`` steps of the recorded episode, its stored metrics (those of the whole run) changed."""
    return {**doc, "steps": doc["steps"][:n], "final_pose": doc["steps"][n]["pose"],
            "metrics": {**doc["metrics"], **metrics}}


def _silent_server() -> str:
    """The base URL of a socket on 127.0.0.1 that accepts connections (the kernel's backlog) and never answers."""
    import atexit
    import socket

    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen(64)
    atexit.register(silent.close)
    return f"http://127.0.0.1:{silent.getsockname()[1]}/v1"


def evidence_files(folder: Path) -> None:
    """Forged trajectories, special files, files over their size limit, a silent LLM server's config and policies
    that break the contract, in the user's folder."""
    import os

    from adaptenv import limits

    doc = _traj_doc(folder)
    n = len(doc["steps"])
    turned = json.loads(json.dumps(doc))
    turned["steps"][3]["pose"]["yaw"] = (turned["steps"][2]["pose"]["yaw"] + 90) % 360
    blocked = json.loads(json.dumps(doc))
    move = next(i for i, s in enumerate(blocked["steps"][:-1]) if s["action"] == "m" and s["moved"])
    blocked["steps"][move]["moved"] = False
    docs = {
        "t-cut-spl.json": _cut(doc, 5, spl=5.0),
        "t-repeated.json": {**doc, "steps": doc["steps"] * (104_000 // n),
                            "metrics": {**doc["metrics"], "episode_length": n * (104_000 // n)}},
        "t-sight-past-end.json": _cut(doc, 5, first_sight_step=n - 10, success=False, spl=0.0, sel=0.0),
        "t-turned.json": turned, "t-blocked-moved.json": blocked,
    }
    for name, d in docs.items():
        (folder / name).write_text(json.dumps(d), encoding="utf-8")
    url = _silent_server()
    for name, retries in (("llm-silent.json", 0), ("llm-silent-retry.json", 1)):
        (folder / name).write_text(json.dumps({"provider": "openai-compatible", "base_url": url, "timeout_s": 0.2,
                                               "max_retries": retries, "backoff_base_s": 0.0}), encoding="utf-8")
    for name, size in (("huge.json", limits.HOUSE_BYTES), ("huge-assets.json", limits.ASSET_TABLE_BYTES),
                       ("huge-config.json", limits.CONFIG_BYTES), ("huge-t.json", limits.TRAJECTORY_BYTES)):
        with open(folder / name, "wb") as f:  # sparse: its size is all a reader may look at
            f.truncate(size + 1)
    with open(folder / "huge-line.jsonl", "wb") as f:
        f.truncate(limits.DATASET_LINE_BYTES + 1)
    (folder / "bad_policy.py").write_text(
        "import numpy as np\n\n\nclass Fixed:\n    def __init__(self, action, extra=0):\n"
        "        self.action, self.extra = action, extra\n\n    def initial_state(self, batch):\n        return None\n\n"
        "    def act(self, obs, state, done):\n        return np.full(len(done) + self.extra, self.action), state\n\n\n"
        "action_12345 = Fixed(12345)\nfive_actions = Fixed(0, extra=3)\nhalf_action = Fixed(2.5)\n", encoding="utf-8")
    os.mkfifo(folder / "fifo.json")


def user_files(folder: Path) -> Path:  # noqa: F811  (the corpus's files, plus those of the cases below)
    """The corpus's user files and :func:`evidence_files`."""
    _CORPUS_USER_FILES(folder)
    evidence_files(folder)
    return folder


FORGED = [("repeated", "t-repeated.json", ("steps[", "jumps", "farther than one move (0.2 m)")),
          ("turned", "t-turned.json", ("steps[3].pose", "turns 90 degrees", "more than one turn (30 degrees)")),
          ("blocked-but-moved", "t-blocked-moved.json", (".moved", "marked blocked")),
          ("fifo", "fifo.json", ("FIFO", "not a regular file")),
          ("over-limit", "huge-t.json", ("over the 64.0 MiB limit of the trajectory",))]
EVIDENCE_CASES = [Case(f"{reader} trajectory {fid}", tuple(fill(line, t=f"{{in}}/{name}").split()), words)
                  for reader, line in TRAJ_READERS.items() for fid, name, words in FORGED]
"""Trajectories whose poses cannot be an episode, and files that are no trajectory to read: refused in one line."""

H_ = "{in}/house.json"
BOUNDED_CASES = [
    case("validate a FIFO", "validate {in}/fifo.json", "fifo.json", "FIFO", report=True),
    case("validate /dev/zero", "validate /dev/zero", "/dev/zero", "character device", report=True),
    case("validate a house over its limit", "validate {in}/huge.json", "huge.json", "over the 32.0 MiB limit",
         report=True),
    case("validate a dataset line over its limit", "validate {in}/huge-line.jsonl", "huge-line.jsonl line 1",
         "over the 32.0 MiB limit"),
    case("render a FIFO house", "render {in}/fifo.json -o {out}/m.png", "fifo.json"),
    case("--assets /dev/zero", "--assets /dev/zero validate " + H_, "--assets /dev/zero", "character device"),
    case("--assets a FIFO", "validate " + H_ + " --assets {in}/fifo.json", "fifo.json", "FIFO"),
    case("--assets over its limit", "--assets {in}/huge-assets.json validate " + H_, "huge-assets.json",
         "over the 64.0 MiB limit"),
    case("experiment --config a FIFO", "experiment --config {in}/fifo.json -o {out}/x", "fifo.json", "FIFO"),
    case("experiment --config over its limit", "experiment --config {in}/huge-config.json -o {out}/x",
         "huge-config.json", "over the 1.0 MiB limit"),
    case("experiment --config deep", "experiment --config {in}/deep.json -o {out}/x", "deep.json", "64 deep"),
    case("--assets deep", "--assets {in}/deep.json validate " + H_, "deep.json", "64 deep"),
    case("analyze --llm-config deep", "analyze " + H_ + " {in}/t.json --llm-config {in}/deep.json", "deep.json",
         "64 deep"),
    case("adapt --llm-config deep", "adapt " + H_ + " -o {out}/a --llm-config {in}/deep.json", "deep.json",
         "64 deep"),
    case("from-objathor deep", "assets from-objathor {in}/deep.json -o {out}/table.json", "deep.json", "64 deep"),
    case("from-objathor a FIFO", "assets from-objathor {in}/fifo.json -o {out}/table.json", "fifo.json", "FIFO"),
    case("from-ai2thor a FIFO", "trajectory from-ai2thor {in}/fifo.json --house " + H_ + " -o {out}/t.json",
         "fifo.json", "FIFO"),
    case("from-ai2thor /dev/zero", "trajectory from-ai2thor /dev/zero --house " + H_ + " -o {out}/t.json",
         "/dev/zero", "character device"),
    case("analyze --llm a silent server", "analyze " + H_ + " {in}/t.json --llm --llm-config {in}/llm-silent.json",
         "127.0.0.1", "after 1 attempt", "timed out after 0.2 s"),
]
"""Special files, files over their size limit, JSON nested too deeply, a server that never answers: one line each."""

CORPUS.extend(EVIDENCE_CASES + BOUNDED_CASES)


@pytest.mark.parametrize("c", EVIDENCE_CASES + BOUNDED_CASES, ids=[c.id for c in EVIDENCE_CASES + BOUNDED_CASES])
def test_a_forged_trajectory_or_an_unbounded_read_is_refused_in_one_line(c, corpus_dirs):
    check(c, corpus_dirs)


RECOMPUTED = [
    ("analyze cut with spl 5", ("analyze", H_, "{in}/t-cut-spl.json"), "",
     ("t-cut-spl.json", "stored spl 5.00 differs from recomputed 0.00", "stored episode_length",
      "the recomputed figures are used"), "Outcome: failure"),
    ("analyze sight past the end", ("analyze", H_, "{in}/t-sight-past-end.json"), "",
     ("t-sight-past-end.json", "stored first_sight_step", "differs from recomputed"), "within 5 steps"),
    ("render cut with spl 5", ("render", H_, "-t", "{in}/t-cut-spl.json", "-o", "{out}/r/map.png"), "r",
     ("stored spl 5.00 differs from recomputed 0.00",), "wrote"),
]
"""(id, args, output folder, the words of the one stderr line, what stdout holds): a trajectory whose stored
metrics its poses contradict is analyzed and drawn with the recomputed ones, and the difference said in one line."""


@pytest.mark.parametrize("id_, args, output, words, said", RECOMPUTED, ids=[r[0] for r in RECOMPUTED])
def test_stored_metrics_are_recomputed_and_the_difference_said_in_one_line(id_, args, output, words, said,
                                                                          corpus_dirs):
    c = Case(id_, args, words, code=0, output=output)
    result = run_case(c, *corpus_dirs)
    assert not result.escaped and result.code == 0, (result.escaped, result.lines)
    assert len(result.lines) == 1 and all(w in result.lines[0] for w in words), result.lines
    assert any(said in line for line in result.out), result.out
    assert not result.outside(c), result.touched
    if id_.startswith("analyze cut"):
        assert not any("SPL 5" in line for line in result.out)


def test_a_silent_llm_server_is_said_at_each_retry_then_in_one_error(corpus_dirs):
    c = Case("analyze --llm a silent server, one retry",
             ("analyze", H_, "{in}/t.json", "--llm", "--llm-config", "{in}/llm-silent-retry.json"), ())
    result = run_case(c, *corpus_dirs)
    assert not result.escaped and result.code == 1, (result.escaped, result.lines)
    assert len(result.lines) == 2, result.lines
    notice, error = result.lines
    assert notice.startswith("LLM: attempt 1 of 2 at http://127.0.0.1:") and "timed out after 0.2 s" in notice
    assert error.startswith("error: ") and "after 2 attempt" in error
    assert not result.touched


CONTRACT = [
    ("rollout action 12345", ("rollout", H_, "--policy", "{in}/bad_policy.py:action_12345", "-o", "{out}/t.json"),
     "", ("--policy {in}/bad_policy.py:action_12345", "action 12345", "episode 0", "from 0 to 6")),
    ("rollout half an action", ("rollout", H_, "--policy", "{in}/bad_policy.py:half_action", "-o", "{out}/t.json"),
     "", ("bad_policy.py:half_action", "action 2.5", "episode 0")),
    ("evaluate five actions for two episodes", ("evaluate", "--houses", H_, "-n", "2", "--policy",
                                                "{in}/bad_policy.py:five_actions", "-o", "{out}/ev"), "ev",
     ("--policy {in}/bad_policy.py:five_actions", "5 actions for 2 episodes")),
    ("adapt action 12345", ("adapt", H_, "--policy", "{in}/bad_policy.py:action_12345", "-o", "{out}/a"), "a",
     ("bad_policy.py:action_12345", "action 12345")),
]
"""(id, args, output folder, words): a user's policy whose answers break the contract, run for real."""


@pytest.mark.parametrize("id_, args, output, words", CONTRACT, ids=[r[0] for r in CONTRACT])
def test_a_policy_that_breaks_the_contract_is_one_line_naming_it(id_, args, output, words, corpus_dirs, monkeypatch):
    monkeypatch.setattr(sys.modules[__name__], "WORK", [])  # the policy must really be asked
    c = Case(id_, args, words, output=output)
    check(c, corpus_dirs)
