"""tools/time_two_trees.py: alternating order, medians and paired ratios, and its errors (timing processes faked)."""

from __future__ import annotations

import json
import sys

import pytest

from tests.tools import load_tool

tool = load_tool("time_two_trees")


def _trees(tmp_path):
    for name in ("before", "after"):
        (tmp_path / name / "adaptenv").mkdir(parents=True)
    return str(tmp_path / "before"), str(tmp_path / "after")


def test_rounds_alternate_and_the_report_pairs_them(tmp_path, monkeypatch, capsys):
    before, after = _trees(tmp_path)
    calls = []
    fps = {before: iter([100.0, 110.0, 90.0]), after: iter([150.0, 160.0, 180.0])}

    def fake(src, code):
        calls.append(src)
        assert "ppo_fps" in code and "loop_fps" not in code  # only the figures asked for
        return {"figures": {"ppo_frames_per_s": next(fps[src])}, "digest": "same"}

    monkeypatch.setattr(tool, "run_child", fake)
    monkeypatch.setattr(sys, "argv", ["time_two_trees.py", before, after, "3", "--figures", "loop"])
    tool.main()
    report = json.loads(capsys.readouterr().out)
    assert calls == [before, after, after, before, before, after]
    assert report["before"]["ppo_frames_per_s"] == 100.0 and report["after"]["ppo_frames_per_s"] == 160.0
    assert report["after_over_before"]["ppo_frames_per_s"] == pytest.approx(150 / 100)  # median of 1.5, 1.45, 2
    assert report["same_results"] is True


def test_bad_figures_and_a_folder_without_the_package_are_named(tmp_path, monkeypatch, capsys):
    before, after = _trees(tmp_path)
    for argv, message in (([before, after, "--figures", "speed"], "--figures 'speed'"),
                          ([before, str(tmp_path)], "no adaptenv package here")):
        monkeypatch.setattr(sys, "argv", ["time_two_trees.py", *argv])
        with pytest.raises(SystemExit):
            tool.main()
        assert message in capsys.readouterr().err
