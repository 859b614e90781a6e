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
   each chunk, resetting its memory where an episode starts inside it.

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

import csv
import json
import os
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from adaptenv.agents.config import TrainConfig, field_docs
from adaptenv.errors import ConfigError

__all__ = ["TrainConfig", "field_docs", "train", "finetune"]


def check_config(cfg: TrainConfig) -> None:
    """Raise one ConfigError for the first inconsistent setting (naming the field and the fix)."""
    positive = ("frames", "num_envs", "rollout_steps", "chunk_len", "batch_chunks", "hidden", "feature_dim",
                "max_episode_steps", "buffer_frames", "save_every")
    for name in positive:
        if getattr(cfg, name) <= 0:
            raise ConfigError(f"--{name.replace('_', '-')} must be positive, got {getattr(cfg, name)}")
    if cfg.rollout_steps % cfg.chunk_len:
        raise ConfigError(f"--rollout-steps ({cfg.rollout_steps}) must be a multiple of --chunk-len "
                          f"({cfg.chunk_len}); e.g. --rollout-steps {cfg.chunk_len * 2}")
    if cfg.buffer_frames < cfg.rollout_steps * cfg.num_envs:
        raise ConfigError(f"--buffer-frames ({cfg.buffer_frames}) must hold at least one block of "
                          f"rollout_steps * num_envs = {cfg.rollout_steps * cfg.num_envs} frames")
    for name in ("beta_start", "beta_end", "beta_decay_fraction"):
        if not 0.0 <= getattr(cfg, name) <= 1.0:
            raise ConfigError(f"--{name.replace('_', '-')} must lie in [0, 1], got {getattr(cfg, name)}")


def beta_at(cfg: TrainConfig, frames: int) -> float:
    """DAgger's expert-mixing probability after ``frames`` collected frames (linear decay)."""
    span = cfg.beta_decay_fraction * cfg.frames
    frac = 1.0 if span <= 0 else min(1.0, frames / span)
    return cfg.beta_start + frac * (cfg.beta_end - cfg.beta_start)


# -- the aggregated dataset -----------------------------------------------------------------------

class SequenceBuffer:
    """FIFO ring of collected blocks, each (T, B) steps, sampled as (chunk_len, N) sequences."""

    def __init__(self, capacity_blocks: int, steps: int, envs: int, chunk_len: int, hidden: int, n_rays: int):
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
        return {
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
        names = ("depth", "semantic", "target", "prev_action", "collided", "first", "label", "h0")
        return {"size": self.size, "cursor": self.cursor,
                **{n: torch.from_numpy(getattr(self, n)[: self.size].copy()) for n in names}}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.size, self.cursor = int(state["size"]), int(state["cursor"])
        for n in ("depth", "semantic", "target", "prev_action", "collided", "first", "label", "h0"):
            getattr(self, n)[: self.size] = state[n].numpy()


# -- logging --------------------------------------------------------------------------------------

LOG_KEYS = ("iteration", "frames", "updates", "wall_time", "charts/beta", "charts/learning_rate",
            "charts/collect_fps", "charts/train_fps", "charts/episodes", "charts/episode_success",
            "charts/episode_length", "charts/buffer_frames", "losses/loss", "losses/accuracy",
            "eval/success", "eval/spl")


class RunLogger:
    """Metrics to ``metrics.csv`` always and to TensorBoard when it is importable."""

    def __init__(self, run_dir: Path | None, tensorboard: bool):
        self.rows: list[dict[str, Any]] = []
        self.csv_path = run_dir / "metrics.csv" if run_dir else None
        self.writer = None
        if run_dir and tensorboard:
            try:
                from torch.utils.tensorboard import SummaryWriter

                self.writer = SummaryWriter(str(run_dir / "tb"))
            except ImportError:
                self.writer = None

    def log(self, row: dict[str, Any]) -> None:
        self.rows.append(row)
        if self.csv_path is not None:
            new = not self.csv_path.exists()
            with self.csv_path.open("a", newline="", encoding="utf-8") as f:
                w = csv.DictWriter(f, fieldnames=list(LOG_KEYS), extrasaction="ignore")
                if new:
                    w.writeheader()
                w.writerow({k: row.get(k, "") for k in LOG_KEYS})
        if self.writer is not None:
            for k, v in row.items():
                if "/" in k and v is not None and v != "":
                    self.writer.add_scalar(k, float(v), int(row["frames"]))

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


# -- training -------------------------------------------------------------------------------------

@dataclass
class TrainResult:
    """What a run returns: the trained policy network, its card and the logged rows."""

    net: Any
    card: dict[str, Any]
    rows: list[dict[str, Any]] = field(default_factory=list)

    def policy(self, *, name: str = "finetuned") -> Any:
        from adaptenv.agents.network import END_THRESHOLD, NeuralPolicy

        return NeuralPolicy(self.net, name=name, end_threshold=self.card.get("end_threshold", END_THRESHOLD))


def default_run_dir(cfg: TrainConfig) -> Path | None:
    """``cfg.run_dir``, else ``runs/train/<output stem>`` (None when nothing is written)."""
    if cfg.run_dir:
        return Path(cfg.run_dir)
    return Path("runs/train") / Path(cfg.output).stem if cfg.output else None


def train(cfg: TrainConfig, *, worlds: Sequence[Any] | None = None, init_net: Any = None,
          command: str = "") -> TrainResult:
    """Run behaviour cloning + DAgger as configured; returns the trained network and its card.

    ``worlds`` (compiled NavWorlds) override ``cfg.houses``; ``init_net`` (a NavNet) overrides
    ``cfg.init``. Both are how :func:`finetune` trains on houses held in memory.
    """
    from adaptenv.agents.checkpoint import atomic_torch_save, load_checkpoint, save_checkpoint
    from adaptenv.agents.evaluate import run_episodes, sample_episodes, summarize
    from adaptenv.agents.houses import load_house_set
    from adaptenv.agents.network import (
        NavNet,
        NetConfig,
        NeuralPolicy,
        choose_actions,
        configure_torch,
        count_parameters,
    )
    from adaptenv.agents.teachers import make_teacher
    from adaptenv.sim import task
    from adaptenv.sim.spec import N_RAYS
    from adaptenv.sim.vector import BatchSim

    check_config(cfg)
    threads = configure_torch(cfg.threads or None)
    run_dir = default_run_dir(cfg)
    state_path = run_dir / "state.pt" if run_dir else None
    if cfg.resume and (state_path is None or not state_path.is_file()):
        raise ConfigError(f"--resume: no saved state at {state_path}; start without --resume or pass the "
                          "--run-dir of the interrupted run")
    if run_dir:
        run_dir.mkdir(parents=True, exist_ok=True)
        (run_dir / "config.json").write_text(json.dumps(asdict(cfg), indent=1) + "\n", encoding="utf-8")

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
        net = load_checkpoint(cfg.init).net
    else:
        net = NavNet(NetConfig(hidden=cfg.hidden, feature_dim=cfg.feature_dim))
    hidden = net.config.hidden
    optimizer = torch.optim.Adam(net.parameters(), lr=cfg.learning_rate, eps=1e-5)
    n_blocks = max(1, cfg.buffer_frames // (cfg.rollout_steps * cfg.num_envs))
    buffer = SequenceBuffer(n_blocks, cfg.rollout_steps, cfg.num_envs, cfg.chunk_len, hidden, N_RAYS)
    frames, updates, iteration, wall_before = 0, 0, 0, 0.0
    if cfg.resume:
        saved = torch.load(state_path, map_location="cpu", weights_only=False)
        net.load_state_dict(saved["net"])
        optimizer.load_state_dict(saved["optimizer"])
        buffer.load_state_dict(saved["buffer"])
        frames, updates, iteration, wall_before = saved["frames"], saved["updates"], saved["iteration"], saved["wall_time"]
        rng.bit_generator.state = saved["numpy_rng"]
        torch.set_rng_state(saved["torch_rng"])

    def save_state() -> None:
        """Atomically write the policy checkpoint and the full resume state."""
        if cfg.output:
            save_checkpoint(cfg.output, net, {"frames": frames, "updates": updates, "houses": cfg.houses,
                                              "seed": cfg.seed, "end_threshold": cfg.end_threshold})
        if state_path is not None:
            atomic_torch_save({"net": net.state_dict(), "optimizer": optimizer.state_dict(),
                               "buffer": buffer.state_dict(), "frames": frames, "updates": updates,
                               "iteration": iteration, "wall_time": wall_before + time.perf_counter() - start,
                               "numpy_rng": rng.bit_generator.state, "torch_rng": torch.get_rng_state(),
                               "config": asdict(cfg)}, state_path)

    def new_episodes(n: int) -> tuple[list[Any], np.ndarray]:
        """Fresh training episodes: a random house each, then a random target and start in it."""
        envs = rng.integers(0, len(worlds), n)
        return [task.sample_episode(worlds[e], rng) for e in envs.tolist()], envs

    sim = BatchSim(worlds, max_steps=cfg.max_episode_steps)
    teacher = make_teacher(cfg.teacher, sim, mix=cfg.teacher_mix, seed=cfg.seed)  # agents/teachers.py
    B, T, L = cfg.num_envs, cfg.rollout_steps, cfg.chunk_len
    eps, envs = new_episodes(B)
    obs, _ = sim.reset(eps, envs)
    h = net.initial_state(B)
    first = np.ones(B, dtype=bool)
    logger = RunLogger(run_dir, cfg.tensorboard)
    progress = _progress(cfg.progress)
    task_id = progress.add_task("DAgger", total=cfg.frames, completed=frames) if progress else None
    start = time.perf_counter()
    last_save = updates
    try:
        while frames < cfg.frames:
            # 1. collect a (T, B) block with the beta-mixture of expert and network
            beta = beta_at(cfg, frames)
            t0 = time.perf_counter()
            block = {"depth": np.empty((T, B, N_RAYS), np.float16), "semantic": np.empty((T, B, N_RAYS), np.uint8),
                     "target": np.empty((T, B), np.uint8), "prev_action": np.empty((T, B), np.uint8),
                     "collided": np.empty((T, B), np.uint8), "first": np.empty((T, B), np.bool_),
                     "label": np.empty((T, B), np.uint8), "h0": np.empty((T // L, B, hidden), np.float16)}
            ep_success, ep_length = [], []
            net.eval()
            for t in range(T):
                if t % L == 0:
                    block["h0"][t // L] = h.numpy()
                for k in ("depth", "semantic", "target", "prev_action", "collided"):
                    block[k][t] = obs[k]
                block["first"][t] = first
                labels = teacher.label(obs, first)
                block["label"][t] = labels
                with torch.no_grad():
                    logits, h = net.step(_to_tensors(obs), torch.from_numpy(first), h)
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
            buffer.add(block)
            frames += T * B
            iteration += 1
            collect_time = time.perf_counter() - t0

            # 2. learn: cross-entropy against the expert's labels on sequences from the whole dataset
            t0 = time.perf_counter()
            net.train()
            losses, accs = [], []
            for _ in range(cfg.updates_per_iter):
                lr = cfg.learning_rate * (max(0.0, 1.0 - frames / cfg.frames) if cfg.anneal_lr else 1.0)
                for group in optimizer.param_groups:
                    group["lr"] = lr
                batch = buffer.sample(cfg.batch_chunks, rng)
                logits, _ = net(batch, batch["first"], batch["h0"])
                loss = F.cross_entropy(logits.reshape(-1, logits.shape[-1]), batch["label"].reshape(-1))
                optimizer.zero_grad()
                loss.backward()
                torch.nn.utils.clip_grad_norm_(net.parameters(), cfg.max_grad_norm)
                optimizer.step()
                updates += 1
                losses.append(loss.item())
                accs.append((logits.argmax(-1) == batch["label"]).float().mean().item())
            train_time = time.perf_counter() - t0

            row: dict[str, Any] = {
                "iteration": iteration, "frames": frames, "updates": updates,
                "wall_time": wall_before + time.perf_counter() - start, "charts/beta": beta,
                "charts/learning_rate": lr, "charts/collect_fps": T * B / collect_time,
                "charts/train_fps": cfg.updates_per_iter * cfg.batch_chunks * L / train_time,
                "charts/episodes": len(ep_success),
                "charts/episode_success": float(np.mean(ep_success)) if ep_success else "",
                "charts/episode_length": float(np.mean(ep_length)) if ep_length else "",
                "charts/buffer_frames": buffer.frames, "losses/loss": float(np.mean(losses)),
                "losses/accuracy": float(np.mean(accs))}
            if cfg.eval_every and iteration % cfg.eval_every == 0:
                episodes = sample_episodes(worlds, cfg.eval_episodes, seed=cfg.seed * 100_003 + iteration)
                res, _ = run_episodes(worlds, episodes, NeuralPolicy(net, end_threshold=cfg.end_threshold), batch=min(cfg.eval_episodes, 128))
                s = summarize(res)
                row["eval/success"], row["eval/spl"] = s["success"], s["spl"]
            logger.log(row)
            if progress:
                progress.update(task_id, completed=min(frames, cfg.frames),
                                description=f"DAgger beta={beta:.2f} loss={row['losses/loss']:.3f} "
                                            f"acc={row['losses/accuracy']:.2f}"
                                            + (f" eval={row['eval/success']:.2f}" if "eval/success" in row else ""))
            if updates - last_save >= cfg.save_every:
                save_state()
                last_save = updates
    except KeyboardInterrupt:
        save_state()
        logger.close()
        if progress:
            progress.stop()
        raise
    if progress:
        progress.stop()

    # final evaluation of the greedy policy on fresh episodes in the training houses
    episodes = sample_episodes(worlds, cfg.final_eval_episodes, seed=cfg.seed + 7_919)
    res, _ = run_episodes(worlds, episodes, NeuralPolicy(net, end_threshold=cfg.end_threshold), batch=128)
    final = summarize(res)
    wall = wall_before + time.perf_counter() - start
    card = {
        "command": command, "houses": cfg.houses, "n_houses": len(worlds), "frames": frames, "updates": updates,
        "wall_time_s": round(wall, 1), "seed": cfg.seed, "parameters": count_parameters(net),
        "final_train_success": final["success"], "final_train_success_ci95": final["success_ci95"],
        "final_train_spl": final["spl"], "final_eval_episodes": final["episodes"],
        "end_threshold": cfg.end_threshold,
        "torch_threads": threads, "cpus": os.cpu_count(), "config": asdict(cfg)}
    logger.log({"iteration": iteration, "frames": frames, "updates": updates, "wall_time": wall,
                "eval/success": final["success"], "eval/spl": final["spl"]})
    logger.close()
    save_state()
    if cfg.output:
        save_checkpoint(cfg.output, net, {k: v for k, v in card.items() if k != "config"})
        Path(cfg.output).with_suffix(".json").write_text(json.dumps(card, indent=1) + "\n", encoding="utf-8")
    net.eval()
    return TrainResult(net, card, logger.rows)


def finetune(policy: Any, houses: Sequence[Any] | str, frames: int, *, seed: int = 0, **overrides: Any) -> Any:
    """Continue training ``policy`` (a NeuralPolicy or checkpoint path) on ``houses``; returns a new policy.

    ``houses`` may be House objects, NavWorlds or a ``--houses`` spec. DAgger keeps the expert in
    control 80% of the time (beta 0.8 throughout: with lower beta the student's success fell, see
    docs/agent.md); nothing is written unless ``output``/``run_dir`` is given in ``overrides`` (any
    TrainConfig field).
    """
    from adaptenv.agents.checkpoint import load_checkpoint
    from adaptenv.agents.houses import compile_houses, load_house_set

    net = load_checkpoint(policy).net if isinstance(policy, (str, Path)) else getattr(policy, "net", policy)
    worlds = load_house_set(houses).worlds if isinstance(houses, str) else compile_houses(list(houses))
    settings = {"frames": frames, "seed": seed, "output": "", "houses": "(in memory)", "beta_start": 0.8,
                "progress": False, "eval_every": 0, "final_eval_episodes": 64, **overrides}
    cfg = TrainConfig(**settings)
    return train(cfg, worlds=worlds, init_net=net).policy()


def _to_tensors(obs: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
    from adaptenv.agents.network import obs_to_tensors

    return obs_to_tensors(obs)


def _progress(enabled: bool):
    """A started rich progress bar, or None."""
    if not enabled:
        return None
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                        TimeRemainingColumn(), transient=False)
    progress.start()
    return progress
