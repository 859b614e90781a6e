"""The batch episode runner: play episodes with a policy in a BatchSim and keep their outcomes.

:mod:`adaptenv.agents.evaluate` (the evaluation harness) and :mod:`adaptenv.agents.suites` (the
expert's step counts for floored suites) both run episodes through :func:`run_episodes`;
``evaluate`` re-exports its names.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from adaptenv.agents.policy import Policy, PolicyContext, bind_policy
from adaptenv.sim import task
from adaptenv.sim.spec import MAX_STEPS
from adaptenv.sim.vector import BatchSim
from adaptenv.sim.world import NavWorld


@dataclass
class EpisodeResult:
    """Outcome of one evaluated episode (one CSV row)."""

    index: int
    house: str
    env: int
    target_type: str
    seed: int
    success: bool
    spl: float
    sel: float
    steps: int
    collisions: int
    path_length: float
    optimal: float
    final_geodesic: float
    expert_steps: int | None = None


@dataclass
class Recorded:
    """Poses and actions of one episode, kept when the runner is asked to record it."""

    start: tuple[float, float, float]
    poses: list[tuple[float, float, float]] = field(default_factory=list)
    actions: list[int] = field(default_factory=list)
    moved: list[bool] = field(default_factory=list)


def _sync(ctx: PolicyContext, sim: BatchSim) -> None:
    """Point the policy context at the simulator's current arrays (they are replaced on reset)."""
    ctx.worlds = sim.worlds
    ctx.env_idx = sim.env
    ctx.target_types = sim.target_types
    ctx.x, ctx.z, ctx.yaw = sim.x, sim.z, sim.yaw


def run_episodes(worlds: Sequence[NavWorld], episodes: Sequence[tuple[int, task.Episode]], policy: Policy, *,
                 batch: int = 64, max_steps: int = MAX_STEPS,
                 record: Callable[[EpisodeResult], bool] | None = None,
                 progress: Callable[[int], None] | None = None) -> tuple[list[EpisodeResult], dict[int, Recorded]]:
    """Run every episode with ``policy`` in a BatchSim of ``batch`` slots.

    Returns results in episode order and the recordings of the episodes for which ``record``
    returned True (all poses are tracked while running; only those are kept). ``progress`` is
    called with the number of episodes finished at each completion.
    """
    n = len(episodes)
    if n == 0:
        return [], {}
    b = min(batch, n)
    sim = BatchSim(worlds, max_steps=max_steps, shapes=getattr(policy, "perception", "labels") == "shape")
    first = [episodes[i] for i in range(b)]
    obs, _ = sim.reset([ep for _, ep in first], [e for e, _ in first])
    ctx = PolicyContext.empty(sim.worlds, b)
    slot_episode = np.arange(b)
    ctx.seeds[:] = [int(getattr(ep, "seed", i) or 0) for i, (_, ep) in enumerate(first)]
    _sync(ctx, sim)
    bind_policy(policy, ctx)
    state = policy.initial_state(b)
    done = np.ones(b, dtype=bool)
    live = np.ones(b, dtype=bool)
    # trajectories of the running episodes: pose before each step (and the final pose), action, moved
    poses = np.zeros((max_steps + 1, b, 3))
    acts = np.zeros((max_steps, b), dtype=np.int64)
    moves = np.zeros((max_steps, b), dtype=bool)
    taken = np.zeros(b, dtype=np.int64)
    slots = np.arange(b)
    results: dict[int, EpisodeResult] = {}
    recordings: dict[int, Recorded] = {}
    next_episode = b
    while live.any():
        _sync(ctx, sim)
        actions, state = policy.act(obs, state, done)
        actions = np.asarray(actions, dtype=np.int64)
        rows = slots[live]
        poses[taken[rows], rows] = np.stack([sim.x[rows], sim.z[rows], sim.yaw[rows]], axis=1)
        obs, _, terminated, truncated, info = sim.step(actions)
        acts[taken[rows], rows] = actions[rows]
        moves[taken[rows], rows] = sim.moved[rows]
        taken[rows] += 1
        finished = np.flatnonzero(live & (terminated | truncated))
        done = np.zeros(b, dtype=bool)
        refill, refill_eps = [], []
        for i in finished.tolist():
            k = int(slot_episode[i])
            e, ep = episodes[k]
            res = EpisodeResult(
                index=k, house=str(worlds[e].name), env=e, target_type=ep.target_type,
                seed=int(getattr(ep, "seed", k) or 0), success=bool(info["success"][i]),
                spl=float(np.nan_to_num(info["spl"][i])), sel=float("nan"), steps=int(info["steps"][i]),
                collisions=int(info["collisions"][i]), path_length=float(info["path_length"][i]),
                optimal=float(sim.start_geodesic[i]), final_geodesic=float(info["geodesic"][i]))
            results[k] = res
            if record is not None and record(res):
                t = int(taken[i])
                poses[t, i] = (sim.x[i], sim.z[i], sim.yaw[i])
                recordings[k] = Recorded(tuple(poses[0, i].tolist()), [tuple(p) for p in poses[: t + 1, i].tolist()],
                                         acts[:t, i].tolist(), moves[:t, i].tolist())
            if next_episode < n:
                slot_episode[i] = next_episode
                refill.append(i)
                refill_eps.append(episodes[next_episode])
                next_episode += 1
            else:
                live[i] = False
        if refill:
            idx = np.asarray(refill)
            obs = sim.reset_at(idx, [ep for _, ep in refill_eps], [e for e, _ in refill_eps])
            ctx.seeds[idx] = [int(getattr(ep, "seed", 0) or 0) for _, ep in refill_eps]
            taken[idx] = 0
            done[idx] = True
        if progress is not None and finished.size:
            progress(len(results))
    return [results[k] for k in range(n)], recordings
