"""Run a policy on given episodes of a house and keep its trajectories: what F analyses and G checks.

Every caller that needs pi_t's behaviour in one scene (the adaptation step, the built-in G's
rollout checks, benchmarks) goes through :func:`run_policy`, or :func:`run_in_worlds` for the same
episodes in several scenes at once (G's candidates); both run any
:class:`~adaptenv.agents.policy.Policy` in the batched harness of :mod:`adaptenv.agents.evaluate`
and return :class:`~adaptenv.sim.trajectory.Trajectory` objects with their metrics::

    trajs = run_policy(world, [episode], policy)
    runs = run_in_worlds([world, child], checking_episodes(episode, 3), policy)   # one batch for both
    scores = [mean_spl(ts) for ts in runs]   # mean SPL, the R G lowers
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from adaptenv.agents.evaluate import EpisodeResult, run_episodes, trajectory_of
from adaptenv.agents.policy import Policy, policy_name
from adaptenv.sim.geodesic import optimal_path_length
from adaptenv.sim.metrics import episode_metrics
from adaptenv.sim.task import Episode, sample_episode
from adaptenv.sim.trajectory import Trajectory
from adaptenv.sim.world import NavWorld

#: Episodes drawn for adaptation start at least this far (geodesic, m) from the target when possible.
MIN_EPISODE_DISTANCE = 2.5


def run_recorded(world: NavWorld, episodes: list[Episode], policy: Policy
                 ) -> list[tuple[EpisodeResult, Trajectory]]:
    """Roll ``policy`` out on each episode of one world: the harness's result and the trajectory (with metrics)."""
    if not episodes:
        return []
    results, recs = run_episodes([world], [(0, ep) for ep in episodes], policy, batch=len(episodes),
                                 record=lambda r: True)
    out = []
    for k, res in enumerate(results):
        traj = trajectory_of(world, res, recs[k], policy_name(policy))
        traj.seed = episodes[k].seed
        traj.metrics = episode_metrics(world, traj)
        out.append((res, traj))
    return out


def run_in_worlds(worlds: list[NavWorld], episodes: list[Episode], policy: Policy) -> list[list[Trajectory]]:
    """Roll ``policy`` out on the same episodes in several worlds in one batch: trajectories with metrics, per world.

    One batch instead of a run per world: the policy is called once per step for all of them, which is
    what makes G's checks of several candidate scenes cheap (the sampler is seeded per episode, so the
    trajectories are those of one world at a time)."""
    pairs = [(w, ep) for w in range(len(worlds)) for ep in episodes]
    if not pairs:
        return [[] for _ in worlds]
    results, recs = run_episodes(worlds, pairs, policy, batch=len(pairs), record=lambda r: True)
    out: list[list[Trajectory]] = [[] for _ in worlds]
    for k, ((w, ep), res) in enumerate(zip(pairs, results, strict=True)):
        traj = trajectory_of(worlds[w], res, recs[k], policy_name(policy))
        traj.seed = ep.seed
        traj.metrics = episode_metrics(worlds[w], traj)
        out[w].append(traj)
    return out


def mean_spl(trajectories: list[Trajectory]) -> float:
    """Mean SPL of recorded trajectories (the R that G tries to lower); NaN for none."""
    return float(np.mean([t.metrics.spl for t in trajectories])) if trajectories else float("nan")


def total_steps(runs: list[list[Trajectory]]) -> int:
    """Environment steps taken in :func:`run_in_worlds`' trajectories (what a budget counts)."""
    return sum(len(t.steps) for trajs in runs for t in trajs)


def run_policy(world: NavWorld, episodes: list[Episode], policy: Policy) -> list[Trajectory]:
    """Roll ``policy`` out on each episode of one world; trajectories carry their metrics."""
    return [traj for _, traj in run_recorded(world, episodes, policy)]


def rollout(world: NavWorld, episode: Episode, policy: Policy) -> Trajectory:
    """One recorded episode (poses, actions, collisions, metrics)."""
    return run_policy(world, [episode], policy)[0]


def checking_episodes(episode: Episode, n: int) -> list[Episode]:
    """``n`` episodes with the same start position and target, headings spread evenly from the original."""
    n = max(1, int(n))
    return [replace(episode, start=(episode.start[0], episode.start[1], (episode.start[2] + k * 360.0 / n) % 360.0))
            for k in range(n)]


def draw_episode(world: NavWorld, rng: np.random.Generator, target_type: str | None = None, *,
                 min_distance: float = MIN_EPISODE_DISTANCE, tries: int = 20) -> Episode:
    """A solvable episode whose start is at least ``min_distance`` from the target (else the longest of ``tries``).

    Very short episodes leave G nothing to work with (no route to narrow, occlude or lengthen).
    """
    best, best_d = None, -1.0
    for _ in range(tries):
        ep = sample_episode(world, rng, target_type)
        d = optimal_path_length(world, ep)
        if d >= min_distance:
            return ep
        if d > best_d:
            best, best_d = ep, d
    return best


def find_solved_episode(world: NavWorld, policy: Policy, rng: np.random.Generator, *, tries: int = 10,
                        target_type: str | None = None,
                        min_distance: float = MIN_EPISODE_DISTANCE) -> tuple[Episode, Trajectory] | None:
    """Sample episodes (see :func:`draw_episode`) until the policy succeeds on one (None after ``tries``)."""
    for _ in range(tries):
        ep = draw_episode(world, rng, target_type, min_distance=min_distance)
        traj = rollout(world, ep, policy)
        if traj.metrics.success:
            return ep, traj
    return None
