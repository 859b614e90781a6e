"""The record an episode leaves behind: poses, actions, outcomes, and what was visible at each step.

Trajectories serialize to JSON and back (``Trajectory.save`` / ``Trajectory.load``); the renderer
draws them and the analysis step F reads them. A loaded trajectory is evidence, not a verdict: its poses must
follow one another by at most one action (:func:`pose_jumps`), and its stored metrics are recomputed from the
poses and the house (:func:`adaptenv.sim.metrics.recompute_metrics`) before anything reads them.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from pydantic import BaseModel, Field

from adaptenv.errors import AdaptenvError
from adaptenv.files import FileRefused, atomic_write_text, loads_json, read_bytes
from adaptenv.limits import TRAJECTORY_BYTES
from adaptenv.sim.spec import ACTIONS, MOVE_STEP, ROTATE_LARGE

JUMP_SLACK = 0.06
"""How much farther (m) than one move (``MOVE_STEP``) a recorded pose may lie from the one before: float noise, and
AI2-THOR's default 0.25 m moves with their noise."""
TURN_SLACK = 1.0
"""How much more (degrees) than one turn (``ROTATE_LARGE``) a recorded yaw may differ from the one before."""
MOVE_SLACK = 0.01
"""A move whose position changed less than this (m) went nowhere; one marked blocked may not move farther."""


class Pose(BaseModel):
    """Agent pose: position (m) in the floor plane and yaw (degrees, 0 faces +z, 90 faces +x)."""

    x: float
    z: float
    yaw: float


class Step(BaseModel):
    """One step: the action taken from ``pose`` and what followed."""

    pose: Pose
    """Pose before the action."""
    action: str
    """One of ``adaptenv.sim.spec.ACTIONS``."""
    moved: bool = True
    """False when a move was blocked (a collision)."""
    visible: list[str] = Field(default_factory=list)
    """Ids of target instances visible (within range, in view, unoccluded) from ``pose``."""
    clearance: float | None = None
    """Distance (m) from the agent's centre to the nearest obstacle at ``pose``."""
    geodesic: float | None = None
    """Geodesic distance (m) from ``pose`` to the target's success region."""


class EpisodeMetrics(BaseModel):
    """Per-episode figures (SPOC's ObjectNav metrics plus collisions and clearance)."""

    success: bool
    spl: float
    sel: float
    episode_length: int
    path_length: float
    final_geodesic: float | None
    collisions: int
    min_clearance: float | None
    rooms_visited: int
    first_sight_step: int | None
    optimal_path_length: float | None
    expert_episode_length: int | None = None
    solvable: bool = True


class Trajectory(BaseModel):
    """A whole ObjectNav episode in one house."""

    house: str
    """Name or path of the house the episode ran in."""
    target_type: str
    target_ids: list[str] = Field(default_factory=list)
    """Ids of every instance of the target type in the house."""
    target_positions: list[tuple[float, float]] = Field(default_factory=list)
    """(x, z) of each target instance, aligned with ``target_ids``."""
    start: Pose
    steps: list[Step] = Field(default_factory=list)
    final_pose: Pose | None = None
    policy: str = ""
    seed: int | None = None
    metrics: EpisodeMetrics | None = None

    @property
    def poses(self) -> list[Pose]:
        """Every pose visited, start to end."""
        out = [s.pose for s in self.steps]
        if self.final_pose is not None:
            out.append(self.final_pose)
        return out or [self.start]

    def save(self, path: str | Path) -> Path:
        p = Path(path)
        atomic_write_text(p, self.model_dump_json(indent=1))
        return p

    @classmethod
    def load(cls, path: str | Path) -> Trajectory:
        """Read a trajectory JSON file; a malformed file raises one clear AdaptenvError."""
        p = Path(path)
        try:
            traj = cls.model_validate(loads_json(read_bytes(p, TRAJECTORY_BYTES, "trajectory")))
        except FileNotFoundError:
            raise AdaptenvError(f"{p}: no such trajectory file; check the path") from None
        except FileRefused:
            raise
        except OSError as exc:
            raise AdaptenvError(f"{p}: the trajectory file cannot be read ({exc.strerror}); check the path") from None
        except (ValueError, RecursionError) as exc:  # not JSON, not a trajectory, nested too deeply
            first = (str(exc).splitlines() or [type(exc).__name__])[0]
            raise AdaptenvError(f"{p}: not a valid adaptenv trajectory ({first}); write it with "
                                "`adaptenv rollout ... -o traj.json`") from None
        if (why := traj.problem()) is not None:
            raise AdaptenvError(f"{p}: not a recorded episode, at {why}; write it with `adaptenv rollout ... -o "
                                "traj.json` or `adaptenv trajectory from-ai2thor`")
        return traj

    def problem(self) -> str | None:
        """What makes this recorded episode impossible (no steps, an unknown action, a number that is not finite,
        targets and positions that do not pair up), or None."""
        if not self.steps:
            return "steps: the episode has no steps"
        if len(self.target_positions) != len(self.target_ids):
            return (f"target_positions: {len(self.target_positions)} positions for {len(self.target_ids)} "
                    "target_ids")
        for where, value in self._numbers():
            if value is not None and not math.isfinite(value):
                return f"{where}: {value} is not a finite number"
        for i, step in enumerate(self.steps):
            if step.action not in ACTIONS:
                return f"steps[{i}].action: unknown action {step.action!r} (actions are {', '.join(ACTIONS)})"
        return pose_jumps(self)

    def _numbers(self) -> Iterator[tuple[str, float | None]]:
        """Every number of the record, with its JSON path."""
        for name, pose in (("start", self.start), ("final_pose", self.final_pose)):
            if pose is not None:
                yield from ((f"{name}.{k}", v) for k, v in pose.model_dump().items())
        for i, step in enumerate(self.steps):
            yield from ((f"steps[{i}].pose.{k}", v) for k, v in step.pose.model_dump().items())
            yield f"steps[{i}].clearance", step.clearance
            yield f"steps[{i}].geodesic", step.geodesic
        for i, (x, z) in enumerate(self.target_positions):
            yield from ((f"target_positions[{i}]", v) for v in (x, z))
        if self.metrics is not None:
            yield from ((f"metrics.{k}", v) for k, v in self.metrics.model_dump().items()
                        if isinstance(v, float))


def metres(v: float) -> str:
    """A coordinate for a message: to the centimetre, or three digits when it is huge (never 300 digits)."""
    return f"{v:.2f}" if abs(v) < 1e6 else f"{v:.3g}"


def step_jump(before: Pose, after: Pose) -> str | None:
    """Why ``after`` cannot follow ``before`` by one action (farther than one move, turned more than one turn), or
    None."""
    dist = math.hypot(after.x - before.x, after.z - before.z)
    turn = abs((after.yaw - before.yaw + 180.0) % 360.0 - 180.0)
    if dist > MOVE_STEP + JUMP_SLACK:
        return f"the agent jumps {metres(dist)} m from the pose before, farther than one move ({MOVE_STEP:g} m)"
    if turn > ROTATE_LARGE + TURN_SLACK:
        return f"the agent turns {turn:.0f} degrees from the pose before, more than one turn ({ROTATE_LARGE:g} degrees)"
    return None


def pose_jumps(traj: Trajectory) -> str | None:
    """Where ``traj``'s poses do not follow one another by one action, or None: a pose farther than one move
    (``MOVE_STEP`` + ``JUMP_SLACK``) or turned more than one turn (``ROTATE_LARGE`` + ``TURN_SLACK``) from the pose
    before it, or a move whose ``moved`` flag its poses contradict."""
    poses = [traj.start, *(s.pose for s in traj.steps)] + ([traj.final_pose] if traj.final_pose is not None else [])
    names = ["steps[0].pose", *(f"steps[{i}].pose" for i in range(1, len(traj.steps))), "final_pose"]
    xyz = np.array([(p.x, p.z, p.yaw) for p in poses], dtype=np.float64)
    dist = np.hypot(np.diff(xyz[:, 0]), np.diff(xyz[:, 1]))
    turn = np.abs((np.diff(xyz[:, 2]) + 180.0) % 360.0 - 180.0)
    bad = np.flatnonzero((dist > MOVE_STEP + JUMP_SLACK) | (turn > ROTATE_LARGE + TURN_SLACK))
    if bad.size:
        k = int(bad[0])
        return f"{names[k]}: {step_jump(poses[k], poses[k + 1])}"
    for i, step in enumerate(traj.steps):  # step i goes from poses[i + 1] to poses[i + 2]
        if step.action not in ("m", "b") or i + 1 >= len(dist):
            continue
        went = float(dist[i + 1])
        if step.moved and went < MOVE_SLACK:
            return f"steps[{i}].moved: the move is marked as made (true) but the agent stayed where it was"
        if not step.moved and went >= MOVE_SLACK:
            return f"steps[{i}].moved: the move is marked blocked (false) but the agent moved {metres(went)} m"
    return None
