"""What ``adaptenv evaluate`` prints: set names readable and distinct at 80 columns, and the houses a floor leaves out."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from adaptenv.cli import app
from adaptenv.cli.agents import set_labels
from tests.sim import helpers as H


def test_set_labels_keep_the_distinguishing_tail_or_number_the_sets():
    assert set_labels(["preset:tiny", "suite:long-unseen"], 20) == ["preset:tiny", "suite:long-unseen"]
    a, b = "runs/some/long/folder/houses.jsonl.gz:0:100", "runs/some/long/folder/houses.jsonl.gz:100:200"
    assert set_labels([a, b], 16) == ["...sonl.gz:0:100", "...nl.gz:100:200"]
    same_tail = ["a/x_" + "z" * 30, "b/x_" + "z" * 30]
    assert set_labels(same_tail, 12) == ["set 1", "set 2"]


def test_two_sets_from_one_folder_read_apart_at_80_columns(tmp_path):
    folder = tmp_path / "a_rather_long_folder_of_house_datasets" / "procthor_style"
    folder.mkdir(parents=True)
    data = folder / "houses.jsonl"
    data.write_text("".join(json.dumps(H.corridor_house().to_dict()) + "\n" for _ in range(2)), encoding="utf-8")
    specs = [f"{data}:0:1", f"{data}:1:2"]
    res = CliRunner().invoke(app, ["evaluate", "--policy", "expert", "--houses", specs[0], "--houses", specs[1],
                                   "--episodes", "2", "-o", str(tmp_path / "eval")], env={"COLUMNS": "80"})
    assert res.exit_code == 0, res.output
    table = [line for line in res.output.splitlines() if line[:1] in "┏┃┡│└"]
    assert table and all(len(line) <= 80 and line[-1] in "┓┃┩│┘" for line in table)  # whole, never cropped
    names = [name for line in table if line[0] == "│" and (name := line.split("│")[1].strip())]
    assert len(names) == 2
    assert len(set(names)) == 2 and names[0].endswith(":0:1") and names[1].endswith(":1:2")
    joined = " ".join(res.output.split())
    assert all(f"{n} = {s}" in joined for n, s in zip(names, specs, strict=True))  # the legend names the full spec


def test_the_floor_says_how_many_houses_it_left_out(tmp_path):
    res = CliRunner().invoke(app, ["evaluate", "--policy", "expert", "--houses", "preset:tiny", "--min-geodesic", "6",
                                   "--episodes", "3", "-o", str(tmp_path)])
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["floor_left_out"] == ["tiny_0001", "tiny_0002"]
    assert (summary["houses_used"], summary["houses_in_set"]) == (1, 3)
    assert ("floor geodesic >= 6 m on preset:tiny: left out 2 house(s) with no start that far from a target "
            "(tiny_0001, tiny_0002; see summary.json); the episodes used 1 of its 3 houses") in " ".join(res.output.split())
