"""The README's main job, `adaptenv demo`, runs the closed loop end to end and writes a report."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from adaptenv.cli import app


@pytest.mark.slow
def test_demo_runs_the_closed_loop_and_writes_the_report(tmp_path):
    out = tmp_path / "demo"
    result = CliRunner().invoke(app, ["demo", "-o", str(out), "--houses", "2", "--iterations", "1"])
    assert result.exit_code == 0, result.output
    index = out / "run" / "report" / "index.html"
    assert index.is_file() and str(index) in result.output.replace("\n", "")
    records = [json.loads(line) for line in (out / "run" / "iterations.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in records] == [0, 1]
    assert records[1]["edits"] > 0 and records[1]["grad_updates"] > 0
    assert set(records[1]["heldout"]) == {"rearranged", "unseen"}
    gallery = records[1]["gallery"][0]
    assert (out / "run" / gallery["after_png"]).is_file()


DEV_EXTRAS = ("ray", "tensorboard", "minigrid", "pytest", "hypothesis", "ruff", "xdist")

DEMO_AND_LIST_IMPORTS = """
import json, sys

from adaptenv.cli import main

sys.argv = ["adaptenv", "demo", "-o", {out!r}, "--houses", "1", "--iterations", "1"]
try:
    main()
except SystemExit as exc:
    assert not exc.code, exc.code
print(json.dumps(sorted({{m.split(".")[0] for m in sys.modules}} & {extras!r})))
"""


@pytest.mark.slow
def test_demo_imports_none_of_the_dev_extras(tmp_path):
    """What `make demo` installs is enough: the whole demo never imports a dev extra."""
    src = Path(__file__).resolve().parents[1] / "src"
    code = DEMO_AND_LIST_IMPORTS.format(extras=set(DEV_EXTRAS), out=str(tmp_path / "demo"))
    env = dict(os.environ, PYTHONPATH=str(src))
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert (tmp_path / "demo" / "run" / "report" / "index.html").is_file()
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == []
