"""Who labels DAgger's states: the shortest-path expert, a searching explorer, or a mix of expert and explorer.

A teacher is asked for one label per agent at every collection step, with the observations the
student sees and the ``first`` mask of new episodes (the explorer keeps a map per episode, so it
must see every step). ``TrainConfig.teacher`` picks one:

- ``expert``: :class:`~adaptenv.sim.expert.ShortestPathExpert` (knows where the target is);
- ``explorer``: :class:`~adaptenv.agents.explorer.ExplorerPolicy` (searches; knows only its pose and
  the map it has seen);
- ``map-explorer``: :class:`~adaptenv.agents.map_explorer.MapExplorerPolicy` (searches on the EgoMap
  built from the student's own observations; no privileged information);
- ``mix``: each episode is labelled by the explorer with probability ``teacher_mix`` (drawn at the
  episode's start from the run's seed), by the expert otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal, Protocol

import numpy as np

from adaptenv.agents.explorer import ExplorerPolicy
from adaptenv.agents.map_explorer import MapExplorerPolicy
from adaptenv.agents.policy import Observation, PolicyContext
from adaptenv.errors import ConfigError
from adaptenv.sim.egomap import EgoMap
from adaptenv.sim.expert import ShortestPathExpert

TeacherKind = Literal["expert", "explorer", "map-explorer", "mix"]
TEACHERS = ("expert", "explorer", "map-explorer", "mix")


class Teacher(Protocol):
    """Labels a batch of states (see the module docstring)."""

    def label(self, obs: Observation, first: np.ndarray) -> np.ndarray:
        """int64 (B,) actions for the simulator's current agents."""
        ...


class _SimTeacher:
    """Shared part: keeps a PolicyContext pointing at a BatchSim's current arrays."""

    def __init__(self, sim: Any):
        self.sim = sim
        self.ctx = PolicyContext.empty(sim.worlds, len(sim.x))

    def _sync(self) -> PolicyContext:
        sim, ctx = self.sim, self.ctx
        ctx.worlds, ctx.env_idx, ctx.target_types = sim.worlds, sim.env, sim.target_types
        ctx.x, ctx.z, ctx.yaw = sim.x, sim.z, sim.yaw
        return ctx


class ExpertTeacher(_SimTeacher):
    """The shortest-path expert's action at every agent's pose."""

    def __init__(self, sim: Any):
        super().__init__(sim)
        self.expert = ShortestPathExpert()

    def label(self, obs: Observation, first: np.ndarray) -> np.ndarray:
        ctx = self._sync()
        return np.asarray(self.expert.act_batch(ctx.worlds, ctx.env_idx, ctx.target_types, ctx.x, ctx.z, ctx.yaw),
                          dtype=np.int64)


class ExplorerTeacher(_SimTeacher):
    """The explorer's action (it updates its map from ``obs`` at every call)."""

    def __init__(self, sim: Any):
        super().__init__(sim)
        self.explorer = ExplorerPolicy()
        self.explorer.bind(self.ctx)

    def label(self, obs: Observation, first: np.ndarray) -> np.ndarray:
        self._sync()
        actions, _ = self.explorer.act(obs, None, np.asarray(first, dtype=bool))
        return actions


class MapExplorerTeacher:
    """The map explorer's action on the student's observations: on its own EgoMap kept from ``obs`` and ``first``,
    or on ``emap``, the student's map, which its MapObserver has already updated with them (the same map)."""

    def __init__(self, sim: Any, emap: EgoMap | None = None):
        self.explorer = MapExplorerPolicy()
        self.emap = emap

    def label(self, obs: Observation, first: np.ndarray) -> np.ndarray:
        done = np.asarray(first, dtype=bool)
        if self.emap is not None:
            return self.explorer.act_on(self.emap, obs, done)
        actions, _ = self.explorer.act(obs, None, done)
        return actions


class MixTeacher:
    """Per episode, the explorer with probability ``p`` and the expert otherwise (both always run, so
    the explorer's map stays current whichever labels an episode)."""

    def __init__(self, sim: Any, p: float, seed: int):
        self.expert, self.explorer = ExpertTeacher(sim), ExplorerTeacher(sim)
        self.p = float(p)
        self.rng = np.random.default_rng([seed, 7_207])
        self.use_explorer = np.zeros(len(sim.x), dtype=bool)

    def label(self, obs: Observation, first: np.ndarray) -> np.ndarray:
        first = np.asarray(first, dtype=bool)
        self.use_explorer[first] = self.rng.random(int(first.sum())) < self.p
        a, b = self.expert.label(obs, first), self.explorer.label(obs, first)
        return np.where(self.use_explorer, b, a)


def make_teacher(kind: str, sim: Any, *, mix: float = 0.5, seed: int = 0, emap: EgoMap | None = None) -> Teacher:
    """The teacher named by ``--teacher`` for a BatchSim; ConfigError for an unknown name.

    ``emap``: the student's map, updated before each label; the map explorer plans on it instead of keeping its own."""
    if kind == "expert":
        return ExpertTeacher(sim)
    if kind == "explorer":
        return ExplorerTeacher(sim)
    if kind == "map-explorer":
        return MapExplorerTeacher(sim, emap)
    if kind == "mix":
        return MixTeacher(sim, mix, seed)
    raise ConfigError(f"--teacher {kind!r}: unknown teacher; choose one of {', '.join(TEACHERS)}")


@dataclass(frozen=True)
class LabelAgreement:
    """How a network's action distribution matches a teacher's labels on a set of visited states."""

    cross_entropy: float
    accuracy: float
    episodes: int
    """Episodes finished while collecting (the states' trajectories)."""
    label_share: list[float]
    """Fraction of the states with each action as the label (``spec.ACTIONS`` order)."""
    argmax_share: list[float]
    """Fraction of the states with each action as the network's most likely one."""


def label_agreement(net: Any, worlds: list, beta: float, *, teacher: str = "expert", envs: int = 64,
                    steps: int = 256, seed: int = 0) -> LabelAgreement:
    """The network's agreement with ``teacher`` on states reached when the teacher acts with probability ``beta``.

    beta 1 gives the teacher's own trajectories, 0 the network's (``choose_actions`` with sampled
    motions, as NeuralPolicy acts): the gap between the two says how far DAgger's data is from
    the states the policy meets (docs/agent.md, "PPO").
    """
    import torch
    import torch.nn.functional as F

    from adaptenv.agents.network import MapObserver, choose_actions, obs_to_tensors, observe
    from adaptenv.sim.spec import N_ACTIONS
    from adaptenv.sim.vector import BatchSim, EpisodeSampler

    rng = np.random.default_rng(seed)
    sampler = EpisodeSampler(worlds)
    sim = BatchSim(worlds, max_steps=300, shapes=bool(net.config.shape_features))
    observer = MapObserver.of(net, envs)
    labeller = make_teacher(teacher, sim, seed=seed, emap=observer.emap if observer else None)
    obs, _ = sim.reset(*sampler.draw(rng, envs))
    first, h = np.ones(envs, dtype=bool), net.initial_state(envs)
    logits_all, labels_all, episodes = [], [], 0
    for _ in range(steps):
        obs = observe(observer, obs, first)
        labels = labeller.label(obs, first)
        with torch.no_grad():
            logits, h = net.step(obs_to_tensors(obs), torch.from_numpy(first), h)
        actions = np.where(rng.random(envs) < beta, labels, choose_actions(logits, rng.random(envs)))
        logits_all.append(logits)
        labels_all.append(torch.from_numpy(labels))
        obs, _, terminated, truncated, _ = sim.step(actions)
        done = np.flatnonzero(terminated | truncated)
        first = np.zeros(envs, dtype=bool)
        if done.size:
            episodes += done.size
            obs = sim.reset_at(done, *sampler.draw(rng, done.size))
            first[done] = True
    logits, labels = torch.cat(logits_all), torch.cat(labels_all)
    argmax = logits.argmax(-1)
    return LabelAgreement(cross_entropy=F.cross_entropy(logits, labels).item(),
                          accuracy=(argmax == labels).float().mean().item(), episodes=episodes,
                          label_share=_shares(labels.numpy(), N_ACTIONS), argmax_share=_shares(argmax.numpy(), N_ACTIONS))


def _shares(actions: np.ndarray, n: int) -> list[float]:
    """Fraction of each of ``n`` actions in ``actions``."""
    return (np.bincount(actions, minlength=n) / len(actions)).tolist()
