"""A hand-written ObjectNav policy plugged into adaptenv with ``--policy examples/my_policy.py:policy``.

It only reads the observation (no map): turn toward the target when any ray sees it, call ``end``
when the target is close and in front, otherwise walk forward and turn away from walls. It keeps a
per-agent memory (steps since the last turn) to show how recurrent state and ``done`` work.

Try it::

    adaptenv evaluate --policy examples/my_policy.py:policy --houses preset:tiny --episodes 20 -o runs/mine
"""

from __future__ import annotations

import numpy as np

from adaptenv.sim.spec import END, MAX_RANGE, MOVE_AHEAD, N_RAYS, ROTATE_LEFT, ROTATE_RIGHT

CLOSE = 1.5 / MAX_RANGE
"""Normalized depth under which a seen target counts as reached (1.5 m)."""
WALL = 0.4 / MAX_RANGE
"""Normalized depth under which the ray straight ahead counts as blocked (0.4 m)."""


class ReactivePolicy:
    """Batched policy: ``initial_state(batch)`` and ``act(obs, state, done) -> (actions, state)``."""

    name = "reactive-example"

    def initial_state(self, batch: int) -> np.ndarray:
        return np.zeros(batch, dtype=np.int64)  # steps since the last turn, per agent

    def act(self, obs: dict[str, np.ndarray], state: np.ndarray, done: np.ndarray):
        state = np.where(done, 0, state)  # a new episode forgets the previous one
        depth, sem = obs["depth"], obs["semantic"]
        hits = sem == obs["target"][:, None]  # (B, N_RAYS): rays that see the target
        centre = N_RAYS // 2
        actions = np.full(len(done), MOVE_AHEAD, dtype=np.int64)
        for i in range(len(done)):
            rays = np.flatnonzero(hits[i])
            if rays.size:  # target in view: face it, then end when close
                bearing = rays.mean() - (N_RAYS - 1) / 2
                if abs(bearing) > 3:
                    actions[i] = ROTATE_LEFT if bearing < 0 else ROTATE_RIGHT
                elif depth[i, rays].min() < CLOSE:
                    actions[i] = END
            elif depth[i, centre - 2:centre + 2].min() < WALL or obs["collided"][i] or state[i] > 25:
                # blocked (or walking for long): turn toward the more open side
                left, right = depth[i, :centre].mean(), depth[i, centre:].mean()
                actions[i] = ROTATE_LEFT if left > right else ROTATE_RIGHT
        state = np.where(actions == MOVE_AHEAD, state + 1, 0)
        return actions, state


policy = ReactivePolicy()
