"""Episode metrics on hand-made trajectories."""

from __future__ import annotations

import pytest

from adaptenv.sim.metrics import episode_metrics, expert_length_bound, sel, spl
from adaptenv.sim.trajectory import Pose, Step, Trajectory
from adaptenv.sim.world import compile_world
from tests.sim import helpers as H


def traj(poses, actions, moved, target="GarbageCan", final=None):
    steps = [Step(pose=Pose(x=x, z=z, yaw=y), action=a, moved=m) for (x, z, y), a, m in zip(poses, actions, moved, strict=True)]
    fx, fz, fy = final or poses[-1]
    return Trajectory(house="h", target_type=target, start=steps[0].pose, steps=steps, final_pose=Pose(x=fx, z=fz, yaw=fy))


def test_formulas():
    assert spl(True, 4.0, 5.0) == pytest.approx(0.8)
    assert spl(True, 4.0, 3.0) == 1.0 and spl(False, 4.0, 4.0) == 0.0
    assert spl(True, 0.0, 0.0) == 1.0
    assert sel(True, 20, 40) == 0.5 and sel(True, 20, 10) == 1.0 and sel(False, 20, 20) == 0.0
    assert expert_length_bound(1.0) == 6


def test_metrics_of_a_hand_made_episode():
    # Two rooms joined by a door at z = 2; the can sits in room 1 at (7, 2).
    w = compile_world(H.two_rooms(1.0, objects=[H.Obj(H.LOW_TARGET, 7.0, 2.0)]))
    poses = [(3.0, 2.0, 0.0), (3.0, 2.0, 90.0), (3.2, 2.0, 90.0), (3.4, 2.0, 90.0), (3.6, 2.0, 90.0),
             (3.8, 2.0, 90.0), (4.0, 2.0, 90.0), (4.2, 2.0, 90.0), (4.4, 2.0, 90.0), (4.6, 2.0, 90.0),
             (4.8, 2.0, 90.0), (5.0, 2.0, 90.0), (5.0, 2.0, 90.0)]
    actions = ["r", "m", "m", "m", "m", "m", "m", "m", "m", "m", "m", "m", "end"]
    moved = [True] * 11 + [False, True]  # the 11th move hits nothing in reality, but is logged as blocked
    t = traj(poses, actions, moved)
    m = episode_metrics(w, t)
    assert m.success and m.solvable
    assert m.episode_length == 13
    assert m.path_length == pytest.approx(2.0)
    assert m.collisions == 1
    assert m.rooms_visited == 2
    assert m.optimal_path_length == pytest.approx(t.metrics.optimal_path_length if t.metrics else m.optimal_path_length)
    assert m.spl == pytest.approx(min(1.0, m.optimal_path_length / 2.0))
    assert m.sel == pytest.approx(expert_length_bound(m.optimal_path_length) / 13)
    assert m.final_geodesic == 0.0
    assert 0.2 < m.min_clearance < 1.0
    assert m.first_sight_step == 1  # yaw 0 looks along +z; after turning right the can is 4 m ahead
    with_expert = episode_metrics(w, t, expert_length=26)
    assert with_expert.sel == 1.0 and with_expert.expert_episode_length == 26


def test_failure_and_timeout():
    w = compile_world(H.two_rooms(1.0, objects=[H.Obj(H.LOW_TARGET, 7.0, 2.0)]))
    # Ends facing away from the target: not a success even inside the 2 m range.
    m = episode_metrics(w, traj([(5.5, 2.0, 270.0)], ["end"], [True]))
    assert not m.success and m.spl == 0.0 and m.sel == 0.0 and m.final_geodesic == 0.0
    # No end action at all (a timeout).
    m = episode_metrics(w, traj([(5.5, 2.0, 90.0)], ["r"], [True], final=(5.5, 2.0, 120.0)))
    assert not m.success


def _walk():
    """Eleven moves east from (3, 2) in the two-room house, then ``end``."""
    poses = [(3.0 + 0.2 * k, 2.0, 90.0) for k in range(12)]
    return traj(poses, ["m"] * 11 + ["end"], [True] * 12)


def test_stored_metrics_are_recomputed_and_each_difference_named():
    from adaptenv.sim.metrics import recompute_metrics

    w = compile_world(H.two_rooms(1.0, objects=[H.Obj(H.LOW_TARGET, 7.0, 2.0)]))
    t = _walk()
    t.metrics = episode_metrics(w, t)
    fresh, differs = recompute_metrics(w, t)
    assert differs == [] and fresh == t.metrics  # a genuine record agrees with itself
    t.metrics = t.metrics.model_copy(update={"spl": 5.0, "collisions": 3})
    fresh, differs = recompute_metrics(w, t)
    assert fresh.spl == episode_metrics(w, t).spl and fresh.collisions == 0
    assert differs == [f"stored spl 5.00 differs from recomputed {fresh.spl:.2f}",
                       "stored collisions 3 differs from recomputed 0"]


def test_a_pose_that_does_not_follow_by_one_action_is_named():
    from adaptenv.sim.trajectory import pose_jumps

    t = _walk()
    assert pose_jumps(t) is None
    t.steps[5].pose = Pose(x=t.steps[5].pose.x + 1.0, z=2.0, yaw=90.0)
    assert pose_jumps(t).startswith("steps[5].pose: the agent jumps 1.20 m from the pose before")
    t = _walk()
    t.steps[5].pose = Pose(x=t.steps[5].pose.x, z=2.0, yaw=150.0)
    assert pose_jumps(t).startswith("steps[5].pose: the agent turns 60 degrees")
    t = _walk()
    t.steps[4].moved = False
    assert pose_jumps(t) == "steps[4].moved: the move is marked blocked (false) but the agent moved 0.20 m"
