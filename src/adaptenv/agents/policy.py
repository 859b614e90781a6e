"""The policy interface every agent implements: batched, recurrent, optionally privileged.

A policy drives a batch of B agents at once. Each call receives one observation per agent (the
layout of :mod:`adaptenv.sim.spec`, batched along the first axis), the recurrent state it returned
last time, and a ``done`` mask saying which agents start a new episode with this observation (their
memory must be reset before acting). It returns one action per agent and the next state::

    policy = RandomPolicy(seed=0)
    state = policy.initial_state(batch=4)
    done = np.ones(4, dtype=bool)              # every agent starts an episode
    actions, state = policy.act(obs, state, done)

Policies that need the true world (the shortest-path expert) also implement ``bind(context)``:
runners call it once with a :class:`PolicyContext` whose arrays they keep up to date (house index,
target type, episode seed and pose of every agent). Learned policies must not use it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from adaptenv.errors import ConfigError
from adaptenv.sim.expert import ShortestPathExpert
from adaptenv.sim.physics import PackedGrids
from adaptenv.sim.scan import pack_semantic, scan
from adaptenv.sim.spec import END, NO_ACTION, class_id
from adaptenv.sim.task import Episode
from adaptenv.sim.world import NavWorld

State = Any
"""Whatever a policy carries between steps (None for memoryless policies, a tensor for a GRU)."""

Observation = dict[str, np.ndarray]
"""Batched observation: ``depth`` (B, N_RAYS) float32, ``semantic`` (B, N_RAYS) int, ``target``,
``prev_action`` and ``collided`` (B,) int."""


@runtime_checkable
class Policy(Protocol):
    """A batched recurrent policy (see the module docstring for the calling convention)."""

    def initial_state(self, batch: int) -> State:
        """The memory of ``batch`` agents before their first step."""
        ...

    def act(self, obs: Observation, state: State, done: np.ndarray) -> tuple[np.ndarray, State]:
        """Actions (B,) int64 in ``range(N_ACTIONS)`` and the next state.

        ``done[i]`` is True when ``obs[i]`` is the first observation of a new episode.
        """
        ...


@runtime_checkable
class Privileged(Protocol):
    """A policy that reads the true world through a :class:`PolicyContext` (e.g. the expert)."""

    def bind(self, context: PolicyContext) -> None:
        """Keep ``context``; its arrays are updated in place by the runner before every ``act``."""
        ...


@dataclass
class PolicyContext:
    """Privileged view of a batch, owned and kept current by the runner (harness, trainer).

    Arrays have one entry per agent; the runner writes them in place (``ctx.x[:] = ...``) after
    every step and reset, so a policy may keep a reference to the context.
    """

    worlds: Sequence[NavWorld]
    """The compiled houses (:class:`~adaptenv.sim.world.NavWorld`) the batch runs in."""
    env_idx: np.ndarray
    """int64 (B,): index into ``worlds`` of each agent's house."""
    target_types: list[str]
    """Target object type of each agent's episode."""
    seeds: np.ndarray
    """int64 (B,): seed of each agent's current episode (for per-episode randomness)."""
    x: np.ndarray
    z: np.ndarray
    yaw: np.ndarray
    extra: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def empty(cls, worlds: Sequence[NavWorld], batch: int) -> PolicyContext:
        """A context for ``batch`` agents with zeroed arrays (the runner fills them)."""
        return cls(worlds, np.zeros(batch, np.int64), [""] * batch, np.zeros(batch, np.int64),
                   np.zeros(batch), np.zeros(batch), np.zeros(batch))


def bind_policy(policy: Policy, context: PolicyContext) -> None:
    """Give ``context`` to ``policy`` if it asks for privileged access (no-op otherwise)."""
    bind = getattr(policy, "bind", None)
    if callable(bind):
        bind(context)


def policy_name(policy: Policy) -> str:
    """A short label for reports: the policy's ``name`` attribute or its class name."""
    return str(getattr(policy, "name", type(policy).__name__))


class RandomPolicy:
    """Uniformly random motion actions (never ``end`` unless ``p_end`` > 0), seeded.

    Matches :func:`adaptenv.sim.rollout.random_policy`: uniform over the six motion actions, and
    ``end`` with probability ``p_end`` per step. When bound to a context, agent i's generator is
    re-seeded from ``(seed, context.seeds[i])`` at every episode start, so its actions do not depend
    on how episodes are batched or split across workers.
    """

    name = "random"

    def __init__(self, seed: int = 0, p_end: float = 0.0):
        self.seed = seed
        self.p_end = float(p_end)
        self._rng = np.random.default_rng(seed)
        self._context: PolicyContext | None = None
        self._slots: list[np.random.Generator] = []

    def bind(self, context: PolicyContext) -> None:
        self._context = context
        self._slots = []

    def initial_state(self, batch: int) -> State:
        return None

    def act(self, obs: Observation, state: State, done: np.ndarray) -> tuple[np.ndarray, State]:
        batch = len(done)
        if self._context is None:
            u = self._rng.random(batch)
            moves = self._rng.integers(0, END, size=batch, dtype=np.int64)
            return np.where(u < self.p_end, END, moves), state
        if len(self._slots) != batch:
            self._slots = [np.random.default_rng(0) for _ in range(batch)]
        for i in np.flatnonzero(done):
            self._slots[i] = np.random.default_rng([self.seed, int(self._context.seeds[i])])
        actions = np.array([END if self.p_end > 0 and g.random() < self.p_end else g.integers(0, END)
                            for g in self._slots], dtype=np.int64)
        return actions, state


class PrivilegedMemoryless:
    """Base of privileged policies without memory: they keep the runner's context and carry no state."""

    name = "privileged"
    _context: PolicyContext | None = None

    def bind(self, context: PolicyContext) -> None:
        self._context = context

    def initial_state(self, batch: int) -> State:
        return None

    def bound(self) -> PolicyContext:
        """The runner's context; a clear error when the policy is run outside adaptenv's runners."""
        if self._context is None:
            raise ConfigError(f"the {self.name} policy needs privileged access to the world; run it through "
                              "adaptenv's runners (evaluate, rollout, adapt, train), which bind a PolicyContext")
        return self._context


class ExpertPolicy(PrivilegedMemoryless):
    """The shortest-path expert as a batched policy (privileged: needs :meth:`bind`)."""

    name = "expert"

    def __init__(self) -> None:
        self.expert = ShortestPathExpert()

    def act(self, obs: Observation, state: State, done: np.ndarray) -> tuple[np.ndarray, State]:
        ctx = self.bound()
        actions = self.expert.act_batch(ctx.worlds, ctx.env_idx, ctx.target_types, ctx.x, ctx.z, ctx.yaw)
        return np.asarray(actions, dtype=np.int64), state


class StepPolicy:
    """A batched policy driving one agent through the per-step callable of :mod:`adaptenv.sim.rollout`.

    ``run_episode(world, episode, as_step_policy(policy))`` then works for every policy: at each call
    the adapter scans from the pose (the same kernel as BatchSim), tracks the previous action and
    the recurrent state, and binds a one-agent :class:`PolicyContext` for privileged policies.
    A call with ``step == 0`` starts a new episode.
    """

    def __init__(self, policy: Policy):
        self.policy = policy
        self.name = policy_name(policy)
        self._state: State = None
        self._prev = NO_ACTION
        self._context: PolicyContext | None = None

    def __call__(self, world: NavWorld, episode: Episode, x: float, z: float, yaw: float, collided: bool, step: int) -> int:
        first = step == 0 or self._context is None or self._context.worlds[0] is not world
        if first:
            self._context = PolicyContext.empty([world], 1)
            bind_policy(self.policy, self._context)
            self._state = self.policy.initial_state(1)
            self._prev = NO_ACTION
        ctx = self._context
        ctx.x[0], ctx.z[0], ctx.yaw[0] = x, z, yaw
        ctx.target_types[0] = episode.target_type
        ctx.seeds[0] = int(getattr(episode, "seed", 0) or 0)
        key = ("agents.packed_scan",)
        if key not in world.cache:
            world.cache[key] = (PackedGrids.from_worlds([world]), pack_semantic([world]))
        grids, semantic = world.cache[key]
        depth, classes = scan(grids, semantic, ctx.env_idx, ctx.x, ctx.z, ctx.yaw)
        obs = {"depth": depth, "semantic": classes, "target": np.array([class_id(episode.target_type)]),
               "prev_action": np.array([self._prev]), "collided": np.array([int(bool(collided))])}
        actions, self._state = self.policy.act(obs, self._state, np.array([first]))
        self._prev = int(actions[0])
        return self._prev


class StepFunctionPolicy(PrivilegedMemoryless):
    """A per-step callable of :mod:`adaptenv.sim.rollout` as a batched, privileged :class:`Policy`.

    ``fn(world, episode, x, z, yaw, collided, step) -> action`` is called once per agent and step
    with the agent's world, an :class:`~adaptenv.sim.task.Episode` (target type, start pose, seed)
    and its pose; the adapter counts steps and reads ``collided`` from the observation.
    """

    def __init__(self, fn: Callable[..., int]):
        self.fn = fn
        self.name = str(getattr(fn, "name", type(fn).__name__))
        self._episodes: list[Any] = []
        self._steps = np.zeros(0, dtype=np.int64)

    def act(self, obs: Observation, state: State, done: np.ndarray) -> tuple[np.ndarray, State]:
        ctx = self.bound()
        batch = len(done)
        if len(self._episodes) != batch:
            self._episodes, self._steps = [None] * batch, np.zeros(batch, dtype=np.int64)
        for i in np.flatnonzero(done):
            start = (float(ctx.x[i]), float(ctx.z[i]), float(ctx.yaw[i]))
            self._episodes[i] = Episode(ctx.target_types[i], start, int(ctx.seeds[i]))
            self._steps[i] = 0
        actions = np.array([self.fn(ctx.worlds[int(ctx.env_idx[i])], self._episodes[i], float(ctx.x[i]),
                                    float(ctx.z[i]), float(ctx.yaw[i]), bool(obs["collided"][i]), int(self._steps[i]))
                            for i in range(batch)], dtype=np.int64)
        self._steps += 1
        return actions, state


def as_policy(policy: Policy | Callable[..., int]) -> Policy:
    """The one place per-step callables become batched policies (batched policies pass through)."""
    if isinstance(policy, Policy):
        return policy
    if callable(policy):
        return StepFunctionPolicy(policy)
    raise ConfigError(f"{type(policy).__name__} is not a policy; it needs initial_state(batch) and "
                      "act(obs, state, done), or to be a per-step callable (see docs/agent.md)")


def as_step_policy(policy: Policy | Callable[..., int]) -> Callable[..., int]:
    """Wrap a batched policy for :func:`adaptenv.sim.rollout.run_episode` (per-step callables pass through)."""
    return StepPolicy(policy) if isinstance(policy, Policy) else policy
