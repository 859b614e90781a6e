"""tools/ppo_curve.py: the periodic evaluations of a PPO run's metrics.csv, and its final row apart."""

from __future__ import annotations

import csv

from tests.tools import load_tool


def test_curve_keeps_the_evaluations_and_sets_the_final_row_apart(tmp_path):
    keys = ["iteration", "frames", "charts/SPS", "eval/success", "eval/spl"]
    rows = [{"iteration": 0, "frames": 0, "eval/success": 0.8, "eval/spl": 0.4},
            {"iteration": 1, "frames": 100, "charts/SPS": 50},
            {"iteration": 2, "frames": 200, "charts/SPS": 50, "eval/success": 0.9, "eval/spl": 0.5},
            {"iteration": 2, "frames": 200, "eval/success": 0.95, "eval/spl": 0.45}]
    path = tmp_path / "metrics.csv"
    with path.open("w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    curve, final = load_tool("ppo_curve").curve_rows(path)
    assert [r["frames"] for r in curve] == ["0", "200"] and final["eval/success"] == "0.95"
