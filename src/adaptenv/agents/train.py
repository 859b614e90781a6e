"""Imitation learning of the navigation policy: behaviour cloning + DAgger from the shortest-path expert.

One readable loop (``train``), configured by one dataclass (``TrainConfig``, whose field docstrings
are the ``adaptenv train --help`` text and which is saved as ``config.json`` in the run folder).

Each iteration:

1. **Collect.** ``num_envs`` agents run ``rollout_steps`` steps in a :class:`BatchSim` over the
   training houses (a finished episode is replaced at once by a fresh one: random house, target and
   start). At every step the expert labels the state, the network proposes an action, and the agent
   executes the expert's action with probability ``beta`` and its own otherwise (DAgger's mixture;
   ``beta`` falls linearly from ``beta_start`` to ``beta_end`` over the first ``beta_decay_fraction``
   of the frames, so training starts as pure behaviour cloning). Every visited state is labelled.
2. **Aggregate.** The (rollout_steps, num_envs) block of observations, episode-start flags and
   expert labels joins a FIFO dataset of at most ``buffer_frames`` frames.
3. **Learn.** ``updates_per_iter`` Adam steps of cross-entropy on minibatches of ``batch_chunks``
   sequences of ``chunk_len`` steps drawn uniformly from the dataset. The GRU is unrolled through
   each chunk, resetting its memory where an episode starts inside it. By default these steps
   run after the collection on every available core; with ``overlap`` they run in a learner
   thread while the next block is collected by a copy of the weights synchronised after every
   iteration (so collection lags one iteration).

After the last iteration the ``end`` threshold is chosen on fresh episodes in the training houses
(``calibrate_episodes``; :mod:`adaptenv.agents.stop`) and saved in the checkpoint.

Memory at chunk starts (the choice the GRU forces): every chunk begins with the hidden state the
network itself had at that step while collecting (R2D2's "stored state"); chunks that begin an
episode start from zero exactly as at inference. Stored states of older blocks come from older
weights; the FIFO bound keeps them recent, and the first steps of a chunk are the only ones that
see a stale memory.

Outputs: the checkpoint at ``output`` (atomically rewritten every ``save_every`` updates) and a
card ``output`` with ``.json`` (command, frames, wall time, houses, seed, final train success);
in ``run_dir``: ``config.json``, ``metrics.csv`` (always), TensorBoard events (when tensorboard
is importable) and ``state.pt`` (weights, optimizer, dataset, counters and generators) from which
``--resume`` continues an interrupted run.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numba
import numpy as np
import torch
import torch.nn.functional as F

from adaptenv.agents.checkpoint import (
    atomic_torch_save,
    load_checkpoint,
    load_tensors,
    save_checkpoint,
)
from adaptenv.agents.config import (
    FinetuneConfig,
    PPOConfig,
    TrainConfig,
    changed_settings,
    field_docs,
)
from adaptenv.agents.evaluate import run_episodes, sample_episodes, summarize
from adaptenv.agents.houses import compile_houses, load_house_set
from adaptenv.agents.network import (
    MapObserver,
    NavNet,
    NetConfig,
    NeuralPolicy,
    available_cores,
    choose_actions,
    count_parameters,
    obs_to_tensors,
    observe,
    resolve_precision,
    same_arithmetic,
    torch_threads,
)
from adaptenv.agents.ppo import train_ppo
from adaptenv.agents.registry import init_checkpoint
from adaptenv.agents.runlog import LOG_KEYS as LOG_KEYS
from adaptenv.agents.runlog import (
    RunLogger,
    TrainResult,
    card_config,
    check_finite,
    check_precision,
)
from adaptenv.agents.stop import calibrate_end_threshold
from adaptenv.agents.teachers import make_teacher
from adaptenv.errors import ConfigError, TrainingDiverged
from adaptenv.files import atomic_write_text
from adaptenv.limits import check_numbers
from adaptenv.progress import ProgressBar
from adaptenv.scene.house import House
from adaptenv.sim.perception import check_perception
from adaptenv.sim.spec import END, N_RAYS
from adaptenv.sim.vector import BatchSim, EpisodeSampler
from adaptenv.sim.world import NavWorld

__all__ = ["TrainConfig", "FinetuneConfig", "field_docs", "train", "finetune", "finetune_policy"]


def snapshot_path(output: str | Path, frames: int) -> Path:
    """Where ``--snapshots`` keeps the policy after ``frames`` frames: ``OUTPUT`` stem + ``-f<frames>.pt``."""
    p = Path(output)
    return p.with_name(f"{p.stem}-f{frames:09d}.pt")


def check_config(cfg: TrainConfig) -> None:
    """Raise one ConfigError for the first inconsistent setting (naming the field and the fix)."""
    check_numbers(cfg)
    if cfg.rollout_steps % cfg.chunk_len:
        raise ConfigError(f"--rollout-steps ({cfg.rollout_steps}) must be a multiple of --chunk-len "
                          f"({cfg.chunk_len}); e.g. --rollout-steps {cfg.chunk_len * 2}")
    if cfg.buffer_frames < cfg.rollout_steps * cfg.num_envs:
        raise ConfigError(f"--buffer-frames ({cfg.buffer_frames}) must hold at least one block of "
                          f"rollout_steps * num_envs = {cfg.rollout_steps * cfg.num_envs} frames")
    check_precision(cfg.precision, "--precision")
    check_perception(cfg.perception)


def sequence_logits(net: NavNet, obs: dict[str, torch.Tensor], first: torch.Tensor, h0: torch.Tensor,
                    precision: str) -> torch.Tensor:
    """fp32 logits (T, B, A) of a training batch, the forward pass in ``precision`` (bf16: under CPU autocast)."""
    with torch.autocast("cpu", dtype=torch.bfloat16, enabled=precision == "bf16"):
        logits, _ = net(obs, first, h0)
    return logits.float()


def beta_at(cfg: TrainConfig, frames: int) -> float:
    """DAgger's expert-mixing probability after ``frames`` collected frames (linear decay)."""
    span = cfg.beta_decay_fraction * cfg.frames
    frac = 1.0 if span <= 0 else min(1.0, frames / span)
    return cfg.beta_start + frac * (cfg.beta_end - cfg.beta_start)


# -- the aggregated dataset -----------------------------------------------------------------------

class SequenceBuffer:
    """FIFO ring of collected blocks, each (T, B) steps, sampled as (chunk_len, N) sequences."""

    def __init__(self, capacity_blocks: int, steps: int, envs: int, chunk_len: int, hidden: int, n_rays: int,
                 map_crop: int = 0, shape_features: int = 0):
        k, t, b = capacity_blocks, steps, envs
        self.capacity, self.steps, self.envs, self.chunk_len = k, t, b, chunk_len
        self.depth = np.zeros((k, t, b, n_rays), np.float16)
        self.semantic = np.zeros((k, t, b, n_rays), np.uint8)
        self.target = np.zeros((k, t, b), np.uint8)
        self.prev_action = np.zeros((k, t, b), np.uint8)
        self.collided = np.zeros((k, t, b), np.uint8)
        self.first = np.zeros((k, t, b), np.bool_)
        self.label = np.zeros((k, t, b), np.uint8)
        self.h0 = np.zeros((k, t // chunk_len, b, hidden), np.float16)
        self.names = ("depth", "semantic", "target", "prev_action", "collided", "first", "label", "h0")
        if map_crop:  # packed map crops (1 byte a pixel) for a map-reading network
            self.map = np.zeros((k, t, b, map_crop, map_crop), np.uint8)
            self.names += ("map",)
        if shape_features:  # the recognising mode's per-ray shapes (metres, half precision)
            self.shape = np.zeros((k, t, b, n_rays, shape_features), np.float16)
            self.names += ("shape",)
        self.size = 0
        self.cursor = 0

    @property
    def frames(self) -> int:
        return self.size * self.steps * self.envs

    def add(self, block: dict[str, np.ndarray]) -> None:
        """Append one block (arrays shaped like one ring slot), overwriting the oldest when full."""
        k = self.cursor
        for name, value in block.items():
            getattr(self, name)[k] = value
        self.cursor = (self.cursor + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def sample(self, n: int, rng: np.random.Generator) -> dict[str, torch.Tensor]:
        """``n`` random chunks as tensors: obs (L, n, ...), first (L, n), label (L, n), h0 (n, H)."""
        n_chunks = self.steps // self.chunk_len
        blk = rng.integers(0, self.size, n)
        chk = rng.integers(0, n_chunks, n)
        env = rng.integers(0, self.envs, n)
        t = chk[None, :] * self.chunk_len + np.arange(self.chunk_len)[:, None]
        idx = (blk[None, :], t, env[None, :])
        extra = {"map": torch.from_numpy(self.map[idx])} if "map" in self.names else {}
        if "shape" in self.names:
            extra["shape"] = torch.from_numpy(self.shape[idx].astype(np.float32))
        return {**extra,
            "depth": torch.from_numpy(self.depth[idx].astype(np.float32)),
            "semantic": torch.from_numpy(self.semantic[idx].astype(np.int64)),
            "target": torch.from_numpy(self.target[idx].astype(np.int64)),
            "prev_action": torch.from_numpy(self.prev_action[idx].astype(np.int64)),
            "collided": torch.from_numpy(self.collided[idx].astype(np.int64)),
            "first": torch.from_numpy(self.first[idx]),
            "label": torch.from_numpy(self.label[idx].astype(np.int64)),
            "h0": torch.from_numpy(self.h0[blk, chk, env].astype(np.float32)),
        }

    def state_dict(self) -> dict[str, Any]:
        """The filled part of the ring (for the resume state)."""
        return {"size": self.size, "cursor": self.cursor,
                **{n: torch.from_numpy(getattr(self, n)[: self.size].copy()) for n in self.names}}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.size, self.cursor = int(state["size"]), int(state["cursor"])
        for n in self.names:
            getattr(self, n)[: self.size] = state[n].numpy()


# -- the resume state -----------------------------------------------------------------------------

STATE_KEYS = ("net", "optimizer", "buffer", "frames", "updates", "iteration", "wall_time", "numpy_rng", "torch_rng",
              "config")
"""What ``state.pt`` must hold (and ``learn_rng``): tensors, numbers, strings and plain dicts only, so it loads with
``weights_only=True`` and never runs code."""
RESUME_MAY_CHANGE = ("resume", "frames", "output", "save_every", "final_eval_episodes", "threads", "progress",
                     "tensorboard")
"""TrainConfig fields a resumed run may set differently from the interrupted one (budget and bookkeeping)."""


def load_resume_state(cfg: TrainConfig, state_path: Path | None) -> dict[str, Any]:
    """Read ``state.pt`` for ``--resume`` (never unpickling code) and check it belongs to this config."""
    if state_path is None:
        raise ConfigError("--resume: this run writes no run folder; pass the --run-dir of the interrupted run")
    if not state_path.parent.is_dir():
        raise ConfigError(f"--resume: the run folder {state_path.parent} does not exist; pass the --run-dir of the "
                          "interrupted run, or start without --resume")
    if not state_path.is_file():
        raise ConfigError(f"--resume: no saved state at {state_path}; start without --resume or pass the "
                          "--run-dir of the interrupted run")
    try:
        saved = load_tensors(state_path)
    except Exception as exc:  # torch raises many types for corrupt or foreign files
        raise ConfigError(f"{state_path}: not a resume state adaptenv train wrote ({type(exc).__name__}); start "
                          "the run again without --resume, in a new --run-dir") from None
    if not isinstance(saved, dict) or not set(STATE_KEYS) <= set(saved) or not isinstance(saved["config"], dict):
        raise ConfigError(f"{state_path}: not a resume state adaptenv train wrote (missing fields); start the run "
                          "again without --resume, in a new --run-dir")
    old = {**asdict(TrainConfig()), **saved["config"]}
    if same_arithmetic(old["precision"], cfg.precision):  # fp32 saved, auto now: the same steps on this CPU
        old["precision"] = cfg.precision
    changed = changed_settings(old, asdict(cfg), RESUME_MAY_CHANGE)
    if changed:
        raise ConfigError(f"--resume: {state_path} was saved with other settings: {', '.join(changed)}; pass the "
                          "interrupted run's values (its config.json) or start a new --run-dir")
    return saved


# -- training -------------------------------------------------------------------------------------

def default_run_dir(cfg: TrainConfig) -> Path | None:
    """``cfg.run_dir``, else ``runs/train/<output stem>`` (None when nothing is written)."""
    if cfg.run_dir:
        return Path(cfg.run_dir)
    return Path("runs/train") / Path(cfg.output).stem if cfg.output else None


def train(cfg: TrainConfig, *, worlds: Sequence[NavWorld] | None = None, init_net: NavNet | None = None,
          command: str = "") -> TrainResult:
    """Run behaviour cloning + DAgger as configured; returns the trained network and its card.

    ``worlds`` (compiled NavWorlds) override ``cfg.houses``; ``init_net`` (a NavNet) overrides
    ``cfg.init``. Both are how :func:`finetune` trains on houses held in memory. Torch's thread count is the
    caller's again afterwards.
    """
    check_config(cfg)
    with torch_threads(cfg.threads or (None if cfg.overlap else available_cores())) as threads, \
            _collector_threads(1 if cfg.overlap else None):
        return _train(cfg, worlds, init_net, command, threads)


@contextmanager
def _collector_threads(n: int | None) -> Iterator[None]:
    """Run a block with ``n`` numba threads for the collecting thread's kernels (map memory, map explorer), then
    restore the count; None leaves it. With the learner thread on the second core they run on one."""
    before = numba.get_num_threads()
    if n is not None:
        numba.set_num_threads(min(n, before))
    try:
        yield
    finally:
        numba.set_num_threads(before)


def _train(cfg: TrainConfig, worlds: Sequence[NavWorld] | None, init_net: NavNet | None, command: str,
           threads: int) -> TrainResult:
    run_dir = default_run_dir(cfg)
    state_path = run_dir / "state.pt" if run_dir else None
    saved = load_resume_state(cfg, state_path) if cfg.resume else None  # checked before anything is written
    precision = resolve_precision(cfg.precision)  # what "auto" means on this CPU; the card records it

    # seeding: one root seed for torch, the data generator and the episode sampler
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    if worlds is None:
        worlds = load_house_set(cfg.houses).worlds
    worlds = list(worlds)

    if init_net is not None:
        net = NavNet(init_net.config)
        net.load_state_dict(init_net.state_dict())
    elif cfg.init:
        net = load_checkpoint(init_checkpoint(cfg.init)).net
    else:
        net = NavNet(NetConfig.of(cfg))
    if run_dir:  # the houses and the --init checkpoint loaded: the run starts
        run_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(run_dir / "config.json", json.dumps(asdict(cfg), indent=1) + "\n")
    hidden = net.config.hidden
    optimizer = torch.optim.Adam(net.parameters(), lr=cfg.learning_rate, eps=1e-5)
    class_weight = torch.ones(net.config.n_actions)
    class_weight[END] = cfg.end_weight
    n_blocks = max(1, cfg.buffer_frames // (cfg.rollout_steps * cfg.num_envs))
    buffer = SequenceBuffer(n_blocks, cfg.rollout_steps, cfg.num_envs, cfg.chunk_len, hidden, N_RAYS,
                            net.config.map_crop if net.config.map_channels else 0, net.config.shape_features)
    frames, updates, iteration, wall_before = 0, 0, 0, 0.0
    learn_rng = np.random.default_rng([cfg.seed, 1])  # minibatches (its own stream: the learner may run in a thread)
    if saved is not None:
        try:
            net.load_state_dict(saved["net"])
            optimizer.load_state_dict(saved["optimizer"])
            buffer.load_state_dict(saved["buffer"])
            frames, updates, iteration = int(saved["frames"]), int(saved["updates"]), int(saved["iteration"])
            wall_before = float(saved["wall_time"])
            rng.bit_generator.state = saved["numpy_rng"]
            learn_rng.bit_generator.state = saved.get("learn_rng", learn_rng.bit_generator.state)
            torch.set_rng_state(saved["torch_rng"])
        except (KeyError, RuntimeError, TypeError, ValueError) as exc:
            raise ConfigError(f"{state_path}: the saved state does not fit this run ({type(exc).__name__}); start the "
                              "run again without --resume, in a new --run-dir") from None
        del saved  # the dataset copy in it is large

    def save_state() -> None:
        """Atomically write the policy checkpoint and the full resume state."""
        if cfg.output:
            save_checkpoint(cfg.output, net, {"frames": frames, "updates": updates, "houses": cfg.houses,
                                              "seed": cfg.seed, "end_threshold": cfg.end_threshold})
        if state_path is not None:
            atomic_torch_save({"net": net.state_dict(), "optimizer": optimizer.state_dict(),
                               "buffer": buffer.state_dict(), "frames": frames, "updates": updates,
                               "iteration": iteration, "wall_time": wall_before + time.perf_counter() - start,
                               "numpy_rng": rng.bit_generator.state, "learn_rng": learn_rng.bit_generator.state,
                               "torch_rng": torch.get_rng_state(),
                               "config": asdict(cfg)}, state_path)

    def new_episodes(n: int) -> tuple[list[Any], np.ndarray]:
        """Fresh training episodes: a random house each, then a random target and start in it."""
        return sampler.draw(rng, n)

    def collect(beta: float) -> tuple[dict[str, np.ndarray], list[float], list[int], float]:
        """One (T, B) block with the beta-mixture of the teacher and ``actor``: (block, successes, lengths, seconds)."""
        nonlocal obs, h, first
        t0 = time.perf_counter()
        block = {"depth": np.empty((T, B, N_RAYS), np.float16), "semantic": np.empty((T, B, N_RAYS), np.uint8),
                 "target": np.empty((T, B), np.uint8), "prev_action": np.empty((T, B), np.uint8),
                 "collided": np.empty((T, B), np.uint8), "first": np.empty((T, B), np.bool_),
                 "label": np.empty((T, B), np.uint8), "h0": np.empty((T // L, B, hidden), np.float16)}
        if observer is not None:
            block["map"] = np.empty((T, B, *buffer.map.shape[-2:]), np.uint8)
        if net.config.shape_features:
            block["shape"] = np.empty((T, B, *buffer.shape.shape[-2:]), np.float16)
        ep_success, ep_length = [], []
        for t in range(T):
            if t % L == 0:
                block["h0"][t // L] = h.numpy()
            obs = observe(observer, obs, first)
            for k in block.keys() - {"first", "label", "h0"}:
                block[k][t] = obs[k]
            block["first"][t] = first
            labels = teacher.label(obs, first)
            block["label"][t] = labels
            with torch.no_grad():
                logits, h = actor.step(_to_tensors(obs), torch.from_numpy(first), h)
            own = choose_actions(logits, rng.random(B) if cfg.sample_actions else None, cfg.end_threshold)
            actions = np.where(rng.random(B) < beta, labels, own)
            obs, _, terminated, truncated, info = sim.step(actions)
            finished = np.flatnonzero(terminated | truncated)
            first = np.zeros(B, dtype=bool)
            if finished.size:
                ep_success += info["success"][finished].tolist()
                ep_length += info["steps"][finished].tolist()
                eps, envs = new_episodes(finished.size)
                obs = sim.reset_at(finished, eps, envs)
                first[finished] = True
        return block, ep_success, ep_length, time.perf_counter() - t0

    def learn(frames_now: int) -> dict[str, Any]:
        """``updates_per_iter`` Adam steps of cross-entropy against the expert's labels on sequences from the dataset."""
        t0 = time.perf_counter()
        net.train()
        losses, accs = [], []
        lr = cfg.learning_rate * (max(0.0, 1.0 - frames_now / cfg.frames) if cfg.anneal_lr else 1.0)
        for group in optimizer.param_groups:
            group["lr"] = lr
        for _ in range(cfg.updates_per_iter):
            batch = buffer.sample(cfg.batch_chunks, learn_rng)
            logits = sequence_logits(net, batch, batch["first"], batch["h0"], precision)
            loss = F.cross_entropy(logits.reshape(-1, logits.shape[-1]), batch["label"].reshape(-1),
                                   weight=class_weight)
            optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(net.parameters(), cfg.max_grad_norm)
            optimizer.step()
            losses.append(loss.item())
            accs.append((logits.argmax(-1) == batch["label"]).float().mean().item())
        net.eval()
        return {"charts/learning_rate": lr, "losses/loss": float(np.mean(losses)),
                "losses/accuracy": float(np.mean(accs)),
                "charts/train_fps": cfg.updates_per_iter * cfg.batch_chunks * L / (time.perf_counter() - t0)}

    sampler = EpisodeSampler(worlds, min_distance=cfg.min_start_distance)
    # with overlap the learner thread takes the second core, so the simulator kernel runs serially
    sim = BatchSim(worlds, max_steps=cfg.max_episode_steps, threads=1 if cfg.overlap else None,
                   shapes=bool(net.config.shape_features))
    B, T, L = cfg.num_envs, cfg.rollout_steps, cfg.chunk_len
    eps, envs = new_episodes(B)
    obs, _ = sim.reset(eps, envs)
    actor = NavNet(net.config).eval()  # the collecting copy of the weights (synchronised after every learn)
    actor.load_state_dict(net.state_dict())
    actor.requires_grad_(False)
    h = actor.initial_state(B)
    observer = MapObserver.of(actor, B)
    teacher = make_teacher(cfg.teacher, sim, mix=cfg.teacher_mix, seed=cfg.seed,  # agents/teachers.py
                           emap=observer.emap if observer else None)
    first = np.ones(B, dtype=bool)
    logger = RunLogger(run_dir, cfg.tensorboard, fresh=not cfg.resume)
    progress = ProgressBar("DAgger" if cfg.progress else None, cfg.frames, transient=False).start()
    progress.update(frames)
    pool = ThreadPoolExecutor(max_workers=1) if cfg.overlap else None
    start = time.perf_counter()
    last_save = updates
    learning: Any = None  # the gradient steps of the last iteration (a Future with overlap)
    row: dict[str, Any] = {}

    def finish_learning() -> None:
        """Wait for the last iteration's gradient steps, then log its row (with a periodic evaluation)."""
        nonlocal learning, updates, last_save
        if learning is None:
            return
        row.update(learning.result() if pool else learning)
        learning = None
        check_finite(net, cfg, frames, last_save)
        updates += cfg.updates_per_iter
        row["updates"], row["wall_time"] = updates, wall_before + time.perf_counter() - start
        actor.load_state_dict(net.state_dict())
        if cfg.eval_every and row["iteration"] % cfg.eval_every == 0:
            episodes = sample_episodes(worlds, cfg.eval_episodes, seed=cfg.seed * 100_003 + row["iteration"])
            res, _ = run_episodes(worlds, episodes, NeuralPolicy(net, end_threshold=cfg.end_threshold),
                                  batch=min(cfg.eval_episodes, 128))
            s = summarize(res)
            row["eval/success"], row["eval/spl"] = s["success"], s["spl"]
        logger.log(dict(row))
        if progress:
            progress.update(min(row["frames"], cfg.frames),
                            description=f"DAgger beta={row['charts/beta']:.2f} loss={row['losses/loss']:.3f} "
                                        f"acc={row['losses/accuracy']:.2f}"
                                        + (f" eval={row['eval/success']:.2f}" if "eval/success" in row else ""))
        if updates - last_save >= cfg.save_every:
            save_state()
            last_save = updates
        done_frames, step = row["frames"], T * B
        if cfg.snapshots and cfg.output and (done_frames - step) * cfg.snapshots // cfg.frames < \
                done_frames * cfg.snapshots // cfg.frames:
            save_checkpoint(snapshot_path(cfg.output, done_frames), net,
                            {"frames": done_frames, "updates": updates, "houses": cfg.houses, "seed": cfg.seed,
                             "end_threshold": cfg.end_threshold})

    try:
        while frames < cfg.frames:
            # 1. collect a (T, B) block (with overlap: while the learner thread runs the last iteration's steps)
            beta = beta_at(cfg, frames)
            block, ep_success, ep_length, collect_time = collect(beta)
            finish_learning()
            # 2. aggregate
            buffer.add(block)
            frames += T * B
            iteration += 1
            row = {"iteration": iteration, "frames": frames, "charts/beta": beta,
                   "charts/collect_fps": T * B / collect_time, "charts/episodes": len(ep_success),
                   "charts/episode_success": float(np.mean(ep_success)) if ep_success else "",
                   "charts/episode_length": float(np.mean(ep_length)) if ep_length else "",
                   "charts/buffer_frames": buffer.frames}
            # 3. learn on the whole dataset (in the learner thread with overlap)
            learning = pool.submit(learn, frames) if pool else learn(frames)
            if not pool:
                finish_learning()
        finish_learning()
    except KeyboardInterrupt:
        finish_learning()
        save_state()
        logger.close()
        if progress:
            progress.stop()
        raise
    except TrainingDiverged:
        logger.close()
        if progress:
            progress.stop()
        raise
    finally:
        if pool:
            pool.shutdown(wait=True)
    if progress:
        progress.stop()

    # the stop decision: choose the end threshold on fresh held-in episodes (never a held-out set)
    end_threshold, calibration = cfg.end_threshold, None
    if cfg.calibrate_episodes:
        calibration = calibrate_end_threshold(net, worlds, episodes=cfg.calibrate_episodes, seed=cfg.seed + 4_241)
        end_threshold = calibration.threshold
    # final evaluation of the policy on fresh episodes in the training houses
    episodes = sample_episodes(worlds, cfg.final_eval_episodes, seed=cfg.seed + 7_919)
    res, _ = run_episodes(worlds, episodes, NeuralPolicy(net, end_threshold=end_threshold), batch=128)
    final = summarize(res)
    wall = wall_before + time.perf_counter() - start
    card = {
        "command": command, "houses": cfg.houses, "n_houses": len(worlds), "frames": frames, "updates": updates,
        "wall_time_s": round(wall, 1), "seed": cfg.seed, "parameters": count_parameters(net),
        "final_train_success": final["success"], "final_train_success_ci95": final["success_ci95"],
        "final_train_spl": final["spl"], "final_eval_episodes": final["episodes"],
        "end_threshold": end_threshold, "end_weight": cfg.end_weight, "precision": precision,
        "end_threshold_calibration": calibration.card() if calibration else None,
        "torch_threads": threads, "cpus": os.cpu_count(), "config": card_config(cfg, net),
        "net_config": asdict(net.config)}
    logger.log({"iteration": iteration, "frames": frames, "updates": updates, "wall_time": wall,
                "eval/success": final["success"], "eval/spl": final["spl"]})
    logger.close()
    save_state()
    if cfg.output:
        save_checkpoint(cfg.output, net, {k: v for k, v in card.items() if k != "config"})
        atomic_write_text(Path(cfg.output).with_suffix(".json"), json.dumps(card, indent=1) + "\n")
    net.eval()
    return TrainResult(net, card, logger.rows)


def ppo_rollout_steps(frames: int, num_envs: int) -> int:
    """PPO's rollout length for a ``frames`` budget: 128 steps, or fewer (a multiple of the 32-step sequence, still
    splitting into the minibatches) when one 128-step rollout of ``num_envs`` agents would overspend the budget."""
    seq, full = PPOConfig.chunk_len, PPOConfig.rollout_steps
    fits = max(seq, min(full, frames // max(num_envs, 1) // seq * seq))
    return next((t for t in range(fits, full, seq) if num_envs * (t // seq) % PPOConfig.num_minibatches == 0), full)


def finetune(net: NavNet, worlds: Sequence[NavWorld], cfg: FinetuneConfig, seed: int,
             learner: dict[str, Any] | None = None) -> TrainResult:
    """Fine-tune a copy of ``net`` (a NavNet) on ``worlds`` (NavWorlds) as ``cfg`` says; returns the new net, its
    card and, for PPO, the learner state that ``learner`` takes to continue this run (no value warm-up then).

    ``algo='dagger'``: DAgger from the current weights with a fresh Adam optimizer, expert-action
    probability ``beta`` throughout, labels from ``cfg.teacher``, ``rollout_steps``-step blocks that are also the training
    sequences, a dataset holding the whole run. ``algo='ppo'``: :func:`adaptenv.agents.ppo.train_ppo`
    on the simulator's reward (plus ``explore_bonus``, anchored by ``kl_coef``) to ``max_episode_steps``,
    with PPOConfig's defaults for the rest (128-step rollouts, or :func:`ppo_rollout_steps` when the budget is under
    one; 32-step sequences; value warm-up on a quarter of the iterations, at least one and at most four) on one torch
    thread, so results do not depend on the core count.
    Nothing is written to disk.
    """
    if cfg.algo not in ("dagger", "ppo"):
        raise ConfigError(f"FinetuneConfig.algo must be 'dagger' or 'ppo', got {cfg.algo!r}")
    check_precision(cfg.precision, "FinetuneConfig.precision")
    if cfg.algo == "dagger" and (cfg.kl_coef or cfg.explore_bonus or cfg.freeze_encoder or cfg.bc_coef):
        raise ConfigError("FinetuneConfig.kl_coef, explore_bonus, freeze_encoder and bc_coef apply to PPO only; leave "
                          "them unset with algo='dagger'")
    evals = cfg.final_eval_episodes or len(worlds)
    if cfg.algo == "ppo":
        rollout = ppo_rollout_steps(cfg.frames, cfg.num_envs)
        iterations = -(-cfg.frames // (cfg.num_envs * rollout))
        # a fresh critic never moves the policy: at least its first PPO iteration trains the value head alone
        warmup = 0 if learner is not None else min(PPOConfig.value_warmup_iters, max(1, iterations // 4))
        pc = PPOConfig(houses="(in memory)", value_warmup_iters=warmup, rollout_steps=rollout,
                       frames=cfg.frames, init="", output="", seed=seed, num_envs=cfg.num_envs,
                       learning_rate=cfg.learning_rate, end_threshold=cfg.end_threshold,
                       calibrate_episodes=cfg.calibrate_episodes, eval_every=0, final_eval_episodes=evals,
                       min_start_distance=cfg.min_start_distance, max_episode_steps=cfg.max_episode_steps,
                       kl_coef=cfg.kl_coef, explore_bonus=cfg.explore_bonus, freeze_encoder=cfg.freeze_encoder,
                       precision=cfg.precision, bc_coef=cfg.bc_coef, bc_teacher=cfg.teacher, threads=1, progress=False,
                       tensorboard=False)
        return train_ppo(pc, worlds=worlds, init_net=net, learner=learner)
    steps = cfg.rollout_steps
    tc = TrainConfig(houses="(in memory)", frames=cfg.frames, output="", seed=seed, num_envs=cfg.num_envs,
                     rollout_steps=steps, chunk_len=steps, batch_chunks=cfg.batch_chunks,
                     updates_per_iter=cfg.updates_per_iter, buffer_frames=max(cfg.frames, steps * cfg.num_envs),
                     beta_start=cfg.beta, beta_end=cfg.beta, end_threshold=cfg.end_threshold, teacher=cfg.teacher,
                     calibrate_episodes=cfg.calibrate_episodes, eval_every=0, final_eval_episodes=evals,
                     min_start_distance=cfg.min_start_distance, progress=False, tensorboard=False,
                     learning_rate=cfg.learning_rate, save_every=10**9, precision=cfg.precision,
                     max_episode_steps=cfg.max_episode_steps)
    return train(tc, worlds=worlds, init_net=net)


def finetune_policy(policy: NeuralPolicy | NavNet | str | Path, houses: Sequence[House | NavWorld] | str, frames: int, *,
                    seed: int = 0, **overrides: Any) -> NeuralPolicy:
    """Continue training ``policy`` (a NeuralPolicy or checkpoint path) on ``houses``; returns a new policy.

    ``houses`` may be House objects, NavWorlds or a ``--houses`` spec. DAgger keeps the expert in
    control 80% of the time (beta 0.8 throughout: with lower beta the student's success fell, see
    docs/agent.md); nothing is written unless ``output``/``run_dir`` is given in ``overrides`` (any
    TrainConfig field).
    """
    net = load_checkpoint(policy).net if isinstance(policy, (str, Path)) else getattr(policy, "net", policy)
    worlds = load_house_set(houses).worlds if isinstance(houses, str) else compile_houses(list(houses))
    settings = {"frames": frames, "seed": seed, "output": "", "houses": "(in memory)", "beta_start": 0.8,
                "progress": False, "eval_every": 0, "final_eval_episodes": 64, "calibrate_episodes": 0, **overrides}
    cfg = TrainConfig(**settings)
    return train(cfg, worlds=worlds, init_net=net).policy()


def _to_tensors(obs: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
    return obs_to_tensors(obs)
