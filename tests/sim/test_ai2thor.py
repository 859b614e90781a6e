"""An episode logged in AI2-THOR (agent metadata per event) becomes an adaptenv trajectory that
analyze, render and adapt take (adaptenv trajectory from-ai2thor, adapt --trajectory)."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from adaptenv.cli import app
from adaptenv.errors import AdaptenvError, ConfigError
from adaptenv.scene.house import load_house, save_house
from adaptenv.sim.ai2thor import action_code, convert_ai2thor_log, trajectory_from_ai2thor
from adaptenv.sim.rollout import expert_policy, run_episode
from adaptenv.sim.task import Episode
from adaptenv.sim.trajectory import Pose, Trajectory
from adaptenv.sim.world import compile_world
from tests.conftest import REAL_HOUSE
from tests.sim import helpers as H

THOR_NAMES = {"m": "MoveAhead", "b": "MoveBack", "l": "RotateLeft", "r": "RotateRight", "end": "Done"}
SOFA = "RoboTHOR_sofa_alrid"
EPISODE = Episode("Sofa", (11.175, 1.925, 60.0), seed=3)


def agent(p: Pose, yaw_offset: float = 0.0) -> dict:
    """``controller.last_event.metadata["agent"]`` at a pose (AI2-THOR's keys; y is the body's height)."""
    return {"name": "agent", "position": {"x": p.x, "y": 0.9009, "z": p.z},
            "rotation": {"x": 0.0, "y": p.yaw + yaw_offset, "z": 0.0}, "cameraHorizon": 30.0, "isStanding": True}


def ai2thor_records(traj: Trajectory, *, blocked_first: bool = False, yaw_offset: float = 0.0) -> list[dict]:
    """The events an AI2-THOR loop logs for ``traj``'s episode: the start, then one per action, in AI2-THOR's
    and SPOC's action names, with a LookDown (no floor motion) and optionally a blocked MoveAhead."""
    poses = traj.poses
    out = [{"action": "TeleportFull", "agent": agent(traj.start, yaw_offset), "lastActionSuccess": True}]
    if blocked_first:
        out.append({"action": "MoveAhead", "agent": agent(traj.start, yaw_offset), "lastActionSuccess": False})
    for k, s in enumerate(traj.steps):
        after = poses[min(k + 1, len(poses) - 1)]
        action = THOR_NAMES.get(s.action) or {"action": "RotateAgent", "degrees": -6 if s.action == "ls" else 6}
        out.append({"action": action, "agent": agent(after, yaw_offset), "lastActionSuccess": s.moved})
        if k == 1:
            out.append({"action": "LookDown", "agent": agent(after, yaw_offset), "lastActionSuccess": True})
    return out


@pytest.fixture(scope="module")
def real_world():
    return compile_world(load_house(REAL_HOUSE, validate=False), REAL_HOUSE.stem)


@pytest.fixture(scope="module")
def expert_run(real_world):
    return run_episode(real_world, EPISODE, expert_policy())


def write_log(path, records: list[dict], header: dict | None = None):
    lines = ([header] if header else []) + records
    path.write_text("\n".join(json.dumps(r) for r in lines) + "\n", encoding="utf-8")
    return path


def test_converted_log_reproduces_the_episode(real_world, expert_run, tmp_path):
    log = write_log(tmp_path / "ep.jsonl", ai2thor_records(expert_run, blocked_first=True),
                    {"house": "train_1", "target_type": "sofa.n.01", "policy": "my-agent", "seed": 3})
    conv = convert_ai2thor_log(log, real_world)
    traj, m, ref = conv.trajectory, conv.trajectory.metrics, expert_run.metrics
    assert conv.dropped == {"LookDown": 1}
    assert traj.target_type == "Sofa" and traj.policy == "my-agent" and traj.house == "train_1"
    assert [s.action for s in traj.steps[1:]] == [s.action for s in expert_run.steps]
    assert traj.steps[0].action == "m" and not traj.steps[0].moved and m.collisions == ref.collisions + 1
    assert m.success == ref.success and m.spl == pytest.approx(ref.spl) and m.path_length == pytest.approx(ref.path_length)
    assert m.episode_length == ref.episode_length + 1 and m.first_sight_step == ref.first_sight_step + 1
    assert traj.steps[-1].visible == expert_run.steps[-1].visible


def test_cli_convert_analyze_render_adapt(expert_run, tmp_path):
    log = write_log(tmp_path / "ep.jsonl", ai2thor_records(expert_run), {"house": "train_1", "policy": "my-agent"})
    traj_path, runner = tmp_path / "traj.json", CliRunner()
    res = runner.invoke(app, ["trajectory", "from-ai2thor", str(log), "--house", str(REAL_HOUSE), "--target", "Sofa",
                              "-o", str(traj_path), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)["metrics"]["success"] is True
    res = runner.invoke(app, ["analyze", str(REAL_HOUSE), str(traj_path), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)["outcome"]["success"] is True
    res = runner.invoke(app, ["render", str(REAL_HOUSE), "-o", str(tmp_path / "ep.png"), "-t", str(traj_path)])
    assert res.exit_code == 0 and (tmp_path / "ep.png").stat().st_size > 10_000, res.output
    res = runner.invoke(app, ["adapt", str(REAL_HOUSE), "-o", str(tmp_path / "out"), "--trajectory", str(traj_path),
                              "--policy", "expert", "--steps", "1", "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    assert summary["episode"]["target_type"] == "Sofa" and summary["episode"]["start"] == list(EPISODE.start)
    assert summary["agent_before"]["steps"] == len(expert_run.steps) and summary["policy"] == "my-agent"
    assert summary["trajectory"]["after_policy"] == "expert"
    assert json.loads((tmp_path / "out" / "trajectory_before.json").read_text())["policy"] == "my-agent"


def test_adapt_refuses_a_trajectory_of_another_house(expert_run, tmp_path):
    other = H.two_rooms(objects=[H.Obj(SOFA, 2.0, 0.6)], agent=(2.0, 2.0, 0.0))
    path = save_house(other, tmp_path / "other.json")
    traj_path = expert_run.save(tmp_path / "traj.json")
    res = CliRunner().invoke(app, ["adapt", str(path), "-o", str(tmp_path / "out"), "--trajectory", str(traj_path)])
    assert isinstance(res.exception, ConfigError) and "pass the house the episode ran in" in str(res.exception)
    res = CliRunner().invoke(app, ["adapt", str(REAL_HOUSE), "-o", str(tmp_path / "out"), "--trajectory",
                                   str(traj_path), "--target", "Bed"])
    assert isinstance(res.exception, ConfigError) and str(res.exception).startswith("--target Bed")


def test_actions_map_by_name_dict_and_observed_turn():
    a, b = Pose(x=1, z=1, yaw=0), Pose(x=1, z=1, yaw=354)
    assert [action_code(n, a, a, "x") for n in ("MoveAhead", "m", "move_back", "Done", "end", "RotateRight")] == [
        "m", "m", "b", "end", "end", "r"]
    assert action_code({"action": "MoveAgent", "ahead": -0.2}, a, a, "x") == "b"
    assert action_code({"action": "RotateAgent", "degrees": 30}, a, a, "x") == "r"
    assert action_code({"action": "RotateAgent", "degrees": -6}, a, b, "x") == "ls"
    assert action_code({"action": "RotateLeft", "degrees": 6}, a, b, "x") == "ls"  # small, from the turn seen
    assert action_code("LookUp", a, a, "x") is None and action_code("sub_done", a, a, "x") is None
    with pytest.raises(AdaptenvError, match="unknown action 'Jump'"):
        action_code("Jump", a, a, "log line 3")


@pytest.mark.parametrize(("change", "words"), [
    ("wrong_house", "outside every room"),
    ("flipped_yaw", "do not go where rotation.y faces"),
    ("no_target", "no target type"),
    ("not_a_target", "not one of adaptenv's ObjectNav targets"),
    ("bad_agent", "line 2: needs \"agent\" with position"),
    ("after_end", "after the episode's end action"),
])
def test_wrong_logs_are_one_clear_error(real_world, expert_run, tmp_path, change, words):
    header = {"target_type": "Alarm clock" if change == "not_a_target" else "Sofa"} if change != "no_target" else None
    records = ai2thor_records(expert_run, yaw_offset=180.0 if change == "flipped_yaw" else 0.0)
    if change == "bad_agent":
        records[0]["agent"] = {"position": {"x": 1.0}}
    if change == "after_end":
        records.append(records[-1])
    log = write_log(tmp_path / "ep.jsonl", records, header)
    world = compile_world(H.two_rooms(objects=[H.Obj(SOFA, 2.0, 0.6)]), "other") \
        if change == "wrong_house" else real_world
    with pytest.raises(AdaptenvError, match=words) as err:
        convert_ai2thor_log(log, world)
    assert str(log) in str(err.value) and "\n" not in str(err.value)


def test_api_takes_records_in_memory(real_world, expert_run):
    conv = trajectory_from_ai2thor(ai2thor_records(expert_run), real_world, "Sofa")
    assert conv.trajectory.metrics.success and conv.trajectory.house == REAL_HOUSE.stem
    with pytest.raises(AdaptenvError, match="no event records"):
        trajectory_from_ai2thor([], real_world, "Sofa")
