"""The experiment runner: methods x seeds, per-seed CSVs, summary with paired tests, plots, resume."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from adaptenv.curriculum.experiment import (
    ExperimentConfig,
    LeverRule,
    final_evaluation,
    holm,
    pack_experiment,
    paired_effect,
    paired_test,
    run_experiment,
    summary_markdown,
)
from adaptenv.curriculum.records import read_iterations
from adaptenv.errors import ConfigError

REPO = Path(__file__).resolve().parents[2]


def test_committed_configs_load():
    for path in sorted((REPO / "configs").glob("experiment-*.json")):
        cfg = ExperimentConfig.load(path)
        assert cfg.reference in cfg.methods
        cfg.loop_config(cfg.methods[0], cfg.seeds[0]).check()


def test_config_errors_name_file_and_field(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"methods": ["ours", "magic"]}))
    with pytest.raises(ConfigError, match=r"bad.json: methods\[1\] 'magic' is unknown"):
        ExperimentConfig.load(bad)
    bad.write_text(json.dumps({"loop": {"itterations": 3}}))
    with pytest.raises(ConfigError, match="itterations"):
        ExperimentConfig.load(bad)


def test_paired_test_is_a_real_test():
    assert paired_test([0.5, 0.6, 0.7], [0.5, 0.6, 0.7]) is None
    p = paired_test([0.9, 0.8, 0.85, 0.95], [0.1, 0.2, 0.15, 0.05])
    assert p is not None and p < 0.01
    assert paired_test([0.5, 0.55, 0.45], [0.52, 0.5, 0.5]) > 0.3


def test_paired_effect_interval_matches_scipy():
    a, b = [0.62, 0.70, 0.58, 0.66, 0.71], [0.55, 0.61, 0.60, 0.57, 0.63]
    e = paired_effect(a, b)
    ci = stats.ttest_rel(a, b).confidence_interval(0.95)
    assert e["diff"] == pytest.approx(np.mean(np.subtract(a, b)))
    assert (e["low"], e["high"]) == pytest.approx((ci.low, ci.high))
    assert paired_effect([0.5], [0.4]) is None


def test_holm_adjusts_step_down_and_keeps_order():
    adjusted = holm({"a": 0.01, "b": 0.04, "c": 0.03, "d": None})
    # sorted 0.01, 0.03, 0.04 times 3, 2, 1, made monotone: 0.03, 0.06, max(0.04, 0.06)
    assert adjusted == pytest.approx({"a": 0.03, "c": 0.06, "b": 0.06, "d": None})
    assert holm({"x": 0.6, "y": 0.5}) == {"x": 1.0, "y": 1.0}


@pytest.mark.slow
def test_primary_compares_with_the_better_baseline_per_set_and_holm_over_sets_only():
    from adaptenv.curriculum.experiment import primary_comparison, primary_markdown

    seeds = range(5)
    table = {
        "ours": {s: {"success:far": 0.60 + 0.01 * s, "success:clutter": 0.80 + 0.02 * (s % 2)} for s in seeds},
        "dr": {s: {"success:far": 0.50 + 0.01 * s + 0.002 * (s % 3), "success:clutter": 0.70} for s in seeds},
        "sfl": {s: {"success:far": 0.55 + 0.01 * s - 0.003 * (s % 2), "success:clutter": 0.60} for s in seeds},
        "none": {s: {"success:far": 0.90, "success:clutter": 0.90} for s in seeds},  # not a declared baseline
    }
    out = primary_comparison(table, "ours", ["dr", "sfl"])
    far, clutter = out["sets"]["success:far"], out["sets"]["success:clutter"]
    assert far["baseline"] == "sfl" and clutter["baseline"] == "dr", "the better baseline on each set"
    assert far["effect"]["diff"] == pytest.approx(0.05 + 0.003 * 0.4, abs=1e-9)
    assert far["seeds"] == clutter["seeds"] == 5
    (lo, lo_adj), (hi, hi_adj) = sorted((r["p"], r["p_holm"]) for r in (far, clutter))
    assert lo_adj == pytest.approx(min(1.0, 2 * lo)) and hi_adj == pytest.approx(max(lo_adj, hi)), "Holm over 2 sets"
    md = "\n".join(primary_markdown(out))
    assert "| far | sfl | +5.1 |" in md and "| clutter | dr | +10.8 |" in md
    with pytest.raises(ConfigError, match="primary"):
        ExperimentConfig(methods=["ours", "dr"], primary=["dr", "sfl"]).check()
    with pytest.raises(ConfigError, match="primary"):
        ExperimentConfig(methods=["ours", "dr"], primary=["ours"]).check()


def test_lever_rule_reads_the_declared_set_and_threshold_in_one_line(tmp_path):
    from adaptenv.curriculum.experiment import lever_reading
    from adaptenv.curriculum.verdict import lever_lines

    rule = LeverRule(arm="rearrange", control="none", heldout="rearranged", threshold=5.0)
    gains = [0.06, 0.05, 0.07, 0.04, 0.065]
    table = {"rearrange": {s: {"success:rearranged": 0.80 + g, "success:far": 0.5} for s, g in enumerate(gains)},
             "none": {s: {"success:rearranged": 0.80, "success:far": 0.9} for s in range(5)}}
    reading = lever_reading(table, rule)
    assert reading["seeds"] == 5 and reading["effect"]["diff"] == pytest.approx(np.mean(gains))
    assert reading["exists"] is True, "a 5.7-point mean gain on the declared set meets a 5-point threshold"
    (line,) = lever_lines({"lever": reading})
    assert line.startswith("Lever: rearrange - none held-out success on rearranged = +5.7 points, 95% interval [")
    assert line.endswith("over 5 paired seeds; threshold +5.0: a lever exists.")
    higher = lever_reading(table, LeverRule(arm="rearrange", heldout="rearranged", threshold=6.0))
    assert higher["exists"] is False and lever_lines({"lever": higher})[0].endswith("no lever.")
    one_seed = lever_reading({m: {0: seeds[0]} for m, seeds in table.items()}, rule)
    assert one_seed["exists"] is None and "undecided" in lever_lines({"lever": one_seed})[0]
    assert lever_lines({}) == [], "no rule declared: no line"
    bad = tmp_path / "lever.json"
    for lever, field in (({"arm": "oracle", "heldout": "far"}, "lever.arm"),
                         ({"arm": "dr", "heldout": "kitchen"}, "lever.heldout")):
        bad.write_text(json.dumps({"methods": ["none", "dr"], "reference": "dr", "lever": lever,
                                   "loop": {"heldout": {"far": "suite:far"}}}))
        with pytest.raises(ConfigError, match=f"lever.json: {field}"):
            ExperimentConfig.load(bad)


def test_small_experiment_writes_every_artifact(tiny_policy, tmp_path, capsys):
    cfg = ExperimentConfig.load(REPO / "configs" / "experiment-small.json")
    cfg.methods = ["none", "dr", "ours"]
    cfg.primary = ["none", "dr"]
    cfg.loop["policy"] = str(tiny_policy)
    summary = run_experiment(cfg, tmp_path)
    log = capsys.readouterr().err  # stderr is not a terminal here: a timestamped line per stage and per run
    for m in cfg.methods:
        for s in cfg.seeds:
            assert f" {m} seed {s}: run finished ({cfg.loop['iterations']} iterations)" in log
    assert " ours seed 1: t=1: fine-tuning on " in log
    for m in cfg.methods:
        rows = (tmp_path / m / "per_seed.csv").read_text().splitlines()
        assert rows[0] == "metric:set,seed_0,seed_1"
        assert any(r.startswith("success:tiny,") for r in rows)
    assert set(summary["methods"]) == set(cfg.methods)
    assert set(summary["tests"]) == {"none", "dr"}
    # the paper's Delta R: final held-out success minus pi_0's on the same episodes, per seed
    for m in cfg.methods:
        for s in cfg.seeds:
            recs = read_iterations(tmp_path / m / f"seed_{s}")
            gain = recs[-1].heldout["tiny"].success - recs[0].heldout["tiny"].success
            row = next(r for r in (tmp_path / m / "per_seed.csv").read_text().splitlines()
                       if r.startswith("success_gain:tiny,"))
            assert float(row.split(",")[1 + cfg.seeds.index(s)]) == pytest.approx(gain, abs=1e-5)
    assert "success_gain:tiny" in summary["tests"]["none"]
    md = (tmp_path / "summary.md").read_text()
    assert "| ours |" in md and "paired t-test" in md
    assert summary["primary"]["sets"]["success:tiny"]["baseline"] in ("none", "dr")
    assert "Declared primary: ours minus the better of none and dr" in md
    assert set(summary["effects"]) == {"none", "dr"} and "p (Holm)" in md
    holm_p = summary["holm"]["none"]["success:tiny"]
    assert holm_p is None or holm_p >= summary["tests"]["none"]["success:tiny"]
    for x in ("iteration", "env_steps"):
        assert (tmp_path / "plots" / f"heldout_tiny_vs_{x}.png").stat().st_size > 1000
    # a second call resumes finished runs instead of recomputing them
    before = (tmp_path / "ours" / "seed_0" / "iterations.jsonl").read_text()
    again = run_experiment(cfg, tmp_path)
    assert (tmp_path / "ours" / "seed_0" / "iterations.jsonl").read_text() == before
    assert again["methods"] == summary["methods"]
    assert summary_markdown(again) == md

    # a final evaluation on more episodes: same tables, cached per run
    final = final_evaluation(tmp_path, cfg, 8)
    assert set(final["methods"]) == set(cfg.methods) and "success_gain:tiny" in final["tests"]["none"]
    doc = json.loads((tmp_path / "ours" / "seed_0" / "final_eval.json").read_text())
    assert doc["episodes"] == 8 and doc["final"]["tiny"]["episodes"] == 8
    assert doc["initial"] == json.loads((tmp_path / "none" / "seed_0" / "final_eval.json").read_text())["initial"]
    assert (tmp_path / "summary_final.md").is_file() and (tmp_path / "ours" / "per_seed_final.csv").is_file()
    assert final["methods"]["ours"]["grad_updates:all"] == summary["methods"]["ours"]["grad_updates:all"]
    assert "nan" not in (tmp_path / "summary_final.md").read_text()
    stamp = (tmp_path / "ours" / "seed_0" / "final_eval.json").stat().st_mtime_ns
    assert final_evaluation(tmp_path, cfg, 8) == final
    assert (tmp_path / "ours" / "seed_0" / "final_eval.json").stat().st_mtime_ns == stamp


def test_runs_finishing_together_evaluate_pi_0_once(tmp_path, monkeypatch):
    """Two runs of a seed asking for pi_0's figures at once: one evaluates, the other waits and reads the cache."""
    import threading

    from adaptenv.curriculum import experiment

    calls = []

    def slow_evaluation(path, specs, episodes, seed, ex):
        calls.append(path)
        time.sleep(0.3)
        return {"long": {"success": 0.5 + len(calls)}}

    monkeypatch.setattr(experiment, "_evaluate_policy", slow_evaluation)
    got = []
    args = ({"long": "suite:long"}, 4, 0, None)
    threads = [threading.Thread(target=lambda m=m: got.append(experiment._initial_figures(tmp_path, tmp_path / m, *args)))
               for m in ("ours", "ours-dr")]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(calls) == 1 and got[0] == got[1] and got[0]["figures"] == {"long": {"success": 1.5}}
    assert experiment._initial_figures(tmp_path, tmp_path / "dr", {"long": "suite:long"}, 8, 0, None)["episodes"] == 8
    assert len(calls) == 2, "a different episode count is evaluated anew"


@pytest.mark.slow
def test_runs_are_finally_evaluated_as_they_finish_and_a_packed_copy_resumes(tiny_policy, tmp_path, capsys):
    cfg = ExperimentConfig.load(REPO / "configs" / "experiment-small.json")
    cfg.methods, cfg.reference = ["none", "dr"], "dr"
    cfg.loop["policy"] = str(tiny_policy)
    out = tmp_path / "exp"
    run_experiment(cfg, out, final_episodes=6, command=f"adaptenv experiment -o {out.resolve()}")
    log = capsys.readouterr().err  # a background experiment's log says when each run's evaluation is written
    assert log.count("final evaluation written: ") == len(cfg.methods) * len(cfg.seeds)
    for m in cfg.methods:
        for s in cfg.seeds:
            doc = json.loads((out / m / f"seed_{s}" / "final_eval.json").read_text())
            assert doc["episodes"] == 6 and doc["iteration"] == cfg.loop["iterations"]
    for s in cfg.seeds:  # pi_0 is evaluated once per seed and shared by that seed's runs
        cached = json.loads((out / "initial_eval" / f"seed_{s}.json").read_text())
        assert cached["figures"] == json.loads((out / "dr" / f"seed_{s}" / "final_eval.json").read_text())["initial"]
    final = final_evaluation(out, cfg, 6)
    _check_timing(out, cfg, log, tmp_path, capsys)

    packed = pack_experiment(out, tmp_path / "packed")
    assert len(packed) == len(cfg.methods) * len(cfg.seeds)
    assert not list((tmp_path / "packed").rglob("*.pt")) and not list((tmp_path / "packed").rglob("scenes"))
    here = str(out.resolve())  # the runs' records name their folder; the packed copy does not
    assert here in (out / "dr" / f"seed_{cfg.seeds[0]}" / "run.json").read_text()
    assert not [f for f in (tmp_path / "packed").rglob("*") if f.is_file() and here in f.read_text()]
    # the packed copy has no policy, so resuming works only if every finished run is skipped
    capsys.readouterr()
    run_experiment(cfg, tmp_path / "packed", final_episodes=6)
    assert "final evaluation" not in capsys.readouterr().err
    assert final_evaluation(tmp_path / "packed", cfg, 6)["methods"] == final["methods"]


def _check_timing(out: Path, cfg: ExperimentConfig, log: str, tmp_path: Path, capsys) -> None:
    """tools/evaluate_runs.py time: each run's final evaluation took measurable time, and the table adds the stages
    of every run and the evaluation's seconds, read from final_eval.json or, for older runs, from the log."""
    from tests.tools import load_tool

    tool = load_tool("evaluate_runs")
    docs = {(m, s): json.loads((out / m / f"seed_{s}" / "final_eval.json").read_text()) for m in cfg.methods
            for s in cfg.seeds}
    assert all(d["seconds"] > 0 for d in docs.values())
    from_log = tool.final_eval_seconds([_write_text(tmp_path / "err.txt", log)])
    assert set(from_log) == set(docs)  # every run's start and end lines paired
    loop_seconds = sum(r.stage_seconds.get(st, 0.0) for m in cfg.methods for s in cfg.seeds
                       for r in read_iterations(out / m / f"seed_{s}") for st in tool.STAGES)
    capsys.readouterr()
    tool.timing(out, [])
    total = sum(d["seconds"] for d in docs.values()) + loop_seconds
    assert capsys.readouterr().out.splitlines()[-1].endswith(f"| {total:,.0f} |")
    for (m, s), d in docs.items():  # an older run without seconds: the log gives them, or a clear error
        del d["seconds"]
        (out / m / f"seed_{s}" / "final_eval.json").write_text(json.dumps(d))
    with pytest.raises(SystemExit, match="--log"):
        tool.timing(out, [])
    tool.timing(out, [tmp_path / "err.txt"])
    total = sum(from_log.values()) + loop_seconds
    assert capsys.readouterr().out.splitlines()[-1].endswith(f"| {total:,.0f} |")


def _write_text(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.slow
def test_a_failed_run_does_not_stop_the_others_and_is_named_at_the_end(tiny_policy, tmp_path, monkeypatch, capsys):
    from adaptenv.curriculum import experiment
    from adaptenv.errors import RunsFailed

    real = experiment.run_loop

    def failing_for_dr(cfg, folder, **kw):
        if cfg.method == "dr" and cfg.seed == 0:
            raise ConfigError("match_run OUT/ours/seed_0: no such run folder")
        return real(cfg, folder, **kw)

    monkeypatch.setattr(experiment, "run_loop", failing_for_dr)
    cfg = ExperimentConfig.load(REPO / "configs" / "experiment-small.json")
    cfg.methods, cfg.reference, cfg.primary = ["none", "dr"], "dr", []
    cfg.loop["policy"] = str(tiny_policy)
    with pytest.raises(RunsFailed, match=r"^1 of 4 runs failed \(dr seed 0: match_run OUT/ours/seed_0: no such"):
        run_experiment(cfg, tmp_path)
    assert "run failed: dr seed 0: match_run" in capsys.readouterr().err
    # the runs after the failed one ran to the end, and the summary holds them
    for m, s in (("none", 0), ("none", 1), ("dr", 1)):
        assert read_iterations(tmp_path / m / f"seed_{s}")[-1].iteration == cfg.loop["iterations"]
    assert (tmp_path / "summary.md").is_file()
    monkeypatch.setattr(experiment, "run_loop", real)  # running again retries the failed run alone
    run_experiment(cfg, tmp_path)
    assert read_iterations(tmp_path / "dr" / "seed_0")[-1].iteration == cfg.loop["iterations"]
