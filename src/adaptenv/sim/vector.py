"""BatchSim: B ObjectNav episodes stepped at once, in one compiled loop, houses mixed freely.

Physics (``physics``), the scan (``scan``) and the geodesic-distance lookup behind the reward run
in a single numba kernel over agents, serial or multi-threaded (``prange``; see
``BatchSim.threads_for`` for the choice); per-agent state lives in NumPy arrays. Only the rare
agents that issue ``end`` go through Python, to be judged by ``task.is_success``.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from functools import cache
from pathlib import Path

import numba
import numpy as np

from adaptenv.errors import AdaptenvError
from adaptenv.sim import geodesic, metrics, physics, scan, task
from adaptenv.sim.geodesic import CHUNK_BITS, NOT_NAVIGABLE
from adaptenv.sim.perception import PackedShapes, ray_shapes
from adaptenv.sim.physics import _MOVE_DELTA, _YAW_DELTA, PackedGrids, _move_one
from adaptenv.sim.scan import RAY_COS, RAY_SIN, _scan_one, pack_runs
from adaptenv.sim.spec import (
    AGENT_RADIUS,
    END,
    MAX_RANGE,
    MAX_STEPS,
    N_ACTIONS,
    N_RAYS,
    NO_ACTION,
    ROTATE_LARGE,
    SUCCESS_DISTANCE,
    class_id,
)

STEP_PENALTY = -0.01
"""Reward added at every step (SPOC's RL shaping)."""
SUCCESS_REWARD = 10.0
"""Reward added when ``end`` is issued with a target in sight within SUCCESS_DISTANCE."""
PARALLEL_MIN_BATCH = 64
"""With ``threads=None``, batches smaller than this use the serial kernel (threads cost more than they save)."""


@numba.njit(cache=True)
def _cell_value(vals, rank, start, off, coff, i):
    """Compact field ``vals`` at flat cell i of the house whose ``geodesic.CellIndex`` is packed at
    ``off`` (rank) and ``coff`` (start); inf on cells that are not navigable."""
    r = rank[off + i]
    if r == NOT_NAVIGABLE:
        return math.inf
    return vals[start[coff + (i >> CHUNK_BITS)] + np.int64(r)]


@numba.njit(cache=True, inline="always")
def _field_at(vals, rank, start, off, coff, h, w, x0, z0, res, x, z):
    """A compact distance field at a point: its cell, or (when that is inf) the best 3x3 neighbour
    plus the distance to its centre, as ``geodesic.field_at`` reads it. Inlined: as a called
    function (three array arguments) the step was 4-7% slower (docs/BENCHMARKS.md)."""
    col = int(math.floor((x - x0) / res))
    row = int(math.floor((z - z0) / res))
    if 0 <= row < h and 0 <= col < w:
        v = _cell_value(vals, rank, start, off, coff, row * w + col)
        if v < math.inf:
            return v
    best = math.inf
    for dr in range(-1, 2):
        for dc in range(-1, 2):
            rr, cc = row + dr, col + dc
            if 0 <= rr < h and 0 <= cc < w:
                v = _cell_value(vals, rank, start, off, coff, rr * w + cc)
                if v < math.inf:
                    best = min(best, v + math.hypot(x0 + (cc + 0.5) * res - x, z0 + (rr + 0.5) * res - z))
    return best


def _dependency_stamp() -> str:
    """SHA-256 of the sources the batch kernels inline or take constants from (physics.py, scan.py,
    geodesic.py).

    numba's on-disk cache only checks the kernel's own file; the stamp is a closure variable of the
    kernels, and numba keys cached code on closure contents, so editing a dependency recompiles.
    """
    h = hashlib.sha256()
    for mod in (physics, scan, geodesic):
        h.update(Path(mod.__file__).read_bytes())
    return h.hexdigest()


def _make_agent_step(stamp: str):
    """The per-agent step kernel, keyed in numba's cache by ``stamp`` (its only closure variable)."""

    @numba.njit(cache=True)
    def _agent_step(i, stepping, clear, ids, rtab, rtoffs, dist, rank, start, coffs, offs, hs, ws, x0s, z0s, ress,
                    env, doff, x, z, yaw, steps, collisions, prev_action, path, geo, best, moved, done,
                    actions, radius, yaw_delta, move_delta, ray_cos, ray_sin, max_range, max_steps,
                    reward, terminated, truncated, depth, classes):
        """Agent i: act (when ``stepping`` and not done), book-keep the reward, then look and measure."""
        _ = stamp  # a closure variable, so that numba's cache key covers physics.py, scan.py, geodesic.py
        e = env[i]
        off, h, w, x0, z0, res = offs[e], hs[e], ws[e], x0s[e], z0s[e], ress[e]
        act = stepping and not done[i]
        a = actions[i] if act else 0
        if act:
            nx, nz, nyaw, ok = _move_one(clear, off, h, w, x0, z0, res, x[i], z[i], yaw[i], yaw_delta[a],
                                         move_delta[a], radius)
            x[i], z[i], yaw[i], moved[i] = nx, nz, nyaw, ok
            if ok:
                path[i] += abs(move_delta[a])
            else:
                collisions[i] += 1
            steps[i] += 1
            prev_action[i] = a
        d = _field_at(dist[doff[i]], rank, start, off, coffs[e], h, w, x0, z0, res, x[i], z[i])
        geo[i] = d
        if act:
            gain = 0.0
            if d < math.inf and best[i] < math.inf and best[i] > d:
                gain = best[i] - d
            reward[i] = STEP_PENALTY + gain
            terminated[i] = a == END
            truncated[i] = a != END and steps[i] >= max_steps
            done[i] = terminated[i] or truncated[i]
        else:
            reward[i] = 0.0
            terminated[i] = False
            truncated[i] = False
        if d < best[i]:
            best[i] = d
        _scan_one(ids, rtab, rtoffs[e], off, h, w, x0, z0, res, x[i], z[i], yaw[i], ray_cos, ray_sin, max_range, depth, classes,
                  i)

    return _agent_step


_STAMP = _dependency_stamp()
_agent_step = _make_agent_step(_STAMP)


def _make_loops(stamp: str):
    """Serial and parallel loops of ``_agent_step`` over agents (a global, so that the closure holds
    only ``stamp``: numba's cache key must not include a dispatcher object)."""

    @numba.njit(cache=True)
    def _run_serial(idx, stepping, clear, ids, rtab, rtoffs, dist, rank, start, coffs, offs, hs, ws, x0s, z0s, ress,
                    env, doff, x, z, yaw, steps, collisions, prev_action, path, geo, best, moved, done,
                    actions, radius, yaw_delta, move_delta, ray_cos, ray_sin, max_range, max_steps,
                    reward, terminated, truncated, depth, classes):
        _ = stamp
        for k in range(idx.shape[0]):
            _agent_step(idx[k], stepping, clear, ids, rtab, rtoffs, dist, rank, start, coffs, offs, hs, ws, x0s, z0s, ress,
                        env, doff, x, z, yaw, steps, collisions, prev_action, path, geo, best, moved, done,
                        actions, radius, yaw_delta, move_delta, ray_cos, ray_sin, max_range, max_steps,
                        reward, terminated, truncated, depth, classes)

    @numba.njit(cache=True, parallel=True)
    def _run_parallel(idx, stepping, clear, ids, rtab, rtoffs, dist, rank, start, coffs, offs, hs, ws, x0s, z0s, ress,
                      env, doff, x, z, yaw, steps, collisions, prev_action, path, geo, best, moved, done,
                      actions, radius, yaw_delta, move_delta, ray_cos, ray_sin, max_range, max_steps,
                      reward, terminated, truncated, depth, classes):
        _ = stamp
        for k in numba.prange(idx.shape[0]):
            _agent_step(idx[k], stepping, clear, ids, rtab, rtoffs, dist, rank, start, coffs, offs, hs, ws, x0s, z0s, ress,
                        env, doff, x, z, yaw, steps, collisions, prev_action, path, geo, best, moved, done,
                        actions, radius, yaw_delta, move_delta, ray_cos, ray_sin, max_range, max_steps,
                        reward, terminated, truncated, depth, classes)

    return _run_serial, _run_parallel


_run_serial, _run_parallel = _make_loops(_STAMP)


def _pack_cells(worlds: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The worlds' cell indices in flat arrays: ranks aligned with ``PackedGrids`` offsets, chunk
    starts with house e's at ``chunk_offset[e]`` (one world's arrays are used in place)."""
    index = [geodesic.cell_index(w) for w in worlds]
    sizes = np.array([ix.start.size for ix in index], dtype=np.int64)
    chunk_offset = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    if len(index) == 1:
        return index[0].rank, index[0].start, chunk_offset
    return (np.concatenate([ix.rank for ix in index]), np.concatenate([ix.start for ix in index]), chunk_offset)


@numba.njit(cache=True)
def _any_within(pts, x, z, d2):
    """Whether some point of ``pts`` (P, 2) lies within squared distance d2 of (x, z)."""
    for p in range(pts.shape[0]):  # noqa: SIM110  (numba compiles no generator expressions)
        if (pts[p, 0] - x) ** 2 + (pts[p, 1] - z) ** 2 <= d2:
            return True
    return False


@cache
def _class_of(target_type: str) -> int:
    """``spec.class_id`` with a readable error for unknown types (memoized: it is on the reset path)."""
    try:
        return class_id(target_type)
    except ValueError:
        raise ValueError(f"unknown target type {target_type!r}; use an object type of the asset catalog") from None


class BatchSim:
    """B ObjectNav agents in a list of houses, stepped together; no auto-reset.

    Reward (SPOC's RL shaping), per step of an active agent::

        r = -0.01 + max(0, best - d) + 10 * success

    where ``d`` is the geodesic distance to the target's success region after the action
    (``geodesic.distance_field`` of the agent's house and target type, computed once per pair and
    read at the agent's cell as ``geodesic.geodesic_distance`` reads it) and ``best`` the smallest ``d`` seen so
    far in the episode (so moving back and forth earns nothing; an unreachable start, d = inf, earns
    no shaping). ``end`` terminates the episode (success judged by ``task.is_success``);
    reaching ``max_steps`` truncates it. A finished agent is frozen (its actions are ignored, its
    reward is 0 and it reports terminated/truncated only once) until the caller gives it a new
    episode with :meth:`reset_at`.

    Pose arrays ``x``, ``z``, ``yaw`` (float64, metres/degrees) and ``moved`` are public and
    updated in place each step, so a caller can record trajectories by copying them.

    Example::

        sim = BatchSim(worlds)
        obs, info = sim.reset(episodes, env_idx)
        obs, reward, terminated, truncated, info = sim.step(actions)
        done = np.flatnonzero(terminated | truncated)
        sim.reset_at(done, [new_episode(i) for i in done])
    """

    def __init__(self, worlds: Sequence, *, max_steps: int = MAX_STEPS, radius: float = AGENT_RADIUS,
                 max_range: float = MAX_RANGE, threads: int | None = None, parallel: bool | None = None,
                 shapes: bool = False) -> None:
        """``shapes`` adds the recognising mode's ``shape`` key to every observation (``perception``). ``threads``: 1 runs the serial kernel, n >= 2 the multi-threaded one on n numba threads, None
        chooses per call (:meth:`threads_for`). ``parallel`` is the older spelling: False is
        ``threads=1``, True the multi-threaded kernel on numba's current thread count."""
        if not worlds:
            raise ValueError("BatchSim needs at least one NavWorld")
        if threads is not None and not 1 <= int(threads) <= numba.config.NUMBA_NUM_THREADS:
            raise ValueError(f"threads must be None or in [1, {numba.config.NUMBA_NUM_THREADS}] (numba's "
                             f"NUMBA_NUM_THREADS), got {threads}")
        self.worlds = list(worlds)
        self.grids = PackedGrids.from_worlds(self.worlds)
        self.runs = pack_runs(self.worlds)
        """The scan's free rectangles (``scan.pack_runs``), aligned with ``grids``."""
        self.shapes = PackedShapes.from_worlds(self.worlds) if shapes else None
        """Cell labels and object shapes behind the ``shape`` observation (``perception``), aligned with ``grids``;
        None when the observation has no ``shape`` key."""
        self.max_steps = int(max_steps)
        self.radius = float(radius)
        self.max_range = float(max_range)
        self.threads = None if threads is None else int(threads)
        """Threads of the kernel: 1 (serial), n >= 2 (multi-threaded), or None (auto, see :meth:`threads_for`)."""
        self.parallel = parallel
        """Older spelling of ``threads`` (used only when ``threads`` is None): True, False or None."""
        self._rank, self._start, self._chunk_offset = _pack_cells(self.worlds)
        """The worlds' ``geodesic.CellIndex`` packed like ``grids`` (one world's used in place)."""
        self._fields = numba.typed.List.empty_list(numba.types.float32[::1])
        self._field_offset: dict[tuple[int, str], int] = {}
        self._targets: dict[tuple[int, str], np.ndarray] = {}
        self._allocate(0)

    # -- state ---------------------------------------------------------------------------------

    def _allocate(self, n: int) -> None:
        self.num_agents = n
        self.env = np.zeros(n, dtype=np.int64)
        self.x = np.zeros(n, dtype=np.float64)
        self.z = np.zeros(n, dtype=np.float64)
        self.yaw = np.zeros(n, dtype=np.float64)
        self.moved = np.ones(n, dtype=np.bool_)
        self.steps = np.zeros(n, dtype=np.int64)
        self.prev_action = np.full(n, NO_ACTION, dtype=np.int64)
        self.collisions = np.zeros(n, dtype=np.int64)
        self.path_length = np.zeros(n, dtype=np.float64)
        self.geodesic = np.full(n, np.inf, dtype=np.float64)
        self.best = np.full(n, np.inf, dtype=np.float64)
        self.start_geodesic = np.full(n, np.inf, dtype=np.float64)
        self.target = np.zeros(n, dtype=np.int64)
        self.success = np.zeros(n, dtype=np.bool_)
        self.done = np.ones(n, dtype=np.bool_)
        self.target_types: list[str] = [""] * n
        self._doff = np.zeros(n, dtype=np.int64)
        self._depth = np.ones((n, N_RAYS), dtype=np.float32)
        self._classes = np.zeros((n, N_RAYS), dtype=np.int64)
        self._reward = np.zeros(n, dtype=np.float64)
        self._terminated = np.zeros(n, dtype=np.bool_)
        self._truncated = np.zeros(n, dtype=np.bool_)
        self._all = np.arange(n, dtype=np.int64)
        self._no_actions = np.zeros(n, dtype=np.int64)

    def _distance_offset(self, e: int, target_type: str) -> int:
        """Index of the (house, target) distance field in ``self._fields``; fetched on first use.

        The fields are ``geodesic.compact_field``'s cached arrays themselves (values on navigable
        cells only, read through the packed cell index), not copies.
        """
        key = (e, target_type)
        off = self._field_offset.get(key)
        if off is None:
            world = self.worlds[e]
            field = geodesic.compact_field(world, target_type)
            if field.dtype != np.float32 or field.shape != (geodesic.cell_index(world).cells,):
                raise ValueError(f"compact distance field of {target_type!r} has {field.dtype} shape "
                                 f"{field.shape}, expected float32 over the world's navigable cells")
            off = self._field_offset[key] = len(self._fields)
            self._fields.append(np.ascontiguousarray(field))
            self._targets[key] = np.asarray(task.target_points(world, target_type).points, dtype=np.float64)
        return off

    def reset(self, episodes: Sequence, env_idx: Sequence[int] | np.ndarray | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """Start one episode per agent (B = len(episodes)); ``env_idx[i]`` is its house (default i % n_houses)."""
        self._allocate(len(episodes))
        if env_idx is None:
            env_idx = np.arange(len(episodes)) % len(self.worlds)
        self.reset_at(np.arange(len(episodes)), episodes, env_idx)
        return self.observe(), self.info()

    def reset_at(self, indices: Sequence[int] | np.ndarray, episodes: Sequence,
                 env_idx: Sequence[int] | np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Give agents ``indices`` new episodes (in houses ``env_idx``, default: their current ones).

        Returns the whole batch's observation, with the fresh first observations in those slots.
        """
        idx = np.asarray(indices, dtype=np.int64).reshape(-1)
        if len(episodes) != idx.size:
            raise ValueError(f"reset_at got {idx.size} indices but {len(episodes)} episodes")
        if idx.size == 0:
            return self.observe()
        envs = self.env[idx] if env_idx is None else np.asarray(env_idx, dtype=np.int64).reshape(-1)
        if envs.size != idx.size or envs.min() < 0 or envs.max() >= len(self.worlds):
            raise ValueError(f"env_idx must hold {idx.size} house indices in [0, {len(self.worlds)})")
        types = [ep.target_type for ep in episodes]
        starts = np.array([ep.start for ep in episodes], dtype=np.float64).reshape(-1, 3)
        self.env[idx] = envs
        self.x[idx], self.z[idx], self.yaw[idx] = starts[:, 0], starts[:, 1], starts[:, 2] % 360.0
        self.target[idx] = [_class_of(t) for t in types]
        self._doff[idx] = [self._distance_offset(e, t) for e, t in zip(envs.tolist(), types, strict=True)]
        for i, t in zip(idx.tolist(), types, strict=True):
            self.target_types[i] = t
        self.steps[idx] = 0
        self.prev_action[idx] = NO_ACTION
        self.moved[idx] = True
        self.collisions[idx] = 0
        self.path_length[idx] = 0.0
        self.success[idx] = False
        self.done[idx] = False
        self.best[idx] = np.inf
        self._run(idx, self._no_actions, stepping=False)
        self.start_geodesic[idx] = self.geodesic[idx]
        return self.observe()

    # -- stepping ------------------------------------------------------------------------------

    def _run(self, idx: np.ndarray, actions: np.ndarray, stepping: bool) -> None:
        """The compiled kernel over agents ``idx``: act (if stepping), reward, distance, scan."""
        threads = self.threads_for(idx.shape[0])
        forced_parallel = self.threads is None and self.parallel is True  # the older spelling's meaning
        if threads == 1 and not forced_parallel:
            self._kernel(_run_serial, idx, actions, stepping)
            return
        previous = numba.get_num_threads()
        if threads != previous:
            numba.set_num_threads(threads)
        try:
            self._kernel(_run_parallel, idx, actions, stepping)
        finally:
            if threads != previous:
                numba.set_num_threads(previous)

    def threads_for(self, batch: int) -> int:
        """Threads the kernel uses for ``batch`` agents (1 = the serial kernel).

        ``threads`` when set; otherwise 1 for batches under PARALLEL_MIN_BATCH or when numba has a
        single thread (``numba.get_num_threads()``), else numba's thread count. The multi-threaded
        kernel loses to the serial one when other processes keep the other cores busy: on a shared
        machine pass ``threads=1`` (or set ``NUMBA_NUM_THREADS=1``). Results do not depend on it.
        """
        if self.threads is not None:
            return self.threads
        if self.parallel is not None:
            return numba.get_num_threads() if self.parallel else 1
        if batch < PARALLEL_MIN_BATCH:
            return 1
        return numba.get_num_threads()

    def _kernel(self, kernel, idx: np.ndarray, actions: np.ndarray, stepping: bool) -> None:
        """Call ``kernel`` (``_run_serial`` or ``_run_parallel``) on the packed state."""
        g = self.grids
        kernel(idx, stepping, g.clearance, self.runs.ids, self.runs.table, self.runs.offset,
               self._fields, self._rank, self._start,
               self._chunk_offset, g.offset, g.height, g.width,
               g.x0, g.z0, g.resolution, self.env, self._doff, self.x, self.z, self.yaw, self.steps, self.collisions,
               self.prev_action, self.path_length, self.geodesic, self.best, self.moved, self.done,
               actions, self.radius, _YAW_DELTA, _MOVE_DELTA, RAY_COS, RAY_SIN, self.max_range, self.max_steps,
               self._reward, self._terminated, self._truncated, self._depth, self._classes)

    def advance(self, actions: np.ndarray) -> None:
        """Step the state in place, leaving reward/terminated/truncated in ``last_*`` (no copies)."""
        actions = np.asarray(actions, dtype=np.int64).reshape(-1)
        if actions.shape[0] != self.num_agents:
            raise ValueError(f"step expected {self.num_agents} actions, got {actions.shape[0]}")
        if actions.size and (actions.min() < 0 or actions.max() >= N_ACTIONS):
            raise ValueError(f"actions must be in [0, {N_ACTIONS}), got {actions.min()}..{actions.max()}")
        self._run(self._all, actions, stepping=True)
        for i in np.flatnonzero(self._terminated).tolist():
            if self._judge(i):
                self.success[i] = True
                self._reward[i] += SUCCESS_REWARD

    @property
    def last_reward(self) -> np.ndarray:
        return self._reward

    @property
    def last_terminated(self) -> np.ndarray:
        return self._terminated

    @property
    def last_truncated(self) -> np.ndarray:
        return self._truncated

    def step(self, actions: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray,
                                                 dict[str, np.ndarray]]:
        """Advance every active agent by one action: (obs, reward, terminated, truncated, info), batched."""
        self.advance(actions)
        return (self.observe(), self._reward.copy(), self._terminated.copy(), self._truncated.copy(),
                self.info(self._terminated))

    def _judge(self, i: int) -> bool:
        """``task.is_success`` for agent i, skipped when no target sample point is within reach."""
        e, target_type = int(self.env[i]), self.target_types[i]
        pts = self._targets[(e, target_type)]
        if pts.shape[0] == 0:
            return False
        if not _any_within(pts, float(self.x[i]), float(self.z[i]), SUCCESS_DISTANCE ** 2):
            return False  # exactly is_success's first test (every point farther than the success distance)
        return bool(task.is_success(self.worlds[e], float(self.x[i]), float(self.z[i]), float(self.yaw[i]),
                                    target_type))

    # -- views ---------------------------------------------------------------------------------

    def observe(self) -> dict[str, np.ndarray]:
        """The current observation of every agent (fresh arrays, leading batch dimension): the labelled scan and,
        under ``shape`` (with ``shapes=True``) what the recognising mode perceives of the objects hit
        (``perception.ray_shapes``)."""
        obs = {"depth": self._depth.copy(), "semantic": self._classes.copy(), "target": self.target.copy(),
               "prev_action": self.prev_action.copy(), "collided": (~self.moved).astype(np.int64)}
        if self.shapes is not None:
            obs["shape"] = ray_shapes(self.shapes, self.grids, self.env, self.x, self.z, self.yaw, self._depth,
                                      self.max_range)
        return obs

    def info(self, ended: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Per-agent diagnostics: success, SPL (NaN except where ``ended``), collisions, geodesic
        distance, path length, steps and pose."""
        spl = np.full(self.num_agents, np.nan)
        if ended is not None and ended.any():
            spl[ended] = [self.spl(i) for i in np.flatnonzero(ended).tolist()]
        return {"success": self.success.copy(), "spl": spl, "collisions": self.collisions.copy(),
                "geodesic": self.geodesic.copy(), "path_length": self.path_length.copy(),
                "steps": self.steps.copy(), "x": self.x.copy(), "z": self.z.copy(), "yaw": self.yaw.copy()}

    def spl(self, i: int) -> float:
        """SPL of agent i's episode so far (``metrics.spl``; optimal = geodesic distance from the start)."""
        return metrics.spl(bool(self.success[i]), float(self.start_geodesic[i]), float(self.path_length[i]))

    @property
    def nbytes(self) -> int:
        """Memory of the arrays BatchSim holds that no world holds too: packed rasters and cell
        indices of several worlds (one world's are used in place) and distance fields no longer in
        their world's cache."""
        held = {id(a) for w in self.worlds for a in (w.grid.clearance, *w.cached_arrays())}
        arrays = [self.grids.clearance, self.runs.ids, self.runs.table, self._rank, self._start, *self._fields]
        if self.shapes is not None:
            arrays += [self.shapes.labels, self.shapes.table]
        return int(sum(a.nbytes for a in arrays if id(a) not in held and id(a.base) not in held))


class EpisodeSampler:
    """Draws ObjectNav episodes for many slots quickly (for auto-reset and benchmarks).

    Same distribution as ``task.sample_episode`` (a house uniformly, a target type uniformly among
    ``task.available_targets`` or the given types, the start at the centre of an enterable cell drawn
    uniformly among those with finite positive geodesic distance, yaw a multiple of 30 degrees), but the
    candidate cells are computed once per (house, target) pair, so a draw costs microseconds.

    A world with ``task_targets`` draws only those types (where available).

    ``min_distance`` > 0 keeps only starts at least that geodesic distance from the target (training on
    the long episodes the hard suites test); a (house, target) pair with no such start keeps its
    farthest quarter of starts instead, so small houses still contribute episodes.
    """

    def __init__(self, worlds: Sequence, target_types: Sequence[str] | None = None, min_distance: float = 0.0) -> None:
        self.worlds = list(worlds)
        self.target_types = tuple(target_types) if target_types is not None else None
        self.min_distance = float(min_distance)
        self._types: dict[int, list[str]] = {}
        self._cells: dict[tuple[int, str], np.ndarray] = {}

    def types_of(self, e: int) -> list[str]:
        """Target types episodes in house e may ask for."""
        if e not in self._types:
            world = self.worlds[e]
            avail = task.available_targets(world)
            types = avail if self.target_types is None else [t for t in self.target_types if t in avail]
            types = [t for t in world.task_targets if t in types] or types
            if not types:
                wanted = "any ObjectNav target" if self.target_types is None else f"any of {list(self.target_types)}"
                raise AdaptenvError(f"{world.name}: no episode can be drawn ({wanted} must be present and "
                                         "reachable); pick other target types or houses")
            self._types[e] = types
        return self._types[e]

    def _candidates(self, e: int, target_type: str) -> np.ndarray:
        key = (e, target_type)
        if key not in self._cells:
            field = geodesic.distance_field(self.worlds[e], target_type)
            cells = np.flatnonzero(np.isfinite(field) & (field > 0) & geodesic.enterable(self.worlds[e]))
            if cells.size == 0:
                raise AdaptenvError(f"{self.worlds[e].name}: the {target_type} cannot be reached from any free "
                                    "floor; choose other target types or houses")
            if self.min_distance > 0:
                d = field.reshape(-1)[cells]
                far = d >= self.min_distance
                cells = cells[far] if far.any() else cells[d >= np.quantile(d, 0.75)]
            self._cells[key] = cells
        return self._cells[key]

    def draw(self, rng: np.random.Generator, n: int, env_idx: np.ndarray | None = None,
             target_type: str | None = None) -> tuple[list, np.ndarray]:
        """``n`` episodes and their house indices (drawn uniformly unless ``env_idx`` is given).

        ``target_type`` fixes the target (it must be reachable in the chosen houses).
        """
        envs = rng.integers(len(self.worlds), size=n) if env_idx is None else np.asarray(env_idx, dtype=np.int64)
        envs = envs.reshape(-1)
        pick = rng.random((envs.size, 2)).tolist()
        yaws = (rng.integers(round(360 / ROTATE_LARGE), size=envs.size) * ROTATE_LARGE).tolist()
        episodes = []
        for e, (p_type, p_cell), yaw in zip(envs.tolist(), pick, yaws, strict=True):
            if target_type is None:
                types = self.types_of(e)
                target = types[min(int(p_type * len(types)), len(types) - 1)]
            else:
                target = target_type
            cells = self._candidates(e, target)
            g = self.worlds[e].grid
            row, col = divmod(int(cells[min(int(p_cell * cells.size), cells.size - 1)]), g.blocked.shape[1])
            x, z = g.x0 + (col + 0.5) * g.resolution, g.z0 + (row + 0.5) * g.resolution
            episodes.append(task.Episode(target, (float(x), float(z), float(yaw))))
        return episodes, envs
