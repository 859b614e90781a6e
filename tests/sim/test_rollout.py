"""Single-environment rollouts and the ``adaptenv rollout`` command."""

from __future__ import annotations

import json

import numpy as np
from typer.testing import CliRunner

from adaptenv.cli import app
from adaptenv.scene.house import save_house
from adaptenv.sim.rollout import expert_policy, random_policy, run_episode
from adaptenv.sim.spec import MAX_RANGE
from adaptenv.sim.task import sample_episode, visible_instances
from adaptenv.sim.trajectory import Trajectory
from adaptenv.sim.world import compile_world
from tests.sim import helpers as H


def test_run_episode_is_deterministic_under_a_seed(real_house):
    w = compile_world(real_house, "real")
    a = run_episode(w, sample_episode(w, 5), random_policy(5), max_steps=80)
    b = run_episode(w, sample_episode(w, 5), random_policy(5), max_steps=80)
    assert a.model_dump() == b.model_dump()
    assert len(a.steps) == 80 and not a.metrics.success  # random never ends: a timeout
    assert a.seed == 5


def test_recorded_steps_and_metrics():
    w = compile_world(H.corridor_house(), "corridor")
    t = run_episode(w, sample_episode(w, 0, use_house_start=True), expert_policy())
    assert t.metrics.success and t.policy == "expert"
    assert t.target_ids == ["GarbageCan|0"] and t.target_positions == [(7.5, 6.6)]
    assert t.final_pose == t.steps[-1].pose
    geo = [s.geodesic for s in t.steps]
    assert geo[0] == t.metrics.optimal_path_length and geo[-1] == 0.0
    assert all(s.clearance >= 0.2 for s in t.steps)
    for s in t.steps[::7]:
        assert s.visible == visible_instances(w, s.pose.x, s.pose.z, s.pose.yaw, "GarbageCan", max_distance=MAX_RANGE)
    assert t.metrics.first_sight_step == next(k for k, s in enumerate(t.steps) if s.visible)
    assert t.metrics.rooms_visited == 3
    quiet = run_episode(w, sample_episode(w, 0, use_house_start=True), expert_policy(), record=False)
    assert quiet.metrics == t.metrics and quiet.steps[0].geodesic is None


def test_cli_rollout_round_trips(tmp_path):
    house = save_house(H.corridor_house(), tmp_path / "house.json")
    out = tmp_path / "traj.json"
    res = CliRunner().invoke(app, ["rollout", str(house), "--policy", "expert", "--seed", "3", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "spl" in res.output
    t = Trajectory.load(out)
    assert t.metrics.success and t.target_type == "GarbageCan"
    assert Trajectory.model_validate(json.loads(out.read_text())) == t
    # the expert solved it: its episode length is a number of steps, with no "n/a" beside it
    [row] = [line for line in res.output.splitlines() if "expert_episode_length" in line]
    assert str(t.metrics.expert_episode_length) in row and "steps" in row
    assert "n/a" not in row and "fails" not in row


def test_cli_rollout_says_na_only_where_the_expert_fails(tmp_path, monkeypatch):
    monkeypatch.setattr("adaptenv.sim.rollout.expert_episode_length", lambda *a, **k: None)
    house = save_house(H.corridor_house(), tmp_path / "house.json")
    res = CliRunner().invoke(app, ["rollout", str(house), "--policy", "random", "--max-steps", "3",
                                   "-o", str(tmp_path / "t.json")])
    assert res.exit_code == 0, res.output
    [row] = [line for line in res.output.splitlines() if "expert_episode_length" in line]
    assert "n/a" in row and "the expert fails" in row


def test_cli_rollout_errors(tmp_path):
    house = save_house(H.corridor_house(), tmp_path / "house.json")
    runner = CliRunner()
    res = runner.invoke(app, ["rollout", str(house), "--target", "Bed", "-o", str(tmp_path / "t.json")])
    assert res.exit_code != 0 and "GarbageCan" in str(res.exception)
    res = runner.invoke(app, ["rollout", str(house), "--policy", "nope", "-o", str(tmp_path / "t.json")])
    assert res.exit_code != 0 and "expert" in str(res.exception)
    empty = save_house(H.one_room(), tmp_path / "empty.json")
    res = runner.invoke(app, ["rollout", str(empty), "-o", str(tmp_path / "t.json")])
    assert res.exit_code != 0 and "no ObjectNav target type is solvable" in str(res.exception)
    assert not (tmp_path / "t.json").exists()


def test_random_policy_never_ends_by_default():
    p = random_policy(np.random.default_rng(0))
    assert {p(None, None, 0, 0, 0, False, k) for k in range(500)} == set(range(6))
