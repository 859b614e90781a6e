"""Run one ObjectNav episode in one house with a per-step policy and record its trajectory.

A policy here is any callable ``policy(world, episode, x, z, yaw, collided, step) -> action index``
(see :class:`Policy`); :func:`expert_policy` and :func:`random_policy` build the two built-in ones.
The episode ends at ``end`` (judged by :func:`~adaptenv.sim.task.is_success`) or after
``max_steps`` actions (a timeout, judged a failure). Each recorded step holds the pose before the
action, the action, whether a move succeeded, and, when ``record`` is on, the target instances in
sight (``visible``: within MAX_RANGE = 5 m, in view and unoccluded, i.e. "seen", not the 2 m
success test), the clearance and the geodesic distance at that pose.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from adaptenv.sim.geodesic import geodesic_distance
from adaptenv.sim.metrics import episode_metrics
from adaptenv.sim.physics import PackedGrids, step_poses
from adaptenv.sim.spec import ACTIONS, END, MAX_RANGE, MAX_STEPS, MOVE_AHEAD, MOVE_BACK, N_ACTIONS
from adaptenv.sim.task import Episode, visible_instances
from adaptenv.sim.trajectory import Pose, Step, Trajectory
from adaptenv.sim.world import NavWorld


class Policy(Protocol):
    """Chooses one action index (``spec.ACTIONS``) per step of one episode."""

    def __call__(self, world: NavWorld, episode: Episode, x: float, z: float, yaw: float,
                 collided: bool, step: int) -> int: ...


def packed_grids(world: NavWorld) -> PackedGrids:
    """A single-world PackedGrids for ``physics.step_poses`` (cached in ``world.cache``)."""
    key = ("packed",)
    if key not in world.cache:
        world.cache[key] = PackedGrids.from_worlds([world])
    return world.cache[key]


def run_episode(world: NavWorld, episode: Episode, policy: Policy, *, max_steps: int = MAX_STEPS,
                record: bool = True, policy_name: str | None = None,
                expert_length: int | None = None) -> Trajectory:
    """Roll out ``policy`` from ``episode.start`` and return the trajectory with its metrics."""
    grids = packed_grids(world)
    env = np.zeros(1, dtype=np.int64)
    x = np.array([episode.start[0]], dtype=np.float64)
    z = np.array([episode.start[1]], dtype=np.float64)
    yaw = np.array([episode.start[2] % 360.0], dtype=np.float64)
    act = np.zeros(1, dtype=np.int64)
    t = episode.target_type
    steps: list[Step] = []
    collided = False
    for k in range(max_steps):
        px, pz, pyaw = float(x[0]), float(z[0]), float(yaw[0])
        a = int(policy(world, episode, px, pz, pyaw, collided, k))
        if not 0 <= a < N_ACTIONS:
            raise ValueError(f"policy returned action {a}; expected an index into spec.ACTIONS (0..{N_ACTIONS - 1})")
        step = Step(pose=Pose(x=px, z=pz, yaw=pyaw), action=ACTIONS[a])
        if record:
            record_sight(world, t, step)
        if a == END:
            steps.append(step)
            break
        act[0] = a
        moved = bool(step_poses(grids, env, x, z, yaw, act)[0])
        step.moved = moved
        collided = a in (MOVE_AHEAD, MOVE_BACK) and not moved
        steps.append(step)
    traj = Trajectory(
        house=world.name, target_type=t, **target_fields(world, t),
        start=Pose(x=episode.start[0], z=episode.start[1], yaw=episode.start[2] % 360.0), steps=steps,
        final_pose=Pose(x=float(x[0]), z=float(z[0]), yaw=float(yaw[0])),
        policy=policy_name or getattr(policy, "name", type(policy).__name__), seed=episode.seed)
    traj.metrics = episode_metrics(world, traj, expert_length=expert_length)
    return traj


def record_sight(world: NavWorld, target_type: str, step: Step) -> None:
    """Fill a step's ``visible`` target ids, ``clearance`` and ``geodesic`` at its pose."""
    p = step.pose
    step.visible = visible_instances(world, p.x, p.z, p.yaw, target_type, max_distance=MAX_RANGE)
    step.clearance = float(world.grid.clearance_at(p.x, p.z))
    g = geodesic_distance(world, target_type, p.x, p.z)
    step.geodesic = g if np.isfinite(g) else None


def target_fields(world: NavWorld, target_type: str) -> dict[str, list]:
    """A trajectory's ``target_ids`` and ``target_positions``: every instance of the type in ``world``."""
    inst = world.instances_of(target_type)
    return {"target_ids": [i.object_id for i in inst],
            "target_positions": [(float(i.center[0]), float(i.center[1])) for i in inst]}


class _ExpertPolicy:
    def __init__(self, expert):
        self.expert = expert
        self.name = getattr(expert, "name", "expert")

    def __call__(self, world, episode, x, z, yaw, collided, step) -> int:
        return self.expert.act(world, episode.target_type, x, z, yaw, collided=collided)


def expert_policy(expert=None) -> Policy:
    """Adapt a :class:`~adaptenv.sim.expert.ShortestPathExpert` (default: a new one) to the Policy protocol."""
    if expert is None:
        from adaptenv.sim.expert import ShortestPathExpert

        expert = ShortestPathExpert()
    return _ExpertPolicy(expert)


class _RandomPolicy:
    name = "random"

    def __init__(self, rng: np.random.Generator, p_end: float):
        self.rng, self.p_end = rng, p_end

    def __call__(self, world, episode, x, z, yaw, collided, step) -> int:
        if self.p_end > 0 and self.rng.random() < self.p_end:
            return END
        return int(self.rng.integers(END))


def random_policy(rng: np.random.Generator | int, p_end: float = 0.0) -> Policy:
    """Uniform over the six motion actions; ``end`` with probability ``p_end`` per step (default never)."""
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng(int(rng))
    return _RandomPolicy(rng, float(p_end))


def expert_episode_length(world: NavWorld, episode: Episode, *, max_steps: int = MAX_STEPS, expert=None) -> int | None:
    """Steps the expert takes to succeed from the episode's start (None if it fails or it is unsolvable)."""
    traj = run_episode(world, episode, expert_policy(expert), max_steps=max_steps, record=False)
    return traj.metrics.episode_length if traj.metrics.success else None
