"""The experiment's verdict: the reference minus each method on held-out success, paired over episodes."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from adaptenv.curriculum.experiment import (
    ExperimentConfig,
    episode_effects,
    final_figures,
    initial_effects,
    run_dir,
    write_summary,
)
from adaptenv.curriculum.records import (
    HELDOUT_DIR,
    iteration_dir,
    read_iterations,
    write_iterations,
)
from adaptenv.curriculum.verdict import initial_lines, verdict_lines
from adaptenv.report import build_report
from tests.report.run_folders import SETS, write_fake_run

EPISODES = 40


def write_episodes(folder: Path, successes: dict[str, list[bool]], iteration: int = 1) -> None:
    """An iteration's held-out episodes.csv per set, in ``adaptenv evaluate``'s columns that matter here."""
    for name, wins in successes.items():
        path = iteration_dir(folder, iteration) / HELDOUT_DIR / name / "episodes.csv"
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=["index", "house", "success", "spl"])
            w.writeheader()
            w.writerows({"index": i, "house": f"h{i % 4}", "success": s, "spl": 0.5 * s} for i, s in enumerate(wins))


def one_seed_experiment(out: Path, ours: dict[str, list[bool]], dr: dict[str, list[bool]]) -> ExperimentConfig:
    """A one-seed experiment of ours and dr (one iteration each) with the given held-out outcomes."""
    cfg = ExperimentConfig(methods=["dr", "ours"], seeds=[0], loop={"iterations": 1})  # the runs are finished
    for method, wins in (("ours", ours), ("dr", dr)):
        folder = write_fake_run(run_dir(out, method, 0), None, method=method, iterations=1, scenes=0)
        write_episodes(folder, wins)
    return cfg


def test_effect_pairs_episodes_and_states_noise(tmp_path):
    ours = {s: [True] * EPISODES for s in SETS}
    dr = {s: [i != 3 for i in range(EPISODES)] for s in SETS}  # dr fails one episode of each set
    cfg = one_seed_experiment(tmp_path, ours, dr)
    e = episode_effects(tmp_path, cfg)["dr"]
    a = [float(x) for s in SETS for x in ours[s]]
    b = [float(x) for s in SETS for x in dr[s]]
    ci = stats.ttest_rel(a, b).confidence_interval(0.95)
    assert e["all"]["episodes"] == 2 * EPISODES
    assert e["all"]["diff"] == pytest.approx(np.mean(np.subtract(a, b)))
    assert (e["all"]["low"], e["all"]["high"]) == pytest.approx((ci.low, ci.high))
    assert e[f"success:{SETS[0]}"]["episodes"] == EPISODES
    [line] = verdict_lines({"reference": "ours", "episode_effects": {"dr": e}})
    assert line.startswith("Verdict: ours - dr held-out success = +2.5 points, 95% interval [")
    assert "within noise" in line and "80 held-out episodes" in line


def test_a_clear_difference_is_beyond_noise_and_opens_summary_and_report(tmp_path):
    ours = {s: [True] * EPISODES for s in SETS}
    dr = {s: [i % 2 == 0 for i in range(EPISODES)] for s in SETS}
    cfg = one_seed_experiment(tmp_path, ours, dr)
    summary = write_summary(tmp_path, cfg, final_figures(tmp_path, cfg), episode_effects=episode_effects(tmp_path, cfg))
    [line] = verdict_lines(summary)
    assert "+50.0 points" in line and "ours is better than dr beyond noise" in line
    assert (tmp_path / "summary.md").read_text().startswith(line + "\n")
    page = build_report(tmp_path).read_text()
    assert page.index('<p class="verdict">') < page.index('id="overview"')
    assert "ours is better than dr beyond noise" in page


def test_budget_line_states_each_methods_steps_and_whether_they_match():
    from adaptenv.curriculum.verdict import budget_line

    def summary(ours: float, dr: float) -> dict:
        return {"reference": "ours", "methods": {"ours": {"env_steps:all": {"mean": ours}},
                                                 "dr": {"env_steps:all": {"mean": dr}}}}

    line = budget_line(summary(135_988, 21_335))
    assert line.startswith("Environment steps: ours 135,988, dr 21,335; ours used 6.4x dr's")
    assert "unequal budgets" in line
    assert "matched budgets" in budget_line(summary(100_000, 98_000))
    assert budget_line({"reference": "ours", "methods": {"ours": {"env_steps:all": {"mean": 1.0}}}}) is None


def test_each_method_is_read_against_pi0_on_the_same_episodes(tmp_path):
    """A method that ends below pi_0 beyond noise says so in the summary and the report; one within noise says that."""
    pi0 = {s: [True] * EPISODES for s in SETS}
    ours = {s: [i != 5 for i in range(EPISODES)] for s in SETS}  # one failure more than pi_0 per set
    dr = {s: [i % 2 == 0 for i in range(EPISODES)] for s in SETS}  # half of pi_0's successes lost
    cfg = one_seed_experiment(tmp_path, ours, dr)
    for method in ("ours", "dr"):
        folder = run_dir(tmp_path, method, 0)
        records = read_iterations(folder)
        write_iterations(folder, [records[0].model_copy(update={"iteration": 0, "edits": 0}), *records])
        write_episodes(folder, pi0, iteration=0)
    effects = initial_effects(tmp_path, cfg)
    assert effects["dr"]["diff"] == pytest.approx(-0.5) and effects["dr"]["episodes"] == 2 * EPISODES
    summary = write_summary(tmp_path, cfg, final_figures(tmp_path, cfg), episode_effects=episode_effects(tmp_path, cfg),
                            initial_effects=effects)
    lines = initial_lines(summary)
    dr_line = next(line for line in lines if line.startswith("Against t=0: dr - pi_0"))
    assert "-50.0 points" in dr_line and "dr ended below pi_0 beyond noise" in dr_line
    ours_line = next(line for line in lines if line.startswith("Against t=0: ours - pi_0"))
    assert "-2.5 points" in ours_line and "within noise of pi_0" in ours_line
    assert dr_line in (tmp_path / "summary.md").read_text()
    assert "dr ended below pi_0 beyond noise" in build_report(tmp_path).read_text()


def test_runs_without_t0_episodes_have_no_line_against_pi0(tmp_path):
    """Runs with no t=0 episodes (written before t=0 kept them) give no figure, rather than a wrong one."""
    cfg = one_seed_experiment(tmp_path, {s: [True] * EPISODES for s in SETS}, {s: [True] * EPISODES for s in SETS})
    assert initial_effects(tmp_path, cfg) == {"dr": None, "ours": None}
    assert initial_lines({"initial_effects": initial_effects(tmp_path, cfg)}) == []
