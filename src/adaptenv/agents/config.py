"""The settings of ``adaptenv train`` as one dataclass (kept free of heavy imports for the CLI)."""

from __future__ import annotations

import ast
import inspect
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

PRECISIONS = ("auto", "fp32", "bf16")
"""Arithmetics of the gradient steps: fp32, bfloat16 autocast (forward in bf16, loss and weights in fp32), or auto
(bf16 where the CPU computes it natively, fp32 elsewhere: agents.network.auto_precision)."""


@dataclass
class TrainConfig:
    """Settings of one imitation-learning run (``adaptenv train``)."""

    houses: str = "preset:pretrain-train"
    """Training houses: a folder of house JSON files, one house file, a dataset FILE.jsonl[.gz][:START:STOP], or preset:NAME."""
    frames: int = 1_200_000
    """Labelled environment frames to collect (the training budget)."""
    output: str = "runs/policy.pt"
    """Policy checkpoint to write; its training card goes next to it with .json ('' writes none)."""
    init: str = ""
    """Start from this checkpoint (fine-tuning; 'pretrained' for the shipped one) instead of random weights."""
    seed: int = 0
    """Seed of torch, numpy and the episode sampler."""
    resume: bool = False
    """Continue an interrupted run from run_dir/state.pt (same config, larger --frames allowed)."""
    run_dir: str = ""
    """Folder for config.json, metrics.csv, TensorBoard logs and state.pt (default runs/train/<output stem>)."""
    num_envs: int = 256
    """Agents simulated in parallel while collecting."""
    rollout_steps: int = 64
    """Steps per agent per iteration (a multiple of chunk_len)."""
    chunk_len: int = 32
    """Length of the training sequences the GRU is unrolled through."""
    batch_chunks: int = 128
    """Sequences per gradient step (batch_chunks * chunk_len frames)."""
    updates_per_iter: int = 8
    """Gradient steps after each collection."""
    buffer_frames: int = 1_500_000
    """Size of the aggregated DAgger dataset (oldest blocks are dropped first)."""
    learning_rate: float = 1e-3
    """Adam learning rate."""
    anneal_lr: bool = True
    """Decay the learning rate linearly to zero over the run."""
    max_grad_norm: float = 1.0
    """Gradient clipping norm."""
    beta_start: float = 1.0
    """Probability of executing the expert's action at the start (1 = behaviour cloning)."""
    beta_end: float = 0.8
    """Probability of executing the expert's action at the end of the decay."""
    beta_decay_fraction: float = 0.5
    """Fraction of the frames over which beta falls linearly from beta_start to beta_end."""
    max_episode_steps: int = 300
    """Episode cap while collecting (evaluation uses the benchmark's 600)."""
    sample_actions: bool = True
    """Sample the network's own motions while collecting, as NeuralPolicy does (else its most likely motion)."""
    end_threshold: float = 0.8
    """The network ends an episode only with at least this probability of end while collecting (and in the saved policy unless calibrated)."""
    end_weight: float = 1.0
    """Weight of the end label in the cross-entropy (> 1 balances the rare stop labels; 1: plain imitation)."""
    calibrate_episodes: int = 200
    """Fresh episodes in the training houses on which the saved end threshold is chosen (agents/stop.py; 0: keep end_threshold)."""
    hidden: int = 256
    """GRU memory size."""
    feature_dim: int = 128
    """Size of the per-step feature vector fed to the GRU."""
    conv_channels: int = 32
    """Channels of the two ray convolutions."""
    map_dim: int = 128
    """Size of the map encoder's output (with map)."""
    map: bool = False
    """Give a fresh network the map memory it builds itself (adaptenv.sim.egomap) as an input beside the scan."""
    eval_every: int = 20
    """Evaluate the greedy policy on fresh training episodes every this many iterations (0: never)."""
    eval_episodes: int = 96
    """Episodes per periodic evaluation."""
    final_eval_episodes: int = 200
    """Episodes of the final evaluation on the training houses (recorded in the card)."""
    save_every: int = 200
    """Save the checkpoint and resume state every this many gradient updates."""
    threads: int = 0
    """Torch threads (0: every available core in the serial loop, one beside the learner thread; see configure_torch)."""
    overlap: bool = False
    """Run an iteration's gradient steps in a second thread while the next block is collected (its weights lag one iteration)."""
    progress: bool = True
    """Show a progress bar."""
    tensorboard: bool = True
    """Also log to TensorBoard when the tensorboard package is importable."""
    teacher: str = "expert"
    """Who labels DAgger's states: expert (shortest path), explorer (searches its own map), map-explorer (searches the
    EgoMap of its observations only) or mix."""
    teacher_mix: float = 0.5
    """With --teacher mix: share of episodes the explorer labels."""
    min_start_distance: float = 0.0
    """Episodes start this geodesic distance (m) or more from the target (0: any)."""
    precision: str = "auto"
    """Arithmetic of the gradient steps: auto (bf16 where the CPU computes it natively, else fp32), fp32, or bf16
    (autocast; about 2.4x faster on CPUs with AVX512_BF16, about 8x slower on AVX2-only ones)."""
    snapshots: int = 0
    """Also keep the policy after each 1/snapshots of the budget as OUTPUT stem + -f<frames>.pt (learning curves on
    validation houses; 0: none)."""
    perception: str = "labels"
    """What a fresh network perceives of the objects its rays hit: labels (their class) or shape (height and
    footprint only, the recognising mode; docs/agent.md). An --init checkpoint keeps its own."""


@dataclass
class PPOConfig:
    """Settings of one PPO run (``adaptenv ppo``): the simulator's SPOC-style reward, warm-started from a checkpoint."""

    houses: str = "preset:pretrain-train"
    """Training houses: a folder of house JSON files, one house file, a dataset FILE.jsonl[.gz][:START:STOP], or preset:NAME."""
    frames: int = 1_000_000
    """Environment frames to collect (the training budget)."""
    init: str = "pretrained"
    """Warm start: a checkpoint (e.g. from `adaptenv train`, BC/DAgger), 'pretrained' for the shipped one, '' for random weights."""
    output: str = "runs/ppo.pt"
    """Policy checkpoint to write; its training card goes next to it with .json ('' writes none)."""
    run_dir: str = ""
    """Folder for config.json, metrics.csv and TensorBoard logs (default runs/ppo/<output stem>)."""
    seed: int = 0
    """Seed of torch, numpy and the episode sampler."""
    num_envs: int = 64
    """Agents simulated in parallel while collecting."""
    rollout_steps: int = 128
    """Steps per agent per iteration (a multiple of chunk_len)."""
    chunk_len: int = 32
    """Length of the sequences the GRU is unrolled through in the update (stored memory at their starts)."""
    num_minibatches: int = 4
    """Minibatches per epoch (each num_envs * rollout_steps / num_minibatches frames)."""
    update_epochs: int = 4
    """Passes over each rollout."""
    learning_rate: float = 1e-4
    """Adam learning rate (small: fine-tuning a pretrained policy)."""
    anneal_lr: bool = True
    """Decay the learning rate linearly to zero over the run."""
    gamma: float = 0.99
    """Discount factor."""
    gae_lambda: float = 0.95
    """GAE lambda."""
    clip_coef: float = 0.2
    """PPO's surrogate clipping coefficient."""
    ent_coef: float = 0.01
    """Entropy bonus weight."""
    vf_coef: float = 0.5
    """Value loss weight."""
    max_grad_norm: float = 0.5
    """Gradient clipping norm."""
    target_kl: float = 0.0
    """Stop an iteration's epochs early when the approximate KL exceeds this (0: never)."""
    bc_coef: float = 0.0
    """Weight of an auxiliary cross-entropy to bc_teacher's labels of the visited states (a DAgger regulariser; 0: pure RL)."""
    bc_teacher: str = "expert"
    """Who labels the states for bc_coef: expert (shortest path, knows the target), explorer or map-explorer (search) or mix."""
    kl_coef: float = 0.0
    """Weight of KL(pi || pi_0) to the frozen warm start on the visited states, over the acting rule's distribution (an anchor; 0: off)."""
    explore_bonus: float = 0.0
    """Reward per fine map cell (0.2 m) an agent sees for the first time in its episode, from its own map (suggested 0.002; 0: off)."""
    value_warmup_iters: int = 4
    """First iterations train only the value head, so a warm-started policy is not moved by a random critic."""
    freeze_encoder: bool = False
    """Keep the observation encoder (scan, map, embeddings) at the warm start's weights and train the memory and heads:
    its features are computed once while collecting and the updates skip it (faster: docs/BENCHMARKS.md)."""
    precision: str = "auto"
    """Arithmetic of the update's minibatch passes: auto (bf16 where the CPU computes it natively, else fp32), fp32,
    or bf16 autocast (faster on CPUs with AVX512_BF16, slower on others;
    collection and pi_0's anchor logits stay fp32; docs/BENCHMARKS.md)."""
    stop_rule: str = "threshold"
    """How end is chosen while collecting: 'threshold' (as the saved policy acts; RL trains the motions) or 'sample' (from the full softmax)."""
    end_threshold: float = 0.8
    """End threshold while collecting with stop_rule 'threshold' (and in the saved policy unless calibrated)."""
    calibrate_episodes: int = 200
    """Fresh episodes in the training houses on which the saved end threshold is chosen (agents/stop.py; 0: keep end_threshold)."""
    max_episode_steps: int = 300
    """Episode cap while collecting (evaluation uses the benchmark's 600)."""
    hidden: int = 256
    """GRU memory size (with init '')."""
    feature_dim: int = 128
    """Size of the per-step feature vector (with init '')."""
    conv_channels: int = 32
    """Channels of the two ray convolutions (with init '')."""
    map_dim: int = 128
    """Size of the map encoder's output (with init '' and map)."""
    eval_every: int = 10
    """Evaluate the policy every this many iterations, and the warm start before any update, on one fixed set of
    fresh training-house episodes started min_start_distance or farther (0: never)."""
    eval_episodes: int = 96
    """Episodes per periodic evaluation."""
    final_eval_episodes: int = 200
    """Episodes of the final evaluation on the training houses (recorded in the card)."""
    min_start_distance: float = 0.0
    """Episodes start this geodesic distance (m) or more from the target (0: any)."""
    threads: int = 0
    """Torch threads (0: every available core; see configure_torch)."""
    progress: bool = True
    """Show a progress bar."""
    tensorboard: bool = True
    """Also log to TensorBoard when the tensorboard package is importable."""


@dataclass
class FinetuneConfig:
    """Settings of one fine-tuning run on houses held in memory (``agents.train.finetune``; what the loop calls)."""

    algo: str = "dagger"
    """Learning algorithm: 'dagger' (imitation of the shortest-path expert) or 'ppo' (the simulator's reward)."""
    frames: int = 16_384
    """Environment frames to collect."""
    num_envs: int = 64
    """Agents simulated in parallel."""
    learning_rate: float = 1e-4
    """Adam learning rate, annealed linearly to zero over the run."""
    rollout_steps: int = 32
    """Steps per agent per iteration (DAgger: also the sequence length)."""
    batch_chunks: int = 64
    """DAgger: sequences per gradient step."""
    updates_per_iter: int = 4
    """DAgger: gradient steps after each collection."""
    beta: float = 0.8
    """DAgger: probability of executing the expert's action, constant over the run."""
    end_threshold: float = 0.8
    """End threshold while collecting."""
    teacher: str = "expert"
    """Who labels the visited states (DAgger; PPO with bc_coef): 'expert' (shortest path), 'explorer', 'map-explorer'
    (search) or 'mix'."""
    calibrate_episodes: int = 0
    """Fresh episodes in the training houses on which the returned card's end threshold is chosen (0: keep end_threshold)."""
    final_eval_episodes: int = 0
    """Episodes of the final evaluation on the training houses (0: one per house)."""
    min_start_distance: float = 0.0
    """Training episodes start at least this geodesic distance (m) from the target where the house allows (0: uniform)."""
    precision: str = "auto"
    """Arithmetic of the gradient steps, auto, fp32 or bf16 (TrainConfig.precision, PPOConfig.precision)."""
    max_episode_steps: int = 300
    """Episode cap while collecting (the evaluation's is 600)."""
    kl_coef: float = 0.0
    """PPO: weight of the KL anchor to the starting policy (PPOConfig.kl_coef; 0: off)."""
    explore_bonus: float = 0.0
    """PPO: reward per newly seen fine map cell (PPOConfig.explore_bonus; 0: off)."""
    freeze_encoder: bool = False
    """PPO: train the memory and heads only, the observation encoder fixed (PPOConfig.freeze_encoder)."""
    bc_coef: float = 0.0
    """PPO: weight of a cross-entropy to ``teacher``'s labels of the visited states (PPOConfig.bc_coef; 0: off)."""


def field_docs(cls: type) -> dict[str, str]:
    """The docstring under each dataclass field (CleanRL-style help text)."""
    tree = ast.parse(inspect.getsource(cls))
    body = tree.body[0].body  # type: ignore[attr-defined]
    docs = {}
    for node, nxt in zip(body, body[1:], strict=False):
        if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
                and isinstance(nxt, ast.Expr) and isinstance(getattr(nxt, "value", None), ast.Constant)):
            docs[node.target.id] = str(nxt.value.value)
    return docs


def changed_settings(saved: dict[str, Any], current: dict[str, Any], may_change: Sequence[str] = ()) -> list[str]:
    """``name (was A, now B)`` for each setting that differs between two config dicts, except ``may_change``."""
    unset = object()
    changed = []
    for k in sorted(set(saved) | set(current)):
        old, new = saved.get(k, unset), current.get(k, unset)
        if k not in may_change and old != new:
            changed.append(f"{k} (was {'unset' if old is unset else repr(old)}, now "
                           f"{'unset' if new is unset else repr(new)})")
    return changed
