"""``adaptenv validate``: exit codes, file names and JSON paths in the output, never a traceback."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from typer.testing import CliRunner

from adaptenv.cli import app

runner = CliRunner()


@pytest.fixture
def broken(real_house_path, tmp_path):
    doc = json.loads(real_house_path.read_text())
    doc["doors"][2]["wall0"] = "wall|99|0.00|0.00|1.00|0.00"
    doc["objects"][5]["assetId"] = "Nope"
    p = tmp_path / "broken.json"
    p.write_text(json.dumps(doc))
    return p


def test_valid_house_exits_0(real_house_path):
    result = runner.invoke(app, ["validate", str(real_house_path)])
    assert result.exit_code == 0, result.output
    assert "1 file valid" in result.output


def test_broken_house_lists_every_problem(broken, real_house_path):
    result = runner.invoke(app, ["validate", str(real_house_path), str(broken)])
    assert result.exit_code == 1
    lines = result.output.strip().splitlines()
    assert lines[0] == f"{broken}: at doors[2].wall0, " + lines[0].split(", ", 1)[1]
    assert any(line.startswith(f"{broken}: at objects[5].assetId, ") for line in lines)
    assert lines[-1] == "2 problems in 1 of 2 files"
    assert "Traceback" not in result.output


@pytest.mark.parametrize("content", [None, "{oops", "", "[]", '{"walls": []}'])
def test_unreadable_files_are_problems_not_tracebacks(tmp_path, content):
    p = tmp_path / "house.json"
    if content is not None:
        p.write_text(content)
    result = runner.invoke(app, ["validate", str(p)])
    assert result.exit_code == 1
    assert result.exception is None or isinstance(result.exception, SystemExit)
    assert str(p) in result.output and "Traceback" not in result.output


def test_json_output(broken):
    result = runner.invoke(app, ["validate", "--json", str(broken)])
    assert result.exit_code == 1
    doc = json.loads(result.output)
    assert doc["valid"] is False
    assert [p["path"] for p in doc["problems"]] == ["doors[2].wall0", "objects[5].assetId"]
    assert all(p["file"] == str(broken) for p in doc["problems"])


def test_console_script_on_a_non_json_file(tmp_path):
    p = tmp_path / "notes.txt"
    p.write_text("not a house")
    proc = subprocess.run([sys.executable, "-c", "from adaptenv.cli import main; main()", "validate", str(p)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1
    assert f"{p}: at $, the file is not valid JSON" in proc.stdout
    assert "Traceback" not in proc.stdout + proc.stderr
