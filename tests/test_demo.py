"""The README's main job, `adaptenv demo`, runs the closed loop end to end and writes a report."""

from __future__ import annotations

import json

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
