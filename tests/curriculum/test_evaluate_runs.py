"""tools/evaluate_runs.py: the validation table that chooses between loop variants."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from tests.tools import TOOLS, load_tool


def _tool():
    return load_tool("evaluate_runs")


def _write(folder: Path, seed: int, success: dict[str, float]) -> None:
    run = folder / f"seed_{seed}"
    run.mkdir(parents=True)
    doc = {"episodes": 100, "seed": seed, "iteration": 4, "final": {k: {"success": v} for k, v in success.items()}}
    (run / "val.json").write_text(json.dumps(doc))


def test_compare_pairs_by_seed_and_averages_the_suites(tmp_path, capsys):
    a, b = tmp_path / "a", tmp_path / "b"
    for seed, (x, y) in enumerate([(0.6, 0.5), (0.7, 0.5), (0.5, 0.45)]):
        _write(a, seed, {"long": x, "far": x - 0.2})
        _write(b, seed, {"long": y, "far": y - 0.1})
    _tool().compare("val", [0, 1, 2], a, b)
    out = capsys.readouterr().out
    # differences (0.10, 0.20, 0.05): mean 0.117, s.d. 0.076, t(2) 2.65; interval mean +- 4.303 * s.d. / sqrt(3)
    # Holm over the two suites: 2 x 0.118 = 0.236 for the smaller p, max(0.236, 0.742) for the larger
    assert "| long | 0.600 | 0.483 | +0.117 | [-0.073, +0.306] | 0.118 | 0.236 | +0.10, +0.20, +0.05 |" in out
    assert "| far | 0.400 | 0.383 | +0.017 | [-0.173, +0.206] | 0.742 | 0.742 | +0.00, +0.10, -0.05 |" in out
    assert "| mean of the suites | 0.500 | 0.433 | +0.067 | [-0.123, +0.256] | 0.270 | | |" in out


def test_compare_names_a_missing_seed(tmp_path):
    _write(tmp_path / "a", 0, {"long": 0.5})
    _write(tmp_path / "b", 1, {"long": 0.5})
    with pytest.raises(FileNotFoundError, match="seed_1"):
        _tool().compare("val", [0, 1], tmp_path / "a", tmp_path / "b")


def test_evaluate_reproduces_the_loops_own_evaluation_and_skips_finished_runs(tiny_policy, tmp_path, capsys):
    from adaptenv.curriculum.loop import LoopConfig, run_loop

    cfg = LoopConfig(method="none", policy=str(tiny_policy), houses="preset:tiny", heldout={"preset:tiny": "preset:tiny"},
                     iterations=1, scenes_per_iteration=2, finetune_frames=512, finetune_envs=16, heldout_episodes=4,
                     gallery=0, seed=3)
    last = run_loop(cfg, tmp_path / "run")[-1]
    tool = _tool()
    tool.evaluate("val", ["preset:tiny"], 4, [tmp_path / "run"])
    doc = json.loads((tmp_path / "run" / "val.json").read_text())
    assert (doc["seed"], doc["iteration"], doc["episodes"]) == (3, 1, 4)
    assert doc["final"]["preset:tiny"] == last.heldout["preset:tiny"].model_dump()
    capsys.readouterr()
    tool.evaluate("val", ["preset:tiny"], 4, [tmp_path / "run"])
    assert capsys.readouterr().out == "", "a run with the file is skipped"


def test_reference_plays_the_loops_final_episodes_and_pairs_with_compare(tiny_policy, tmp_path, capsys):
    from adaptenv.agents.checkpoint import load_checkpoint
    from adaptenv.curriculum.executor import InProcessExecutor
    from adaptenv.curriculum.jobs import PolicyWeights
    from adaptenv.curriculum.loop import evaluate_sets

    tool = _tool()
    tool.reference("ref", str(tiny_policy), ["preset:tiny"], 6, [3, 4], tmp_path / "ref")
    weights = PolicyWeights.of(load_checkpoint(tiny_policy).policy())
    for seed in (3, 4):
        doc = json.loads((tmp_path / "ref" / f"seed_{seed}" / "ref.json").read_text())
        loop = evaluate_sets(weights, {"preset:tiny": "preset:tiny"}, 6, seed, InProcessExecutor())
        assert doc["final"]["preset:tiny"] == loop["preset:tiny"].model_dump(), "the loop's episodes and figures"
    capsys.readouterr()
    tool.reference("ref", str(tiny_policy), ["preset:tiny"], 6, [3, 4], tmp_path / "ref")
    assert capsys.readouterr().out == "", "finished seeds are skipped"
    tool.compare("ref", [3, 4], tmp_path / "ref", tmp_path / "ref")
    assert "| preset:tiny |" in capsys.readouterr().out


def test_layouts_counts_a_child_as_its_parents_layout(tmp_path, capsys):
    run = tmp_path / "ours" / "seed_0"
    for t, names in ((0, []), (1, ["dr0001", "pretrain-train_0003"]), (2, ["dr0001~t02f00", "dr0002", "dr0001"])):
        (run / f"iter_{t:04d}").mkdir(parents=True)
        (run / f"iter_{t:04d}" / "scenes.json").write_text(json.dumps({"trained_on": names}))
    _tool().layouts([0], [tmp_path / "ours"])
    assert "| ours | 0 | 3 | 3 | 1 | 1 |" in capsys.readouterr().out


def _fake_run(run: Path, heldout: str, final: dict | None = None, name: str = "final_eval",
              initial: float | None = None) -> None:
    """A finished 2-iteration run folder evaluating ``heldout`` during the run, and its final evaluation file."""
    from adaptenv.curriculum.records import IterationRecord, SetMetrics, write_iterations

    run.mkdir(parents=True)
    figs = SetMetrics(success=0.5, spl=0.3, collisions=1.0, episodes=4)
    write_iterations(run, [IterationRecord(iteration=t, env_steps=100 * t, grad_updates=t, edits=0,
                                           heldout={heldout: figs}) for t in range(2)])
    doc = {"episodes": 300, "iteration": 1, "final": {k: figs.model_copy(update={"success": v}).model_dump()
                                                      for k, v in (final or {}).items()}}
    if initial is not None:
        doc["initial"] = {k: figs.model_copy(update={"success": initial}).model_dump() for k in final}
    (run / f"{name}.json").write_text(json.dumps(doc))


def test_assemble_gathers_methods_from_two_experiments_and_tests_them(tmp_path, capsys):
    # ours-dr was evaluated by this tool (heldout.json, no pi_0 figures); dr by its experiment (final_eval.json).
    ours_dr, dr = [0.70, 0.75, 0.65], [0.60, 0.62, 0.61]
    for seed in range(3):
        _fake_run(tmp_path / "a" / "ours-dr" / f"seed_{seed}", "val", {"long": ours_dr[seed]}, name="heldout")
        _fake_run(tmp_path / "b" / "dr" / f"seed_{seed}", "long", {"long": dr[seed]}, initial=0.55)
    config = tmp_path / "combined.json"
    config.write_text(json.dumps({"methods": ["ours-dr", "dr"], "seeds": [0, 1, 2], "reference": "ours-dr",
                                  "loop": {"heldout": {"long": "suite:long-unseen"}}}))
    out = tmp_path / "combined"
    _tool().assemble(config, out, [f"ours-dr={tmp_path / 'a' / 'ours-dr'}:heldout", f"dr={tmp_path / 'b' / 'dr'}"])
    summary = json.loads((out / "summary_final.json").read_text())
    # ours-dr - dr per seed +0.10, +0.13, +0.04: mean 0.09, t(2) = 3.40, p = 0.077 (the in-loop sets differ: val, long)
    assert summary["effects"]["dr"]["success:long"]["diff"] == pytest.approx(0.09)
    assert summary["tests"]["dr"]["success:long"] == pytest.approx(0.0766, abs=1e-4)
    assert summary["methods"]["ours-dr"]["success_gain:long"]["mean"] == pytest.approx(0.70 - 0.55)
    assert summary["episodes"] == 300
    assert (out / "ours-dr" / "seed_0" / "iterations.jsonl").is_symlink()
    assert "| dr | long | +0.090 |" in capsys.readouterr().out
    with pytest.raises(SystemExit, match="lists methods"):
        _tool().assemble(config, tmp_path / "x", [f"ours-dr={tmp_path / 'a' / 'ours-dr'}:heldout"])
    with pytest.raises(SystemExit, match="no run of seed 0 has pi_0's figures"):
        config.write_text(json.dumps({"methods": ["ours-dr"], "seeds": [0], "reference": "ours-dr", "loop": {}}))
        _tool().assemble(config, tmp_path / "y", [f"ours-dr={tmp_path / 'a' / 'ours-dr'}:heldout"])


def test_table_of_a_single_seed_says_the_effects_need_two(tmp_path, capsys):
    source = TOOLS.parent / "docs" / "results" / "efficacy-item4"
    summary = json.loads((source / "summary_final.json").read_text())
    summary["seeds"] = [0]
    for name in ("effects", "tests", "holm"):  # as summarize writes them for one seed: no paired effect
        summary[name] = {m: dict.fromkeys(v) for m, v in summary[name].items()}
    (tmp_path / "summary_final.json").write_text(json.dumps(summary))
    shutil.copy(source / "experiment.json", tmp_path)
    shutil.copytree(source / "initial_eval", tmp_path / "initial_eval")
    _tool().table(tmp_path)
    out = capsys.readouterr().out
    assert out.startswith("seeds [0], 1000 episodes per suite")
    assert "| `dr` | clutter | n/a (one seed) | n/a | n/a | n/a |" in out


def test_table_of_a_single_method_says_there_is_no_comparison(capsys):
    _tool().table(TOOLS.parent / "docs" / "results" / "lever-episodes" / "near")
    out = capsys.readouterr().out
    assert "| `none` | 80.4 ± 0.2 | 88.7 ± 0.8 | 90.6 ± 0.6 | +3.4, +1.3, +1.4 |" in out
    assert out.rstrip().endswith("no comparison (pair it with another experiment's runs by `compare`)")


def test_table_prints_a_committed_experiment_in_points(capsys):
    """The item-4 experiment's figures as docs/results/ARCHIVE.md quotes them, from its committed summary_final.json."""
    _tool().table(TOOLS.parent / "docs" / "results" / "efficacy-item4")
    out = capsys.readouterr().out
    assert out.startswith("seeds [0, 1, 2, 3, 4, 5, 6, 7, 8, 9], 1000 episodes per suite; pi_0: long-unseen 70.8, "
                          "far 45.1, clutter 64.3")
    assert "| `dr` | 70.5 ± 1.1 | 49.1 ± 0.9 | 63.9 ± 1.2 | -0.3, +4.0, -0.4 | 536,695 | 1,024 | 0 |" in out
    assert "| `dr` | clutter | +4.2 | [+1.1, +7.3] | 0.014 | 0.19 |" in out
    assert out.count("| `ours-dr` |") == 1 and "Holm over all 27 comparisons" in out
