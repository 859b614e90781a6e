"""``adaptenv train/evaluate`` end to end, and batched policies in the single-episode rollout."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from adaptenv.agents.evaluate import run_episodes, sample_episodes
from adaptenv.agents.network import NavNet, NetConfig, NeuralPolicy
from adaptenv.agents.policy import ExpertPolicy, as_step_policy
from adaptenv.cli import app
from adaptenv.errors import ConfigError
from adaptenv.sim.rollout import run_episode
from adaptenv.sim.spec import ACTIONS

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "my_policy.py"


def test_step_adapter_matches_the_batched_runner(tiny_set):
    """A batched policy gives the same actions in run_episode (one agent) as in BatchSim."""
    torch.manual_seed(1)
    net = NavNet(NetConfig(hidden=32, feature_dim=32, conv_channels=8))
    eps = sample_episodes(tiny_set.worlds, 3, seed=2)
    for make in (lambda: NeuralPolicy(net), ExpertPolicy):
        results, recs = run_episodes(tiny_set.worlds, eps, make(), batch=3, max_steps=60, record=lambda r: True)
        for (e, ep), res in zip(eps, results, strict=True):
            traj = run_episode(tiny_set.worlds[e], ep, as_step_policy(make()), max_steps=60, record=False)
            assert [s.action for s in traj.steps] == [ACTIONS[a] for a in recs[res.index].actions]
            assert traj.metrics.success == res.success


def test_cli_evaluate_writes_the_report(tmp_path):
    out = tmp_path / "eval"
    res = CliRunner().invoke(app, ["evaluate", "--policy", f"{EXAMPLE}:policy", "--houses", "preset:tiny",
                                   "--episodes", "4", "--seed", "1", "-o", str(out)])
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["episodes"] == 4 and "success_ci95" in summary and summary["command"].startswith("adaptenv evaluate")
    assert (out / "houses.csv").is_file() and (out / "episodes.csv").is_file()
    failed = sum(1 for line in (out / "episodes.csv").read_text().splitlines()[1:] if ",False," in line)
    assert sum(summary["failure_modes"].values()) == failed  # every failure classified by the built-in F


def test_cli_evaluate_names_how_a_random_walker_fails(tmp_path):
    res = CliRunner().invoke(app, ["evaluate", "--policy", "random", "--houses", "preset:tiny", "--episodes", "6",
                                   "-o", str(tmp_path)])
    assert res.exit_code == 0, res.output
    modes = json.loads((tmp_path / "summary.json").read_text())["failure_modes"]
    assert modes and set(modes) <= {"timeout", "ended_too_far", "ended_without_sight", "stuck", "looping",
                                    "never_saw_target"}
    assert "failures on preset:tiny (built-in analysis F)" in " ".join(res.output.split())


def test_cli_evaluate_compares_sets_and_rejects_unknown_policies(tmp_path):
    runner = CliRunner()
    res = runner.invoke(app, ["evaluate", "--policy", "expert", "--houses", "preset:tiny", "--houses", "preset:tiny",
                              "--episodes", "3", "-o", str(tmp_path)])
    assert res.exit_code == 0, res.output
    cmp = json.loads((tmp_path / "comparison.json").read_text())
    assert cmp["drops"]["preset:tiny"]["success"]["drop"] == 0.0
    res = runner.invoke(app, ["evaluate", "--policy", "nonsense", "--houses", "preset:tiny", "-o", str(tmp_path)])
    assert res.exit_code != 0 and isinstance(res.exception, ConfigError)
    assert "pretrained, pretrained-map, pretrained-scan, expert, explorer, map-explorer, random" in str(res.exception)


def test_cli_train_help_lists_every_config_field():
    res = CliRunner().invoke(app, ["train", "--help"], env={"COLUMNS": "200"})
    assert res.exit_code == 0
    for flag in ("--houses", "--frames", "--output", "--init", "--seed", "--resume", "--chunk-len", "--beta-end"):
        assert flag in res.output


def test_cli_train_starts_from_pretrained_and_says_when_no_final_evaluation_ran(tmp_path):
    from adaptenv.agents.checkpoint import load_checkpoint
    from adaptenv.agents.registry import pretrained_path

    out = tmp_path / "p.pt"
    res = CliRunner().invoke(app, [
        "train", "--init", "pretrained-scan", "--houses", "preset:tiny", "--frames", "64", "--num-envs", "4",
        "--rollout-steps", "16", "--chunk-len", "8", "--batch-chunks", "2", "--updates-per-iter", "1",
        "--buffer-frames", "64", "--calibrate-episodes", "0", "--eval-every", "0", "--final-eval-episodes", "0",
        "--hidden", "32", "--feature-dim", "32", "--no-tensorboard", "--no-progress", "--no-overlap",
        "-o", str(out), "--run-dir", str(tmp_path / "run")], env={"COLUMNS": "300"})
    assert res.exit_code == 0, res.output
    assert "no final evaluation was run" in res.output and "nan" not in res.output
    # warm-started: the network is the shipped one's shape, not the fresh --hidden 32 one
    assert load_checkpoint(out).net.config == load_checkpoint(pretrained_path("pretrained-scan")).net.config
    assert load_checkpoint(out).net.config.hidden != 32


def test_init_names_a_network_or_says_which_names_do():
    from adaptenv.agents.registry import init_checkpoint, pretrained_path

    assert init_checkpoint("pretrained") == pretrained_path()
    assert init_checkpoint("runs/a.pt") == Path("runs/a.pt")
    for spec in ("expert", "explorer", "random", "random:3", "examples/my_policy.py:policy"):
        with pytest.raises(ConfigError, match=f"--init '{spec}': no network to start from; use pretrained"):
            init_checkpoint(spec)


def test_cli_evaluate_breaks_success_down_by_the_number_of_rooms(tmp_path):
    from adaptenv.scene.house import save_house
    from adaptenv.scene.procedural import GenerationConfig, generate_house

    folder = tmp_path / "houses"
    for seed, rooms in ((1, 2), (2, 2), (3, 3)):
        save_house(generate_house(seed, GenerationConfig(n_rooms=rooms)), folder / f"h{seed}.json")
    out = tmp_path / "eval"
    res = CliRunner().invoke(app, ["evaluate", "--policy", "expert", "--houses", str(folder), "--episodes", "6",
                                   "-o", str(out)])
    assert res.exit_code == 0, res.output
    rows = json.loads((out / "summary.json").read_text())["by_rooms"]
    assert [(r["rooms"], r["houses"]) for r in rows] == [(2, 2), (3, 1)]
    assert sum(r["episodes"] for r in rows) == 6 and all(r["success"] == 1.0 for r in rows)  # the expert
    header, *lines = (out / "rooms.csv").read_text().splitlines()
    assert header.startswith("rooms,houses,episodes,success,") and len(lines) == 2
    printed = " ".join(res.output.split())
    assert (f"success by rooms: 2: 1.00 ({rows[0]['episodes']} ep), 3: 1.00 ({rows[1]['episodes']} ep)"
            in printed)
