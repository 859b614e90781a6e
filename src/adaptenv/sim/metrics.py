"""Per-episode ObjectNav metrics computed from a trajectory and its world (a pure function).

Everything is recomputed from the recorded poses and actions, so a trajectory from any runner
(single env, batched env, hand-made) gets the same figures:

- ``success``: the last action is ``end`` and :func:`~adaptenv.sim.task.is_success` holds at its pose.
- ``spl`` = success * optimal / max(path_length, optimal), with 0/0 taken as 1 (start already in
  the success region and no move).
- ``sel`` = success * expert_len / max(episode_length, expert_len); when the expert's length is
  unknown, expert_len is the lower bound ceil(optimal / MOVE_STEP) + 1 (moves plus ``end``,
  ignoring turns), so SEL is then an upper bound of the true SEL.
- ``episode_length``: steps taken (``end`` included); ``path_length``: sum of achieved displacements.
- ``collisions``: move actions that did not move; ``min_clearance``: smallest clearance over visited poses.
- ``rooms_visited``: distinct rooms over visited poses; ``first_sight_step``: first step whose pose
  sees a target instance within MAX_RANGE (in view, in line of sight), None if never.
- ``solvable``: the success region is reachable from the start; unsolvable episodes have
  success False and SPL/SEL 0 and must be excluded from agent-failure statistics.
"""

from __future__ import annotations

import math

import numpy as np

from adaptenv.sim.geodesic import geodesic_distance
from adaptenv.sim.spec import ACTIONS, MAX_RANGE, MOVE_STEP
from adaptenv.sim.task import is_success, visible_instances
from adaptenv.sim.trajectory import EpisodeMetrics, Trajectory
from adaptenv.sim.world import NavWorld

_MOVES = {ACTIONS[0], ACTIONS[1]}


def spl(success: bool, optimal: float, path_length: float) -> float:
    """Success weighted by path length (0/0 counts as 1)."""
    if not success or not math.isfinite(optimal):
        return 0.0
    denom = max(path_length, optimal)
    return 1.0 if denom <= 1e-9 else float(optimal / denom)


def sel(success: bool, expert_length: int, episode_length: int) -> float:
    """Success weighted by episode length relative to the expert's."""
    if not success:
        return 0.0
    return float(expert_length / max(episode_length, expert_length, 1))


def expert_length_bound(optimal: float) -> int:
    """A lower bound on any successful episode's length: the moves to cover ``optimal`` plus ``end``."""
    return int(math.ceil(optimal / MOVE_STEP - 1e-6)) + 1


def first_sight(world: NavWorld, trajectory: Trajectory) -> int | None:
    """Index of the first step whose pose sees a target instance within MAX_RANGE (None if never)."""
    poses = [s.pose for s in trajectory.steps] or [trajectory.start]
    for k, p in enumerate(poses):
        if visible_instances(world, p.x, p.z, p.yaw, trajectory.target_type, max_distance=MAX_RANGE):
            return k
    return None


def episode_metrics(world: NavWorld, trajectory: Trajectory, *, expert_length: int | None = None) -> EpisodeMetrics:
    """ObjectNav metrics of one episode (see the module docstring for each definition)."""
    t = trajectory.target_type
    poses = trajectory.poses
    xs = np.array([p.x for p in poses])
    zs = np.array([p.z for p in poses])
    optimal = float(geodesic_distance(world, t, trajectory.start.x, trajectory.start.z))
    solvable = math.isfinite(optimal)
    steps = trajectory.steps
    last = steps[-1] if steps else None
    success = bool(solvable and last is not None and last.action == "end"
                   and is_success(world, last.pose.x, last.pose.z, last.pose.yaw, t))
    path = float(np.hypot(np.diff(xs), np.diff(zs)).sum()) if len(xs) > 1 else 0.0
    final = float(geodesic_distance(world, t, xs[-1], zs[-1]))
    clear = world.grid.clearance_at(xs, zs)
    rows, cols = world.grid.to_cell(xs, zs)
    ok = world.grid.in_bounds(rows, cols)
    rooms = world.grid.room[rows[ok], cols[ok]]
    ref_len = expert_length if expert_length is not None else (expert_length_bound(optimal) if solvable else 1)
    return EpisodeMetrics(
        success=success,
        spl=spl(success, optimal, path),
        sel=sel(success, ref_len, len(steps)),
        episode_length=len(steps),
        path_length=path,
        final_geodesic=final if math.isfinite(final) else None,
        collisions=sum(1 for s in steps if s.action in _MOVES and not s.moved),
        min_clearance=float(clear.min()) if len(clear) else None,
        rooms_visited=int(len(np.unique(rooms[rooms >= 0]))),
        first_sight_step=first_sight(world, trajectory),
        optimal_path_length=optimal if solvable else None,
        expert_episode_length=expert_length,
        solvable=solvable,
    )


CHECKED_FIGURES = ("success", "spl", "sel", "episode_length", "path_length", "collisions", "first_sight_step",
                   "final_geodesic", "optimal_path_length", "rooms_visited", "min_clearance", "solvable")
"""The stored figures :func:`recompute_metrics` compares with its own."""


def _figure(value: object) -> str:
    """A figure as a message shows it: floats to two decimals, None as none, booleans lower case."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:.2f}" if abs(value) < 1e6 else f"{value:.3g}"
    return "none" if value is None else str(value)


def _same(a: object, b: object) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-4)
    return a == b


def recompute_metrics(world: NavWorld, trajectory: Trajectory) -> tuple[EpisodeMetrics, list[str]]:
    """The episode's metrics recomputed from its poses in ``world``, and each stored figure that differs from them
    (``stored spl 5.00 differs from recomputed 0.00``). A stored expert length is kept when it is possible (no
    shorter than :func:`expert_length_bound`), since only a rerun of the expert could check it."""
    fresh = episode_metrics(world, trajectory)
    stored = trajectory.metrics
    expert = stored.expert_episode_length if stored is not None else None
    if expert is not None and fresh.optimal_path_length is not None and expert >= expert_length_bound(
            fresh.optimal_path_length):
        fresh = fresh.model_copy(update={"expert_episode_length": expert,
                                         "sel": sel(fresh.success, expert, fresh.episode_length)})
    if stored is None:
        return fresh, []
    differs = [f"stored {name} {_figure(getattr(stored, name))} differs from recomputed {_figure(getattr(fresh, name))}"
               for name in CHECKED_FIGURES if not _same(getattr(stored, name), getattr(fresh, name))]
    return fresh, differs
