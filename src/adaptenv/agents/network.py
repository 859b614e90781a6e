"""The neural navigation policy: scan encoder, target/action embeddings, a GRU core, action logits.

Per ray the encoder sees a learned embedding of the semantic class, the depth, and a flag saying
whether the ray hits the target type; two 1-D convolutions over the 32 rays (ray order is the
horizontal angle, so convolution is translation in view angle) feed a linear layer. The target
type, previous action and collided flag are embedded and concatenated. A GRU cell carries memory;
the head reads the memory and the current features. About 0.4 M parameters: fast on a CPU.

With ``NetConfig.map_channels`` > 0 the network also reads the map memory the agent builds itself
(:mod:`adaptenv.sim.egomap`): the packed egocentric crops (observation key ``map``) go through a
small 2-D CNN beside the scan encoder. :class:`MapObserver` keeps the map and adds the key, and
:class:`NeuralPolicy` carries it in its state, so every runner drives such a policy unchanged.
"""

from __future__ import annotations

import ctypes
import functools
import os
import platform
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from adaptenv.sim.egomap import CROP, MAP_CHANNELS, EgoMap
from adaptenv.sim.perception import CLASS_OBJECT, MAP_TARGET_MASK, N_SHAPE
from adaptenv.sim.spec import END, N_ACTIONS, N_RAYS, n_classes


@dataclass(frozen=True)
class NetConfig:
    """Architecture sizes; saved in every checkpoint so it can be rebuilt."""

    n_rays: int = N_RAYS
    n_classes: int = 0
    """Number of semantic classes (0 means ``adaptenv.sim.spec.n_classes()``)."""
    n_actions: int = N_ACTIONS
    class_dim: int = 16
    conv_channels: int = 32
    target_dim: int = 32
    action_dim: int = 16
    feature_dim: int = 128
    hidden: int = 256
    map_channels: int = 0
    """Channels of the map observation (0: the network reads no map; ``egomap.MAP_CHANNELS`` with one)."""
    map_crop: int = CROP
    """Pixels on a side of the map observation's windows."""
    map_dim: int = 128
    """Size of the map encoder's output."""
    shape_features: int = 0
    """Per-ray shape features read in place of object classes: 0 (``labels`` perception: told each object's class)
    or ``perception.N_SHAPE`` (``shape``: the recognising mode, where every object reads as one class)."""

    @property
    def perception(self) -> str:
        """``labels`` or ``shape`` (``adaptenv.sim.perception``)."""
        return "shape" if self.shape_features else "labels"

    def resolved(self) -> NetConfig:
        """This config with ``n_classes`` filled in from the simulator spec."""
        if self.n_classes:
            return self
        return NetConfig(**{**asdict(self), "n_classes": n_classes()})

    @classmethod
    def of(cls, settings: object) -> NetConfig:
        """The sizes named by a run config (``hidden``, ``feature_dim``, ``conv_channels``, ``map_dim``) for fresh
        weights."""
        return cls(hidden=settings.hidden, feature_dim=settings.feature_dim,  # type: ignore[attr-defined]
                   conv_channels=settings.conv_channels,  # type: ignore[attr-defined]
                   map_channels=MAP_CHANNELS if getattr(settings, "map", False) else 0,
                   map_dim=settings.map_dim,  # type: ignore[attr-defined]
                   shape_features=N_SHAPE if getattr(settings, "perception", "labels") == "shape" else 0)


def obs_to_tensors(obs: dict[str, np.ndarray], device: torch.device | str = "cpu") -> dict[str, torch.Tensor]:
    """Convert a (batched) numpy observation to tensors: depth float32, the packed map uint8, the rest int64."""
    out = {
        "depth": torch.as_tensor(np.asarray(obs["depth"], dtype=np.float32), device=device),
        "semantic": torch.as_tensor(np.asarray(obs["semantic"], dtype=np.int64), device=device),
        "target": torch.as_tensor(np.asarray(obs["target"], dtype=np.int64), device=device),
        "prev_action": torch.as_tensor(np.asarray(obs["prev_action"], dtype=np.int64), device=device),
        "collided": torch.as_tensor(np.asarray(obs["collided"], dtype=np.int64), device=device),
    }
    if "map" in obs:
        out["map"] = torch.as_tensor(np.asarray(obs["map"], dtype=np.uint8), device=device)
    if "shape" in obs:
        out["shape"] = torch.as_tensor(np.asarray(obs["shape"], dtype=np.float32), device=device)
    return out


class MapObserver:
    """Adds the packed map crop (key ``map``) to each batched observation, from an :class:`EgoMap` it updates."""

    def __init__(self, batch: int, crop: int = CROP):
        self.emap = EgoMap(batch, crop=crop)

    @classmethod
    def of(cls, net: NavNet, batch: int) -> MapObserver | None:
        """The observer a network needs for ``batch`` agents (None when it reads no map)."""
        return cls(batch, net.config.map_crop) if net.config.map_channels else None

    def __call__(self, obs: dict[str, np.ndarray], first: np.ndarray) -> dict[str, np.ndarray]:
        """``obs`` with ``map`` added after marking it; ``first`` starts fresh maps."""
        self.emap.update(obs, np.asarray(first, dtype=bool))
        return {**obs, "map": self.emap.crop()}


def observe(observer: MapObserver | None, obs: dict[str, np.ndarray], first: np.ndarray) -> dict[str, np.ndarray]:
    """``observer(obs, first)``, or ``obs`` unchanged for a network without a map or when it holds one already."""
    return obs if observer is None or "map" in obs else observer(obs, first)


def unpack_map(packed: torch.Tensor, channels: int, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """0/1 values of ``dtype`` (N, channels, S, S) in channels-last memory from packed crops (N, S, S) uint8 (bit k is
    channel k)."""
    table = ((torch.arange(256)[:, None] >> torch.arange(channels)) & 1).to(dtype)
    return torch.nn.functional.embedding(packed.int(), table).permute(0, 3, 1, 2)


RAY_TARGET_DIM = 8
"""Size of the target embedding every ray reads in the recognising mode (``NetConfig.shape_features`` > 0)."""


class NavNet(nn.Module):
    """Recurrent ObjectNav policy network over the ``adaptenv.sim.spec`` observation."""

    @staticmethod
    def _shape_channels(cfg: NetConfig) -> int:
        """Extra input channels of each ray in the recognising mode: its shape and the target's embedding."""
        return cfg.shape_features + RAY_TARGET_DIM if cfg.shape_features else 0

    def __init__(self, config: NetConfig | None = None):
        super().__init__()
        cfg = (config or NetConfig()).resolved()
        self.config = cfg
        c = cfg.conv_channels
        self.class_embed = nn.Embedding(cfg.n_classes, cfg.class_dim)
        # the recognising mode: every ray also reads the target type, so the first convolution can match each
        # ray's shape against the type asked for (the labelled mode gets that match as the is-target flag)
        self.ray_target_embed = nn.Embedding(cfg.n_classes, RAY_TARGET_DIM) if cfg.shape_features else None
        self.conv = nn.Sequential(
            nn.Conv1d(cfg.class_dim + 2 + self._shape_channels(cfg), c, kernel_size=5, padding=2), nn.ReLU(),
            nn.Conv1d(c, c, kernel_size=5, stride=2, padding=2), nn.ReLU(),
        )
        conv_out = c * ((cfg.n_rays + 1) // 2)
        self.target_embed = nn.Embedding(cfg.n_classes, cfg.target_dim)
        self.action_embed = nn.Embedding(cfg.n_actions + 1, cfg.action_dim)
        self.collided_embed = nn.Embedding(2, 8)
        self.map_encoder = None
        map_out = 0
        if cfg.map_channels:
            # 4x4 patches (0.8 m of the fine window), then a 3x3 convolution: cheap enough to train on a CPU
            side = -(-cfg.map_crop // 8)
            self.map_encoder = nn.Sequential(
                nn.Conv2d(cfg.map_channels, 16, 4, stride=4), nn.ReLU(),
                nn.Conv2d(16, 32, 3, stride=2, padding=1), nn.ReLU(),
                nn.Flatten(), nn.Linear(32 * side * side, cfg.map_dim), nn.ReLU()).to(memory_format=torch.channels_last)
            map_out = cfg.map_dim
        self.features = nn.Sequential(
            nn.Linear(conv_out + cfg.target_dim + cfg.action_dim + 8 + map_out, cfg.feature_dim), nn.ReLU())
        self.gru = nn.GRUCell(cfg.feature_dim, cfg.hidden)
        self.head = nn.Sequential(nn.Linear(cfg.hidden + cfg.feature_dim, 128), nn.ReLU(),
                                  nn.Linear(128, cfg.n_actions))

    def encode(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """Features (..., feature_dim) of observations with any leading shape."""
        depth, sem = obs["depth"], obs["semantic"]
        lead = depth.shape[:-1]
        depth = depth.reshape(-1, depth.shape[-1])
        sem = sem.reshape(-1, sem.shape[-1])
        target = obs["target"].reshape(-1)
        if self.config.shape_features:  # the recognising mode: no class reaches the network, only shapes
            if "shape" not in obs:
                raise ValueError("this network perceives shapes: pass observations with the 'shape' key (BatchSim("
                                 "shapes=True), or the Gym env's perception='shape')")
            sem = sem.clamp(max=CLASS_OBJECT)
            is_target = torch.zeros_like(depth)
            extra = [obs["shape"].reshape(-1, depth.shape[-1], self.config.shape_features).float(),
                     self.ray_target_embed(target)[:, None, :].expand(-1, depth.shape[-1], -1)]
        else:
            is_target = (sem == target[:, None]).float()
            extra = []
        rays = torch.cat([self.class_embed(sem), depth[..., None], is_target[..., None], *extra], dim=-1)
        scan = self.conv(rays.transpose(1, 2)).flatten(1)
        parts = [scan, self.target_embed(target), self.action_embed(obs["prev_action"].reshape(-1)),
                 self.collided_embed(obs["collided"].reshape(-1).clamp(0, 1))]
        if self.map_encoder is not None:
            if "map" not in obs:
                raise ValueError("this network reads the map memory: pass observations through MapObserver "
                                 "(adaptenv.agents.network) or run it as a NeuralPolicy")
            parts.append(self.map_encoder(self._map_input(self._sensed_map(obs["map"], len(lead)), len(lead))))
        return self.features(torch.cat(parts, dim=-1)).reshape(*lead, -1)

    def _sensed_map(self, m: torch.Tensor, lead_dims: int) -> torch.Tensor:
        """The map as this network may read it: in the recognising mode without the target channels (packed crops
        masked, the Gym env's unpacked channels zeroed)."""
        if not self.config.shape_features:
            return m
        if m.dim() == lead_dims + 2:
            return m & MAP_TARGET_MASK
        keep = torch.ones(m.shape[-3], dtype=m.dtype, device=m.device)
        keep[[2, 6]] = 0
        return m * keep[:, None, None]

    def _map_input(self, m: torch.Tensor, lead_dims: int) -> torch.Tensor:
        """Encoder input (N, C, S, S) from packed crops (lead..., S, S) or the Gym env's unpacked (lead..., C, S, S)."""
        if m.dim() == lead_dims + 2:
            # under bf16 autocast the convolution would cast a float32 input: unpack to its dtype at once (same values)
            cpu_autocast = torch.is_autocast_enabled("cpu")
            return unpack_map(m.reshape(-1, *m.shape[-2:]), self.config.map_channels,
                              torch.get_autocast_dtype("cpu") if cpu_autocast else torch.float32)
        return m.reshape(-1, *m.shape[-3:]).float().contiguous(memory_format=torch.channels_last)

    def encoder_modules(self) -> list[nn.Module]:
        """The modules :meth:`encode` runs (scan, map and embeddings): the observation encoder, without the memory and head."""
        return [m for m in (self.class_embed, self.ray_target_embed, self.conv, self.target_embed, self.action_embed, self.collided_embed,
                            self.map_encoder, self.features) if m is not None]

    def initial_state(self, batch: int) -> torch.Tensor:
        return torch.zeros(batch, self.config.hidden)

    def forward(self, obs: dict[str, torch.Tensor], done: torch.Tensor, h0: torch.Tensor
                ) -> tuple[torch.Tensor, torch.Tensor]:
        """Logits (T, B, A) of a (T, B) sequence and the final memory (B, H).

        ``done[t, b]`` resets agent b's memory to zero before step t (an episode starts there).
        """
        z, h = self.core(obs, done, h0)
        return self.head(z), h

    def core(self, obs: dict[str, torch.Tensor], done: torch.Tensor, h0: torch.Tensor
             ) -> tuple[torch.Tensor, torch.Tensor]:
        """What the heads read, (T, B, hidden + feature_dim): memory and current features; and the final memory."""
        return self.recur(self.encode(obs), done, h0)

    def recur(self, feats: torch.Tensor, done: torch.Tensor, h0: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`core` from features (T, B, feature_dim) that :meth:`encode` computed."""
        keep = (~done).float()[..., None]
        h = h0
        outs = []
        for t in range(feats.shape[0]):
            h = self.gru(feats[t], h * keep[t])
            outs.append(h)
        return torch.cat([torch.stack(outs), feats], dim=-1), h

    def step(self, obs: dict[str, torch.Tensor], done: torch.Tensor, h: torch.Tensor
             ) -> tuple[torch.Tensor, torch.Tensor]:
        """One step for a batch: logits (B, A) and the next memory (B, H)."""
        seq = {k: v[None] for k, v in obs.items()}
        logits, h = self(seq, done[None], h)
        return logits[0], h


def count_parameters(net: nn.Module) -> int:
    return sum(p.numel() for p in net.parameters())


END_THRESHOLD = 0.8
"""The policy issues ``end`` only when the network gives it at least this probability (see docs/agent.md)."""


def choose_actions(logits: torch.Tensor, u: np.ndarray | None, end_threshold: float = END_THRESHOLD) -> np.ndarray:
    """Actions from logits (B, A): ``end`` iff its probability >= ``end_threshold``, else a motion action.

    With ``u`` (B,) uniform numbers in [0, 1) the motion action is sampled from the softmax
    restricted to the motions (inverse CDF); with ``u=None`` it is the most likely motion. Stopping
    is terminal, so it is decided by confidence, never by chance; sampling the motions breaks the
    left-right loops an argmax policy falls into (measured: 24% success greedy, 77% this way, on
    the pretrain-train houses with an early checkpoint).
    """
    probs = torch.softmax(logits.float(), -1).numpy()
    end = probs[:, END] >= end_threshold
    motion = probs.copy()
    motion[:, END] = 0.0
    if u is None:
        moves = motion.argmax(-1)
    else:
        cdf = np.cumsum(motion, -1)
        cdf /= cdf[:, -1:]
        moves = np.minimum((cdf < np.asarray(u)[:, None]).sum(-1), END - 1)
    return np.where(end, END, moves).astype(np.int64)


@dataclass
class MapState:
    """A map-reading policy's memory: the GRU state (B, H) and the map it builds."""

    h: torch.Tensor
    observer: MapObserver


class NeuralPolicy:
    """A :class:`NavNet` as a batched :class:`~adaptenv.agents.policy.Policy`.

    ``end`` when the network is confident (probability >= ``end_threshold``); otherwise a motion
    sampled from the network's distribution (``greedy=False``, the default) or its most likely
    motion (``greedy=True``). When a runner binds a context, each agent's sampler is re-seeded from
    ``(seed, episode seed)`` at every episode start, so results do not depend on batching; the
    context is read for the episode seeds only, never for privileged information.
    """

    def __init__(self, net: NavNet, *, greedy: bool = False, seed: int = 0, name: str = "neural",
                 end_threshold: float = END_THRESHOLD):
        self.net = net.eval()
        self.greedy = greedy
        self.seed = seed
        self.name = name
        self.end_threshold = end_threshold
        self._rng = np.random.default_rng(seed)
        self._context = None
        self._slots: list[np.random.Generator] = []

    def bind(self, context) -> None:
        self._context = context
        self._slots = []

    def initial_state(self, batch: int) -> torch.Tensor | MapState:
        """Zero memory (a tensor), with an empty map beside it for a map-reading network."""
        h = self.net.initial_state(batch)
        observer = MapObserver.of(self.net, batch)
        return h if observer is None else MapState(h, observer)

    def forget(self, state: torch.Tensor | MapState, indices: np.ndarray) -> torch.Tensor | MapState:
        """``state`` with agents ``indices`` wiped: zero GRU memory and an empty map from the current pose on."""
        idx = torch.as_tensor(np.asarray(indices, dtype=np.int64))
        if isinstance(state, MapState):
            state.observer.emap.reset(idx.numpy())
            h = state.h.clone()
            h[idx] = 0.0
            return MapState(h, state.observer)
        h = state.clone()
        h[idx] = 0.0
        return h

    def _uniforms(self, done: np.ndarray) -> np.ndarray:
        """One uniform number per agent, from per-episode generators when bound."""
        if self._context is None:
            return self._rng.random(len(done))
        if len(self._slots) != len(done):
            self._slots = [np.random.default_rng(0) for _ in range(len(done))]
        for i in np.flatnonzero(done):
            self._slots[i] = np.random.default_rng([self.seed, int(self._context.seeds[i])])
        return np.array([g.random() for g in self._slots])

    @property
    def perception(self) -> str:
        """What the network perceives (``labels`` or ``shape``): runners give a ``shape`` policy that observation."""
        return self.net.config.perception

    @torch.no_grad()
    def act(self, obs: dict[str, np.ndarray], state: torch.Tensor, done: np.ndarray
            ) -> tuple[np.ndarray, torch.Tensor]:
        done = np.asarray(done, dtype=bool)
        if isinstance(state, MapState):
            logits, h = self.net.step(obs_to_tensors(state.observer(obs, done)), torch.as_tensor(done), state.h)
            state = MapState(h, state.observer)
        else:
            logits, state = self.net.step(obs_to_tensors(obs), torch.as_tensor(done), state)
        u = None if self.greedy else self._uniforms(done)
        return choose_actions(logits, u, self.end_threshold), state


def available_cores() -> int:
    """Cores this process may use: the machine's, capped by ``OMP_NUM_THREADS`` (an executor's worker sets 1)."""
    cores = os.cpu_count() or 2
    cap = os.environ.get("OMP_NUM_THREADS", "")
    return max(1, min(cores, int(cap))) if cap.isdigit() and int(cap) > 0 else cores


def configure_torch(threads: int | None = None) -> int:
    """Set torch's intra-op threads and return the number.

    Default: half the available cores (1 on a 2-core machine), for code that runs torch beside
    the simulator's kernels or a learner thread: on a busy 2-core machine two spinning OpenMP
    threads made every small torch op tens of times slower (measured: 8,000 vs 800 gradient
    frames/s). Serial training loops pass :func:`available_cores` instead.
    """
    n = threads or max(1, available_cores() // 2)
    torch.set_num_threads(n)
    keep_freed_memory()
    return n


BF16_FLAGS = {"x86_64": frozenset({"avx512_bf16", "amx_bf16"}), "aarch64": frozenset({"bf16"})}
"""Per machine (``platform.machine()``, lower case; amd64 and arm64 count as x86_64 and aarch64), the
/proc/cpuinfo flags of which any one means the CPU computes bfloat16 natively."""
BF16_SLOWDOWN = "about 8 times slower per gradient step than fp32 on an AVX2-only CPU"
"""What bf16 autocast costs without native bf16 (measured: 95-118 against 780-980 DAgger frames/s of the
map recipe on a 2-core AVX2 EPYC)."""


def native_bf16(cpuinfo: str | None = None, machine: str | None = None) -> bool:
    """Whether the CPU computes bf16 natively, from the flags (x86) or Features (aarch64) lines of ``cpuinfo``
    (default: this machine's /proc/cpuinfo; none readable, or another architecture: False)."""
    arch = (machine or platform.machine()).lower()
    arch = {"amd64": "x86_64", "arm64": "aarch64"}.get(arch, arch)
    if cpuinfo is None:
        try:
            with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
                cpuinfo = f.read()
        except OSError:
            return False
    words = {w for line in cpuinfo.splitlines() if line.split(":", 1)[0].strip().lower() in ("flags", "features")
             for w in line.split(":", 1)[-1].split()}
    return bool(BF16_FLAGS.get(arch, frozenset()) & words)


@functools.cache
def auto_precision() -> str:
    """What precision ``auto`` means on this machine: bf16 where the CPU computes it natively, else fp32."""
    return "bf16" if native_bf16() else "fp32"


_warned_slow_bf16: list[str] = []
"""Where the bf16 warning was given in this process (it is given once, whichever option asked for bf16)."""


def _warn_slow_bf16(where: str) -> None:
    if _warned_slow_bf16:
        return
    _warned_slow_bf16.append(where)
    print(f"adaptenv: warning: {where} bf16 on a CPU without native bf16 (no avx512_bf16 or amx_bf16 flag): "
          f"{BF16_SLOWDOWN}; pass {where} auto or fp32", file=sys.stderr, flush=True)


def same_arithmetic(a: object, b: object) -> bool:
    """Whether two precision settings compute alike on this machine (``auto`` as :func:`auto_precision`): a run
    saved with fp32 resumes under ``auto`` where auto means fp32."""
    def used(p: object) -> object:
        return auto_precision() if p == "auto" else p
    return used(a) == used(b)


def resolve_precision(precision: str, where: str = "--precision") -> str:
    """The arithmetic a run uses for ``precision``: ``auto`` is :func:`auto_precision`; an explicit bf16 on a CPU
    without native bf16 stays bf16, with one warning line on stderr (once per process) naming the cost."""
    if precision == "auto":
        return auto_precision()
    if precision == "bf16" and auto_precision() != "bf16":
        _warn_slow_bf16(where)
    return precision


_M_TRIM_THRESHOLD, _M_TOP_PAD, _M_MMAP_THRESHOLD = -1, -2, -3
"""glibc's ``mallopt`` parameters (malloc.h)."""
KEEP_MEMORY = {_M_TRIM_THRESHOLD: 2**31 - 1, _M_TOP_PAD: 256 << 20, _M_MMAP_THRESHOLD: 32 << 20}
"""What :func:`keep_freed_memory` sets: never give the heap's top back, grow the heap 256 MiB at a time (so large
buffers come from its top too), and serve buffers up to glibc's largest mmap threshold (32 MiB) from the heap."""
KEEP_MEMORY_ENV = "ADAPTENV_KEEP_MEMORY"
"""Set to 0 to leave glibc's malloc at its defaults (see :func:`keep_freed_memory`)."""


@functools.cache
def keep_freed_memory() -> bool:
    """Have glibc's malloc keep freed memory for reuse (:data:`KEEP_MEMORY`); once per process, called by
    :func:`configure_torch`. Returns whether it applied.

    Torch frees and reallocates the same activations every minibatch; by default glibc hands them back to the
    system and the next minibatch page-faults them in again: 1.4 million faults in 24,576 frames of the loop's
    PPO, about a fifth of its time (docs/BENCHMARKS.md). Results do not change. Skipped off glibc, when
    ``ADAPTENV_KEEP_MEMORY=0``, or when glibc's own variables set these (yours win).
    """
    own = {"MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_", "MALLOC_MMAP_THRESHOLD_"} & os.environ.keys() or \
        "glibc.malloc." in os.environ.get("GLIBC_TUNABLES", "")
    if own or os.environ.get(KEEP_MEMORY_ENV, "1") == "0" or platform.libc_ver()[0] != "glibc":
        return False
    libc = ctypes.CDLL(None)
    if not all(libc.mallopt(param, value) == 1 for param, value in KEEP_MEMORY.items()):
        return False
    # M_TOP_PAD acts when the heap next runs out, which a warm heap may never do: make it run out now (blocks below
    # M_MMAP_THRESHOLD come from the heap), so its top has room for large buffers
    libc.malloc.restype, libc.free.argtypes = ctypes.c_void_p, [ctypes.c_void_p]
    blocks = [libc.malloc(KEEP_MEMORY[_M_MMAP_THRESHOLD] // 2) for _ in range(20)]
    for block in blocks:
        libc.free(block)
    return True


@contextmanager
def torch_threads(threads: int | None = None) -> Iterator[int]:
    """Run a block with ``threads`` torch threads (:func:`configure_torch`'s rule), then restore the caller's."""
    before = torch.get_num_threads()
    try:
        yield configure_torch(threads)
    finally:
        torch.set_num_threads(before)
