"""Gymnasium front ends: ``NavEnv`` (one agent) and ``NavVectorEnv`` (a native batch over BatchSim).

``reset(seed=..., options={"house": ..., "target_type": ..., "start": ...})`` resets to a level
(JaxUED style): the house may be a ``House``, a path to a house JSON, or a compiled ``NavWorld``.
Without a house the env draws one of the houses it was built with (a list, or a house dataset
``FILE.jsonl.gz[:START:STOP]``, see :mod:`adaptenv.scene.dataset`), or, when built with none,
one of a small built-in set of procedural houses (generated once, from ``builtin_seed``).
``terminated`` means the agent issued ``end``; ``truncated`` means it ran out of steps.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from adaptenv.errors import ConfigError, HouseError
from adaptenv.scene.dataset import dataset_houses, parse_dataset_spec
from adaptenv.scene.house import House, load_house
from adaptenv.scene.procedural import generate_houses
from adaptenv.sim import task
from adaptenv.sim.egomap import CROP, MAP_CHANNELS, EgoMap, unpack
from adaptenv.sim.perception import (
    CLASS_OBJECT,
    N_SHAPE,
    SHAPE_MAX,
    check_perception,
    sensor_classes,
)
from adaptenv.sim.spec import ACTIONS, MAX_STEPS, N_ACTIONS, N_RAYS, TARGET_TYPES, n_classes
from adaptenv.sim.trajectory import Pose, Step, Trajectory
from adaptenv.sim.vector import BatchSim, EpisodeSampler
from adaptenv.sim.world import NavWorld, compile_world

FrameRenderer = Callable[[Any, Any, Any], np.ndarray]
"""``renderer(house or None, SceneGeometry, Trajectory) -> (H, W, 3) uint8``: what ``NavEnv.render`` returns."""

HouseLike = House | str | Path | NavWorld
"""A ``House``, a path to a house JSON file, or a compiled ``NavWorld``."""
Houses = Sequence[HouseLike] | str | Path
"""Houses an env is built with: a list of them, or a house dataset spec ``FILE.jsonl.gz[:START:STOP]``."""

BUILTIN_HOUSES = 8
"""Size of the built-in procedural house set used when an env is built without houses."""


def observation_space(map: bool = False, perception: str = "labels") -> spaces.Dict:
    """The single-agent observation space of ``spec``; with ``map``, also the unpacked egocentric map crop; with
    ``perception="shape"``, object classes folded into one and the rays' shape features (``sim.perception``)."""
    k = n_classes()
    shape = check_perception(perception, "perception") == "shape"
    parts = {
        "depth": spaces.Box(0.0, 1.0, (N_RAYS,), np.float32),
        "semantic": spaces.MultiDiscrete(np.full(N_RAYS, CLASS_OBJECT + 1 if shape else k, dtype=np.int64)),
        "target": spaces.Discrete(k),
        "prev_action": spaces.Discrete(N_ACTIONS + 1),
        "collided": spaces.Discrete(2),
    }
    if map:
        parts["map"] = spaces.Box(0, 1, (MAP_CHANNELS, CROP, CROP), np.uint8)
    if shape:
        parts["shape"] = spaces.Box(0.0, SHAPE_MAX, (N_RAYS, N_SHAPE), np.float32)
    return spaces.Dict(parts)


def sensed(obs: dict[str, Any], perception: str, emap: EgoMap | None, first: np.ndarray | None) -> dict[str, Any]:
    """A batched observation as ``perception`` reports it, the map (when ``emap``) marked from it and added.

    Under ``shape`` the object classes fold into ``CLASS_OBJECT`` before the map is marked (so it holds no
    target cells) and the map's target channels stay zero."""
    if perception == "shape":
        obs = {**obs, "semantic": sensor_classes(obs["semantic"])}
    if emap is not None:
        if first is not None:
            emap.update(obs, first)
        crop = map_observation(emap)
        if perception == "shape":
            crop[:, [2, 6]] = 0
        obs["map"] = crop
    return obs


def map_observation(emap: EgoMap) -> np.ndarray:
    """uint8 (B, MAP_CHANNELS, CROP, CROP), values 0/1: ``emap``'s egocentric crops, unpacked."""
    return unpack(emap.crop(), dtype=np.uint8)


def _to_world(item: HouseLike, name: str) -> tuple[NavWorld, House | None]:
    """Compile a House or a house file into a NavWorld; a NavWorld passes through."""
    if isinstance(item, NavWorld):
        return item, None
    if isinstance(item, str | Path):
        house = load_house(item)
        return compile_world(house, name=str(item)), house
    if isinstance(item, House):
        return compile_world(item, name=name), item
    raise ConfigError(f"options['house']: expected a House, a path or a NavWorld, got {type(item).__name__}; "
                      "pass one of those")


def _house_items(houses: Houses) -> list[HouseLike]:
    """The houses an env is built with: a list as given, or the houses of a dataset (an invalid one is an error)."""
    if not isinstance(houses, str | Path):
        return list(houses)
    dataset = parse_dataset_spec(houses)
    if dataset is None:
        raise ConfigError(f"houses: {str(houses)!r} is one path, not a list of houses; pass [path] or a house "
                          "dataset FILE.jsonl.gz[:START:STOP]")
    items = []
    for _, house in dataset_houses(dataset):
        if isinstance(house, HouseError):
            raise house
        items.append(house)
    return items


class _HouseSet:
    """Houses given at construction, compiled lazily (or the built-in procedural set)."""

    def __init__(self, houses: Houses | None, builtin_seed: int) -> None:
        self._items = _house_items(houses) if houses is not None else None
        self._builtin_seed = builtin_seed
        self._compiled: dict[int, tuple[Any, Any]] = {}

    def _ensure_items(self) -> list:
        if self._items is None:
            self._items = list(generate_houses(BUILTIN_HOUSES, self._builtin_seed))
        if not self._items:
            raise ConfigError("houses: the list is empty; pass at least one house or None for the built-in set")
        return self._items

    def __len__(self) -> int:
        return len(self._ensure_items())

    def get(self, k: int) -> tuple[Any, Any]:
        """(NavWorld, House or None) of house k."""
        if k not in self._compiled:
            self._compiled[k] = _to_world(self._ensure_items()[k], name=f"house_{k}")
        return self._compiled[k]


class NavEnv(gymnasium.Env):
    """ObjectNav in one house at a time: the ``spec`` observation, ``spec`` actions, SPOC's reward.

    Args:
        houses: houses to draw from on ``reset()`` without a house option (default: built-in set): a list, or
            a house dataset ``FILE.jsonl.gz[:START:STOP]``.
        target_types: target types to draw from (default: every reachable ObjectNav target type).
        max_steps: episode cap (truncation).
        render_mode: None or ``"rgb_array"`` (a top-down image of the house and the agent).
        builtin_seed: seed of the built-in procedural house set.
        renderer: draws a frame for ``render()``: ``renderer(house, geometry, trajectory) -> (H, W, 3)
            uint8``; the registered id passes :func:`adaptenv.render.topdown.env_frame` (rendering sits
            above the simulator, so the simulator never imports it).
        map: add the key ``"map"``: the egocentric crops of an :class:`~adaptenv.sim.egomap.EgoMap` the
            env builds from the agent's own observations (uint8 (MAP_CHANNELS, CROP, CROP), 0/1).
        perception: ``"labels"`` (each ray's semantic class) or ``"shape"``, the recognising mode: every object
            reads as one class and the key ``"shape"`` (float32 (N_RAYS, 3)) gives the height and footprint sides
            of what each ray hits (:mod:`adaptenv.sim.perception`).

    Example::

        env = gymnasium.make("adaptenv/ObjectNav-v0", houses=["house.json"])
        obs, info = env.reset(seed=0)
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 5}

    def __init__(self, houses: Houses | None = None, target_types: Sequence[str] | None = None,
                 max_steps: int = MAX_STEPS, render_mode: str | None = None, builtin_seed: int = 0,
                 renderer: FrameRenderer | None = None, map: bool = False, perception: str = "labels") -> None:
        if render_mode not in (None, "rgb_array"):
            raise ConfigError(f"render_mode: expected None or 'rgb_array', got {render_mode!r}")
        if render_mode is not None and renderer is None:
            raise ConfigError("render_mode 'rgb_array' needs a renderer; make the env with "
                              "gymnasium.make('adaptenv/ObjectNav-v0', render_mode='rgb_array') or pass "
                              "renderer=adaptenv.render.topdown.env_frame")
        self.renderer = renderer
        self.perception = check_perception(perception, "perception")
        self.observation_space = observation_space(map=map, perception=perception)
        self.action_space = spaces.Discrete(N_ACTIONS)
        self.emap = EgoMap(1) if map else None
        """The map memory behind the ``map`` key (None without the option)."""
        self.render_mode = render_mode
        self.max_steps = int(max_steps)
        self.target_types = tuple(target_types) if target_types is not None else None
        self._houses = _HouseSet(houses, builtin_seed)
        self._sims: dict[int, Any] = {}
        self._adhoc: tuple[Any, Any, Any, Any] | None = None
        """(the options['house'] object, its NavWorld, its House, its BatchSim) of the last level given."""
        self._sim = None
        self._house = None
        self._world = None
        self._start = None
        self._steps: list = []
        self._action = np.zeros(1, dtype=np.int64)

    def _sim_for(self, world, k: int | None):
        """(BatchSim, EpisodeSampler) of construction house k (kept), or of the last option house."""
        if k is None:
            return self._adhoc[3]
        if k not in self._sims:
            self._sims[k] = (self._batch_sim([world]), EpisodeSampler([world], self.target_types))
        return self._sims[k]

    def _batch_sim(self, worlds: list) -> BatchSim:
        return BatchSim(worlds, max_steps=self.max_steps, shapes=self.perception == "shape")

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode; ``options`` may fix ``house``, ``target_type`` and ``start`` (x, z, yaw).

        Unfixed parts are drawn from ``self.np_random`` with ``task.sample_episode``'s distribution.
        """
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"house", "target_type", "start"}
        if unknown:
            raise ConfigError(f"options: unknown keys {sorted(unknown)}; use 'house', 'target_type', 'start'")
        k = None
        if "house" in options:
            item = options["house"]
            # A NavWorld given again reuses its sim; a House or path is recompiled (it may have been edited).
            if self._adhoc is None or self._adhoc[0] is not item or self._adhoc[2] is not None:
                world, house = _to_world(item, name="house")
                sim = (self._batch_sim([world]), EpisodeSampler([world], self.target_types))
                self._adhoc = (item, world, house, sim)
            world, house = self._adhoc[1], self._adhoc[2]
        else:
            k = int(self.np_random.integers(len(self._houses)))
            world, house = self._houses.get(k)
        self._sim, sampler = self._sim_for(world, k)
        target = options.get("target_type")
        if target is not None and "start" in options:  # a fully specified level: nothing to draw
            episode = task.Episode(target_type=target, start=tuple(float(v) for v in options["start"]))
        else:
            episode = sampler.draw(self.np_random, 1, np.zeros(1, dtype=np.int64), target_type=target)[0][0]
            if "start" in options:
                episode = task.Episode(target_type=episode.target_type,
                                       start=tuple(float(v) for v in options["start"]))
        self._world, self._house = world, house
        self._sim.reset([episode], [0])
        self._start, self._steps = self._pose(), []
        return self._obs(first=True), self._info(terminated=False)

    def step(self, action):
        if self._sim is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        sim = self._sim
        before = self._pose() if self.render_mode is not None else None
        frozen = bool(sim.done[0])  # stepped after its end: the simulator ignores the action
        self._action[0] = int(action)
        sim.advance(self._action)
        if before is not None:
            self._steps.append(Step(pose=before, action=ACTIONS[int(action)], moved=bool(sim.moved[0])))
        terminated = bool(sim.last_terminated[0])
        obs = self._obs(first=False, mark=not frozen)
        return obs, float(sim.last_reward[0]), terminated, bool(sim.last_truncated[0]), self._info(terminated)

    def _pose(self):
        return Pose(x=float(self._sim.x[0]), z=float(self._sim.z[0]), yaw=float(self._sim.yaw[0]))

    def _obs(self, first: bool, mark: bool = True) -> dict[str, Any]:
        """The observation; with the map option, ``mark`` updates the map from it first (``first``: a fresh map)."""
        batch = sensed(self._sim.observe(), self.perception, self.emap, np.array([first]) if mark else None)
        obs = {k: v[0] for k, v in batch.items()}
        for k in ("target", "prev_action", "collided"):
            obs[k] = np.int64(obs[k])
        return obs

    def _info(self, terminated: bool) -> dict[str, Any]:
        sim = self._sim
        out = {"success": bool(sim.success[0]), "collisions": int(sim.collisions[0]),
               "geodesic": float(sim.geodesic[0]), "path_length": float(sim.path_length[0]),
               "steps": int(sim.steps[0]), "pose": (float(sim.x[0]), float(sim.z[0]), float(sim.yaw[0])),
               "target_type": sim.target_types[0], "house": self._world.name}
        if terminated:
            out["spl"] = sim.spl(0)
        return out

    @property
    def world(self):
        """The NavWorld of the current episode."""
        return self._world

    def render(self):
        """Top-down RGB image (H, W, 3) uint8 of the house with the episode so far drawn on it."""
        if self.render_mode is None:
            return None
        if self._world is None:
            raise gymnasium.error.ResetNeeded("call reset() before render()")
        return self.renderer(self._house, self._world.geometry, self.trajectory())

    def trajectory(self):
        """The current episode as a :class:`~adaptenv.sim.trajectory.Trajectory` (steps recorded when rendering)."""
        sim, target = self._sim, self._sim.target_types[0]
        inst = self._world.instances_of(target)
        return Trajectory(house=self._world.name, target_type=target, target_ids=[t.object_id for t in inst],
                          target_positions=[tuple(t.center) for t in inst], start=self._start, steps=list(self._steps),
                          final_pose=Pose(x=float(sim.x[0]), z=float(sim.z[0]), yaw=float(sim.yaw[0])))


class NavVectorEnv(VectorEnv):
    """``num_envs`` NavEnv episodes stepped by one BatchSim, with next-step autoreset.

    An agent whose episode ended at step t is given a new episode at step t+1 (its action is
    ignored, the reward is 0 and the observation is the new episode's first), Gymnasium's
    ``AutoresetMode.NEXT_STEP``. ``info`` holds per-agent arrays (``success``, ``spl``,
    ``collisions``, ``geodesic``, ``path_length``, ``steps``, ``x``, ``z``, ``yaw``).

    ``map=True`` adds the key ``"map"`` as in :class:`NavEnv`, one :class:`~adaptenv.sim.egomap.EgoMap`
    over the slots; a slot's map starts afresh with each of its episodes (autoreset included).
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 8, houses: Houses | None = None,
                 target_types: Sequence[str] | None = None, max_steps: int = MAX_STEPS,
                 builtin_seed: int = 0, render_mode: str | None = None, map: bool = False,
                 perception: str = "labels") -> None:
        if num_envs < 1:
            raise ConfigError(f"num_envs: expected a positive count, got {num_envs}")
        self.num_envs = int(num_envs)
        self.max_steps = int(max_steps)
        self.render_mode = render_mode
        self.target_types = tuple(target_types) if target_types is not None else None
        self._houses = _HouseSet(houses, builtin_seed)
        self.perception = check_perception(perception, "perception")
        self.single_observation_space = observation_space(map=map, perception=perception)
        self.emap = EgoMap(self.num_envs) if map else None
        """The slots' map memory behind the ``map`` key (None without the option)."""
        self.single_action_space = spaces.Discrete(N_ACTIONS)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._sim = None
        self._sampler = None
        self._rng = np.random.default_rng()
        self._autoreset = np.zeros(self.num_envs, dtype=np.bool_)

    def _episodes(self, n: int) -> tuple[list, np.ndarray]:
        """Draw n (episode, house index) pairs from the env's generator."""
        return self._sampler.draw(self._rng, n)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start a new episode in every slot; ``seed`` seeds the episode stream."""
        if options:
            raise ConfigError("options: NavVectorEnv.reset takes no options; build it with the houses to use")
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        if self._sim is None:
            worlds = [self._houses.get(k)[0] for k in range(len(self._houses))]
            self._sim = BatchSim(worlds, max_steps=self.max_steps, shapes=self.perception == "shape")
            self._sampler = EpisodeSampler(worlds, self.target_types)
        eps, envs = self._episodes(self.num_envs)
        obs, info = self._sim.reset(eps, envs)
        self._autoreset[:] = False
        return self._with_map(obs, np.ones(self.num_envs, dtype=np.bool_)), info

    def step(self, actions):
        if self._sim is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        obs, reward, terminated, truncated, info = self._sim.step(np.asarray(actions, dtype=np.int64))
        first = self._autoreset.copy()
        again = np.flatnonzero(first)
        if again.size:
            eps, envs = self._episodes(again.size)
            obs = self._sim.reset_at(again, eps, envs)
            for key, value in self._sim.info().items():
                if key != "spl":
                    info[key][again] = value[again]
        self._autoreset = terminated | truncated
        return self._with_map(obs, first), reward, terminated, truncated, info

    def _with_map(self, obs: dict[str, np.ndarray], first: np.ndarray) -> dict[str, np.ndarray]:
        """``obs`` as the env's perception reports it, with the ``map`` key after marking the slots' maps (``first``:
        new episodes), if the option is on."""
        return sensed(obs, self.perception, self.emap, first)

    def close_extras(self, **kwargs) -> None:
        self._sim = None


def make_sync_vector_env(num_envs: int, **kwargs) -> gymnasium.vector.SyncVectorEnv:
    """Gymnasium's SyncVectorEnv over ``num_envs`` NavEnv copies (same kwargs); slower than NavVectorEnv."""
    return gymnasium.vector.SyncVectorEnv([lambda: NavEnv(**kwargs) for _ in range(num_envs)])


__all__ = ["NavEnv", "NavVectorEnv", "TARGET_TYPES", "make_sync_vector_env", "map_observation", "observation_space"]
