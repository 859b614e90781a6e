"""The output rule of every command that writes (adaptenv.cli._outputs), through the real command line.

Each refusal is exit 1 with one line on stderr naming the flag and the file and the fix, and touches no file:
the whole tmp folder is compared, bytes and modification times, before and after.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from adaptenv.cli import app, main
from adaptenv.cli._outputs import MANIFEST

sys.path.insert(0, str(Path(__file__).parent))
from test_cli_safety import LOOP, TINY_TRAIN, WorkStarted, refuse_work  # noqa: E402  (the cheapest train and loop)

HOUSE = Path(__file__).parent / "data" / "procthor-10k-train-1.json"
CONFIG = Path(__file__).parents[1] / "configs" / "experiment-small.json"


def snapshot(folder: Path) -> dict[str, tuple[int, bytes]]:
    """Every file under ``folder``: (modification time in ns, bytes)."""
    return {p.relative_to(folder).as_posix(): (p.stat().st_mtime_ns, p.read_bytes())
            for p in sorted(folder.rglob("*")) if p.is_file()}


def cli(monkeypatch, capsys, *args) -> tuple[int, str]:
    """Run ``adaptenv ARGS`` through the console entry point: (exit code, stderr)."""
    monkeypatch.setattr(sys, "argv", ["adaptenv", *map(str, args)])
    code = 0
    try:
        main()
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    return code, capsys.readouterr().err


def refused(monkeypatch, capsys, tmp_path, *args, words=("--force",)) -> str:
    """Run a command that must be refused: exit 1, one line naming ``words``, nothing under tmp_path touched."""
    before = snapshot(tmp_path)
    code, err = cli(monkeypatch, capsys, *args)
    line = " ".join(err.split())
    assert code == 1 and len(err.strip().splitlines()) == 1 and line.startswith("error: "), err
    for w in words:
        assert str(w) in line, (w, line)
    assert snapshot(tmp_path) == before
    return line


def ok(*args):
    res = CliRunner().invoke(app, [str(a) for a in args])
    assert res.exit_code == 0, (res.output, res.exception)
    return res


def mine(path: Path, text: str = "the user's own file") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


# -- files --------------------------------------------------------------------------------------

def test_houses_generate_replaces_its_own_houses_but_not_a_house_you_edited(tmp_path, monkeypatch, capsys):
    out = tmp_path / "houses"
    mine(out / "notes.txt")
    refused(monkeypatch, capsys, tmp_path, "houses", "generate", "--preset", "tiny", "-o", out,
            words=(f"-o {out}", "not written by adaptenv houses generate", "--force"))
    (out / "notes.txt").unlink()
    ok("houses", "generate", "--preset", "tiny", "-o", out)
    ok("houses", "generate", "--preset", "tiny", "-o", out)  # its own output: replaced whole
    house = sorted(out.glob("*.json"))[0]
    house.write_text(house.read_text() + "\n")  # the user edits one
    line = refused(monkeypatch, capsys, tmp_path, "houses", "generate", "--preset", "tiny", "-o", out)
    assert house.name in line and "changed since" in line
    ok("houses", "generate", "--preset", "tiny", "-o", out, "--force")
    assert (out / MANIFEST).is_file()
    ok("houses", "generate", "--n", "1", "--rooms", "1", "-o", out)  # fewer houses: none of the earlier set is left
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST, "house_0000.json"]


def test_houses_export_does_not_replace_an_edited_house(tmp_path, monkeypatch, capsys):
    dataset = tmp_path / "d.jsonl"
    dataset.write_text(json.dumps(json.loads(HOUSE.read_text())) + "\n")
    out = tmp_path / "houses"
    ok("houses", "export", dataset, "-o", out)
    ok("houses", "export", dataset, "-o", out)
    mine(out / "house-000000.json", "{}")
    refused(monkeypatch, capsys, tmp_path, "houses", "export", dataset, "-o", out,
            words=(f"-o {out}", "house-000000.json", "--force"))
    refused(monkeypatch, capsys, tmp_path, "houses", "export", dataset, "-o", tmp_path,
            words=(f"-o {tmp_path}", "holds this command's input"))


def test_houses_rearrange_never_replaces_its_input(tmp_path, monkeypatch, capsys):
    house = tmp_path / "my.json"
    house.write_bytes(HOUSE.read_bytes())
    for extra in ([], ["--force"]):
        refused(monkeypatch, capsys, tmp_path, "houses", "rearrange", house, "-o", house, *extra,
                words=(f"-o {house}", "is also this command's input"))
    mine(tmp_path / "other.json")
    refused(monkeypatch, capsys, tmp_path, "houses", "rearrange", house, "-o", tmp_path / "other.json",
            words=(f"-o {tmp_path / 'other.json'}", "--force"))
    ok("houses", "rearrange", house, "-o", tmp_path / "new.json", "--seed", "1")
    ok("houses", "rearrange", house, "-o", tmp_path / "new.json", "--seed", "2")  # its own file


@pytest.mark.parametrize("command", [
    ["render", HOUSE, "-o", "{out}"],
    ["rollout", HOUSE, "--max-steps", "3", "-o", "{out}"],
    ["rollout", HOUSE, "--max-steps", "3", "-o", "{new}", "--render", "{out}"],
    ["assets", "from-objathor", "{other}", "-o", "{out}"],
    ["trajectory", "from-ai2thor", "{other}", "--house", HOUSE, "-o", "{out}"],
    ["memory-check", "--houses", "preset:tiny", "-n", "1", "-o", "{folder}"],
    [*TINY_TRAIN, "--frames", "64", "-o", "{out}"],
    ["ppo", "--houses", "preset:tiny", "-o", "{out}"],
], ids=["render", "rollout", "rollout-render", "assets", "trajectory", "memory-check", "train", "ppo"])
def test_a_file_you_made_is_not_replaced(tmp_path, monkeypatch, capsys, command):
    out = mine(tmp_path / "mine.out")
    mine(tmp_path / "memory" / "memory_check.json")
    args = [str(a).format(out=out, other=tmp_path / "input.json", folder=tmp_path / "memory", new=tmp_path / "new.json")
            for a in command]
    mine(tmp_path / "input.json", "[]")
    flag = args[args.index(str(out)) - 1] if str(out) in args else "-o"
    refused(monkeypatch, capsys, tmp_path, *args, words=(flag, "not written by adaptenv", "--force"))


def test_render_replaces_its_own_image_and_never_a_house(tmp_path, monkeypatch, capsys):
    ok("render", HOUSE, "-o", tmp_path / "map.png", "--size", "256")
    ok("render", HOUSE, "-o", tmp_path / "map.png", "--size", "256")
    house = tmp_path / "h.json"
    house.write_bytes(HOUSE.read_bytes())
    refused(monkeypatch, capsys, tmp_path, "render", house, "-o", house, "--force",
            words=(f"-o {house}", "input"))
    refused(monkeypatch, capsys, tmp_path, "rollout", HOUSE, "-o", tmp_path / "t.json", "--render",
            tmp_path / "t.json", words=("--render", "input"))


# -- train --------------------------------------------------------------------------------------

def test_train_never_replaces_your_checkpoint_or_appends_to_your_metrics(tmp_path, monkeypatch, capsys):
    own = tmp_path / "own"
    ckpt, run = mine(own / "ckpt.pt", "my weights"), own / "rundir"
    mine(run / "metrics.csv", "step,loss\n1,0.5\n")
    refused(monkeypatch, capsys, tmp_path, *TINY_TRAIN, "--frames", "64", "-o", ckpt, "--run-dir", run,
            words=(f"--output {ckpt}", "--force"))
    refused(monkeypatch, capsys, tmp_path, *TINY_TRAIN, "--frames", "64", "-o", own / "new.pt", "--run-dir", run,
            words=(f"--run-dir {run}", "not written by adaptenv train", "--force"))


def test_train_card_never_replaces_a_house_or_the_checkpoint(tmp_path, monkeypatch, capsys):
    houses = tmp_path / "dir"
    (houses / "house_0000.json").parent.mkdir()
    (houses / "house_0000.json").write_bytes(HOUSE.read_bytes())
    card = houses / "house_0000.json"
    refused(monkeypatch, capsys, tmp_path, *TINY_TRAIN, "--frames", "64", "-o", houses / "house_0000.pt",
            "--run-dir", tmp_path / "run", words=(f"its card {card}", "not written by adaptenv train"))
    args = [a if a != "preset:tiny" else str(houses) for a in TINY_TRAIN]
    refused(monkeypatch, capsys, tmp_path, *args, "--frames", "64", "-o", houses / "p.pt", "--run-dir",
            tmp_path / "run", "--force", words=(f"--output {houses / 'p.pt'}", f"into {houses}"))
    refused(monkeypatch, capsys, tmp_path, *TINY_TRAIN, "--frames", "64", "-o", tmp_path / "pol.json",
            words=("--output", "pol.json", "overwrite the checkpoint", "pol.pt"))


def test_train_replaces_its_own_run_whole_and_resumes_its_own_run(tmp_path, monkeypatch):
    from adaptenv.agents.train import SequenceBuffer

    args = [*TINY_TRAIN, "--frames", "64", "-o", tmp_path / "p.pt", "--run-dir", tmp_path / "run"]
    ok(*args)
    rows = (tmp_path / "run" / "metrics.csv").read_text().splitlines()
    mine(tmp_path / "run" / "notes.txt")  # the user's, beside the run: kept
    ok(*args)  # its own run: replaced, not appended to
    assert len((tmp_path / "run" / "metrics.csv").read_text().splitlines()) == len(rows) >= 2
    assert (tmp_path / "run" / "notes.txt").read_text() == "the user's own file"

    def interrupt(self, block):
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(SequenceBuffer, "add", interrupt)
        assert CliRunner().invoke(app, [str(a) for a in args]).exit_code == 130
    ok(*args, "--resume")  # its own interrupted run, continued
    assert json.loads((tmp_path / "p.json").read_text())["frames"] == 64


# -- folders ------------------------------------------------------------------------------------

@pytest.mark.parametrize("command", [
    ["report", "{input}", "-o", "{out}"],
    ["experiment", "--config", CONFIG, "-o", "{out}"],
    ["evaluate", "--houses", "preset:tiny", "-n", "1", "-o", "{out}"],
    ["adapt", HOUSE, "--steps", "1", "-o", "{out}"],
    ["demo", "-o", "{out}"],
    [*LOOP, "-o", "{out}"],
    [*LOOP, "-o", "{out}", "--resume"],
], ids=["report", "experiment", "evaluate", "adapt", "demo", "loop", "loop-resume"])
def test_a_folder_you_made_is_not_written_into(tmp_path, monkeypatch, capsys, command):
    out = tmp_path / "mine"
    mine(out / "index.html", "<html>my page</html>")
    (tmp_path / "run").mkdir()
    args = [str(a).format(out=out, input=tmp_path / "run") for a in command]
    fix = "--force" if command[0] not in ("experiment", "demo", "loop") else "new or empty folder"
    refused(monkeypatch, capsys, tmp_path, *args, words=(f"-o {out}", "not written by adaptenv", fix))


def test_adapt_replaces_its_earlier_folder_whole(tmp_path, monkeypatch, capsys):
    out = tmp_path / "out"
    ok("adapt", HOUSE, "--policy", "expert", "--steps", "2", "--seed", "1", "-o", out)
    ok("houses", "generate", "--n", "1", "--rooms", "2", "--seed", "3", "-o", tmp_path / "other")
    start = time.time_ns()
    ok("adapt", tmp_path / "other" / "house_0000.json", "--policy", "expert", "--steps", "1", "-o", out)
    old = [p for p in out.rglob("*") if p.is_file() and p.name != MANIFEST and p.stat().st_mtime_ns < start]
    assert old == []  # nothing of the first house is left
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps_requested"] == 1
    (out / "summary.json").write_text("{}")  # the user edits the output: now theirs
    refused(monkeypatch, capsys, tmp_path, "adapt", HOUSE, "--steps", "1", "-o", out,
            words=(f"-o {out}", "summary.json", "--force"))
    refused(monkeypatch, capsys, tmp_path, "adapt", tmp_path / "other", "--steps", "1", "-o", tmp_path,
            words=(f"-o {tmp_path}", "holds this command's input"))


def test_report_and_experiment_keep_to_their_own_folders(tmp_path, monkeypatch, capsys):
    import adaptenv.curriculum.experiment as experiment

    def finished(cfg, out, **kwargs):  # an experiment that ran: what run_experiment leaves
        out.mkdir(parents=True, exist_ok=True)
        (out / "experiment.json").write_text("{}")
        (out / "summary.md").write_text("| method |\n")

    monkeypatch.setattr(experiment, "run_experiment", finished)
    ok("experiment", "--config", CONFIG, "-o", tmp_path / "exp")
    ok("experiment", "--config", CONFIG, "-o", tmp_path / "exp")  # its own: continued
    assert json.loads((tmp_path / "exp" / MANIFEST).read_text())["folder"] == "experiment"
    refused(monkeypatch, capsys, tmp_path, "report", tmp_path / "exp", "-o", tmp_path / "exp",
            words=(f"-o {tmp_path / 'exp'}", "input"))
    os.remove(tmp_path / "exp" / MANIFEST)  # without its manifest the folder is the user's, whatever it holds
    refused(monkeypatch, capsys, tmp_path, "experiment", "--config", CONFIG, "-o", tmp_path / "exp",
            words=(f"-o {tmp_path / 'exp'}", "not written by adaptenv experiment"))


def test_loop_resumes_its_own_folder(tmp_path, monkeypatch):
    import adaptenv.curriculum.loop as loop_module

    monkeypatch.setattr(loop_module, "run_loop", refuse_work)
    mine(tmp_path / "run" / "run.json", "{}")  # a run cut short, but no manifest: the folder is the user's
    res = CliRunner().invoke(app, [*LOOP, "-o", str(tmp_path / "run"), "--resume"])
    assert "not written by adaptenv loop" in str(res.exception), res.output
    mine(tmp_path / "run" / MANIFEST, json.dumps({"folder": "loop", "files": {}}))  # the loop's own
    res = CliRunner().invoke(app, [*LOOP, "-o", str(tmp_path / "run"), "--resume"])
    assert isinstance(res.exception, WorkStarted), res.output


def test_a_second_run_into_a_folder_another_run_writes_is_refused(tmp_path, monkeypatch, capsys):
    """Two runs at once: the second is refused, naming the first's process id; once the first ends, it runs."""
    import subprocess

    out = tmp_path / "houses"
    first = subprocess.Popen([sys.executable, "-c", "import sys\nfrom adaptenv.files import FolderLock\n"
                              "lock = FolderLock(sys.argv[1]).acquire('-o')\nprint('writing', flush=True)\n"
                              "sys.stdin.read()\nlock.release()\n", str(out)],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                             env={**os.environ, "PYTHONPATH": str(Path(__file__).parents[1] / "src")})
    try:
        assert first.stdout.readline().strip() == "writing"
        for command in (["houses", "generate", "--n", "1", "--rooms", "1", "-o", out],
                        ["evaluate", "--houses", "preset:tiny", "-n", "1", "--policy", "expert", "-o", out]):
            refused(monkeypatch, capsys, tmp_path, *command, words=(f"-o {out}", f"process id {first.pid}"))
    finally:
        first.communicate("")
    ok("houses", "generate", "--n", "1", "--rooms", "1", "-o", out)
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST, "house_0000.json"]  # the lock file is gone


def test_force_never_writes_through_a_link_nor_deletes_a_file_of_yours(tmp_path, monkeypatch, capsys):
    user = mine(tmp_path / "user.json", "the user's own file")
    out = tmp_path / "t.json"
    out.symlink_to(user)
    refused(monkeypatch, capsys, tmp_path, "rollout", HOUSE, "--policy", "expert", "-o", out, "--force",
            words=(f"-o {out}", "symbolic link"))
    out.unlink()
    ok("rollout", HOUSE, "--policy", "expert", "-o", out)
    ok("houses", "generate", "--n", "1", "--rooms", "1", "-o", tmp_path / "h")
    notes = mine(tmp_path / "h" / "sub" / "notes.txt")
    ok("houses", "generate", "--n", "1", "--rooms", "2", "-o", tmp_path / "h", "--force")
    assert notes.read_text() == "the user's own file"
