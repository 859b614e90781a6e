"""PPO fine-tuning of the navigation policy on the simulator's SPOC-style shaped reward.

One readable file in CleanRL's manner (``ppo_atari_lstm.py``), configured by one dataclass
(:class:`~adaptenv.agents.config.PPOConfig`, whose field docstrings are the ``adaptenv ppo --help``
text and which is saved as ``config.json`` in the run folder). The reward is ``BatchSim``'s::

    r = -0.01 + max(0, best - d) + 10 * success

(``d`` the geodesic distance to the target's success region, ``best`` the smallest ``d`` so far),
plus, when ``explore_bonus`` > 0, ``explore_bonus`` per fine map cell the agent sees for the first time in its
episode (:class:`ExplorationBonus`; not counted in ``charts/episodic_return``).

Each iteration:

1. **Collect** ``rollout_steps`` steps of ``num_envs`` agents in a :class:`BatchSim` over the
   training houses (a finished episode is replaced at once by a fresh one), storing observations,
   episode-start flags, actions, log-probabilities, values, rewards, and the GRU memory at every
   ``chunk_len``-th step. With ``stop_rule='threshold'`` the agent acts exactly as the saved
   :class:`NeuralPolicy` does: ``end`` iff its probability >= ``end_threshold``, otherwise a motion
   sampled from the softmax over the six motions; the stop is then a deterministic rule, so RL
   trains the motions (searching) and the stop head keeps what imitation taught it (plus
   ``bc_coef``'s labels; the saved threshold is re-calibrated on held-in episodes at the end, see
   :mod:`adaptenv.agents.stop`). With ``stop_rule='sample'`` every action, ``end`` included, is
   drawn from the full softmax.
2. **Advantages** by GAE(``gamma``, ``gae_lambda``); a finished episode (``end`` or the step cap)
   does not bootstrap (CleanRL's choice: truncation is treated as termination).
3. **Learn**: ``update_epochs`` passes over the rollout in ``num_minibatches`` minibatches of
   ``chunk_len``-step sequences (GRU memory at a sequence start: the stored one, reset where an
   episode starts), with PPO's clipped surrogate, a value loss, an entropy bonus and, when
   ``bc_coef`` > 0, cross-entropy to ``bc_teacher``'s labels of the visited states
   (:mod:`adaptenv.agents.teachers`), and, when ``kl_coef`` > 0, ``KL(pi || pi_0)`` to a frozen copy of the
   warm start run over the same sequences (:func:`anchor_kl`; logged always as ``losses/kl_anchor``).
   For the first ``value_warmup_iters`` iterations only the value head learns (it reads the
   policy's memory and features, detached), so a random critic cannot move a warm-started policy.
   With ``freeze_encoder`` the observation encoder keeps the warm start's weights: its features are
   stored while collecting, and the update and the anchor run only the memory and heads on them.
   With ``precision='bf16'`` the minibatch passes run under CPU bf16 autocast (logits and values cast
   back to fp32 for the losses); collection and pi_0's anchor logits stay fp32.

Warm start: ``init`` is a checkpoint written by ``adaptenv train`` (behaviour cloning + DAgger)
or ``pretrained``. Outputs: the policy checkpoint at ``output`` (the network only; the value head
is not needed to act) with its card, and in ``run_dir`` ``config.json``, ``metrics.csv`` and
TensorBoard events.
"""

from __future__ import annotations

import copy
import json
import os
import time
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from adaptenv.agents.checkpoint import load_checkpoint, non_finite_weight, save_checkpoint
from adaptenv.agents.config import PPOConfig
from adaptenv.agents.evaluate import run_episodes, sample_episodes, summarize
from adaptenv.agents.houses import load_house_set
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
    torch_threads,
)
from adaptenv.agents.registry import init_checkpoint
from adaptenv.agents.runlog import (
    RunLogger,
    TrainResult,
    card_config,
    check_finite,
    check_precision,
)
from adaptenv.agents.stop import calibrate_end_threshold
from adaptenv.agents.suites import EpisodeFloor
from adaptenv.agents.teachers import TEACHERS, make_teacher
from adaptenv.errors import ConfigError, TrainingDiverged
from adaptenv.files import atomic_write_text
from adaptenv.limits import check_numbers
from adaptenv.progress import ProgressBar
from adaptenv.sim.egomap import EgoMap
from adaptenv.sim.spec import END, N_RAYS
from adaptenv.sim.vector import BatchSim, EpisodeSampler

__all__ = ["PPOConfig", "ActorCritic", "ExplorationBonus", "anchor_kl", "train_ppo", "check_ppo_config"]

PPO_LOG_KEYS = ("iteration", "frames", "updates", "wall_time", "charts/learning_rate", "charts/SPS",
                "charts/collect_fps", "charts/episodes", "charts/episodic_return", "charts/episode_success",
                "charts/episode_length", "losses/value_loss", "losses/policy_loss", "losses/entropy",
                "charts/explore_bonus", "losses/bc_loss", "losses/kl_anchor", "losses/approx_kl", "losses/clipfrac",
                "losses/explained_variance", "eval/success", "eval/spl")


def check_ppo_config(cfg: PPOConfig) -> None:
    """Raise one ConfigError for the first inconsistent setting (naming the flag and the fix)."""
    check_numbers(cfg)
    if cfg.rollout_steps % cfg.chunk_len:
        raise ConfigError(f"--rollout-steps ({cfg.rollout_steps}) must be a multiple of --chunk-len ({cfg.chunk_len})")
    sequences = cfg.num_envs * (cfg.rollout_steps // cfg.chunk_len)
    if sequences % cfg.num_minibatches:
        raise ConfigError(f"--num-minibatches ({cfg.num_minibatches}) must divide the rollout's {sequences} "
                          "sequences (num_envs * rollout_steps / chunk_len)")
    if cfg.bc_teacher not in TEACHERS:
        raise ConfigError(f"--bc-teacher {cfg.bc_teacher!r}: unknown teacher; choose one of {', '.join(TEACHERS)}")
    if cfg.stop_rule not in ("threshold", "sample"):
        raise ConfigError(f"--stop-rule must be 'threshold' or 'sample', got {cfg.stop_rule!r}")
    check_precision(cfg.precision, "--precision")


class ActorCritic(nn.Module):
    """A :class:`NavNet` (the actor: its own head) plus a value head reading the same memory and features."""

    def __init__(self, net: NavNet):
        super().__init__()
        self.net = net
        c = net.config
        self.value = nn.Sequential(nn.Linear(c.hidden + c.feature_dim, 128), nn.Tanh(), nn.Linear(128, 1))

    def forward(self, obs: dict[str, torch.Tensor], done: torch.Tensor, h0: torch.Tensor, *,
                detach_value: bool = False) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Logits (T, B, A), values (T, B) and the final memory of a (T, B) sequence."""
        return self.from_features(self.net.encode(obs), done, h0, detach_value=detach_value)

    def from_features(self, feats: torch.Tensor, done: torch.Tensor, h0: torch.Tensor, *,
                      detach_value: bool = False) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """:meth:`forward` from the encoder's features (T, B, feature_dim), e.g. a frozen encoder's stored ones."""
        z, h = self.net.recur(feats, done, h0)
        value = self.value(z.detach() if detach_value else z).squeeze(-1)
        return self.net.head(z), value, h


def _learner(net: NavNet, freeze_encoder: bool, learning_rate: float) -> tuple[ActorCritic, torch.optim.Adam]:
    """The actor-critic around ``net`` and its Adam optimizer, as :func:`train_ppo` makes them."""
    for module in net.encoder_modules() if freeze_encoder else ():
        module.requires_grad_(False)
    agent = ActorCritic(net)
    return agent, torch.optim.Adam([p for p in agent.parameters() if p.requires_grad], lr=learning_rate, eps=1e-5)


def learner_problem(learner: Any, net: NavNet, freeze_encoder: bool) -> str | None:
    """Why ``learner`` (a saved ``{"value", "optimizer"}`` state) cannot continue PPO on ``net``, or None: it is
    loaded into a copy of what :func:`train_ppo` builds, and every tensor must be finite."""
    if not isinstance(learner, dict) or not {"value", "optimizer"} <= set(learner):
        return "not a learner state (expected the value head and optimizer state the loop saves)"
    tensors = [t for t in learner["value"].values()] if isinstance(learner["value"], dict) else []
    tensors += [t for st in (learner["optimizer"].get("state") or {}).values() if isinstance(st, dict)
                for t in st.values()] if isinstance(learner["optimizer"], dict) else []
    if any(isinstance(t, torch.Tensor) and t.is_floating_point() and not bool(torch.isfinite(t).all())
           for t in tensors):
        return "its value head or optimizer state holds NaN or infinite values"
    agent, optimizer = _learner(copy.deepcopy(net), freeze_encoder, 1e-4)
    try:
        agent.value.load_state_dict(learner["value"])
        optimizer.load_state_dict(copy.deepcopy(learner["optimizer"]))
    except (KeyError, RuntimeError, TypeError, ValueError, AttributeError, IndexError) as exc:
        return f"it does not fit this policy's network ({type(exc).__name__})"
    return None


def acting_log_probs(logits: torch.Tensor, stop_rule: str) -> torch.Tensor:
    """Log-probabilities (..., A) of the distribution actions are drawn from.

    ``threshold``: the six motions (``end`` is a deterministic rule, -inf here); ``sample``: the full softmax.
    """
    if stop_rule == "threshold":
        logits = logits.masked_fill(torch.arange(logits.shape[-1]) == END, float("-inf"))
    return torch.log_softmax(logits, -1)


def log_prob_entropy(logits: torch.Tensor, actions: torch.Tensor, stop_rule: str
                     ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Log-probability of ``actions`` under the acting distribution, its entropy, and which actions were drawn from it."""
    drawn = actions != END if stop_rule == "threshold" else torch.ones_like(actions, dtype=torch.bool)
    logp = acting_log_probs(logits, stop_rule)
    chosen = logp.gather(-1, actions.clamp(max=logits.shape[-1] - 1)[..., None]).squeeze(-1)
    p = logp.exp()
    entropy = -(p * torch.where(p > 0, logp, torch.zeros_like(logp))).sum(-1)
    return torch.where(drawn, chosen, torch.zeros_like(chosen)), entropy, drawn


def kl_divergence(logp: torch.Tensor, logq: torch.Tensor) -> torch.Tensor:
    """``KL(p || q)`` over the last axis from log-probabilities (terms where p is 0 count 0)."""
    p = logp.exp()
    return (p * torch.where(p > 0, logp - logq, torch.zeros_like(logp))).sum(-1)


def stop_log_probs(logits: torch.Tensor) -> torch.Tensor:
    """``log (p(end), 1 - p(end))`` (..., 2) under the full softmax: the Bernoulli the threshold rule reads."""
    logp = torch.log_softmax(logits, -1)
    is_end = torch.arange(logits.shape[-1]) == END
    return torch.stack([logp[..., END], torch.logsumexp(logp.masked_fill(is_end, float("-inf")), -1)], -1)


def anchor_kl(logits: torch.Tensor, anchor_logits: torch.Tensor, stop_rule: str) -> torch.Tensor:
    """Per-state ``KL(pi || pi_0)`` (...,) of the acting rule: ``pi`` from ``logits``, ``pi_0`` from ``anchor_logits``."""
    # Direction: that of KL-regularised RL (KL control, RLHF): maximising return - kl_coef * KL(pi || pi_0) has the
    # optimum pi_0 * exp(Q / kl_coef) / Z, which re-weights pi_0's own choices by their value. It is mode-seeking:
    # pi may drop actions of pi_0 that lead nowhere at a bounded cost but pays heavily for actions pi_0 rules out.
    # The reverse, KL(pi_0 || pi), is distillation to pi_0 (kickstarting) and would keep pi as broad as pi_0.
    # Distribution: 'sample' draws from the full softmax, so its KL. 'threshold' reads p(end) (stop iff >= the
    # threshold) and otherwise draws one of the six motions, so both parts are anchored: the KL of the Bernoulli
    # p(end) plus that of the motion softmax (the full softmax's KL by the chain rule, the motion term weighted 1
    # rather than 1 - p(end), since the motions are drawn whenever the rule does not stop).
    kl = kl_divergence(acting_log_probs(logits, stop_rule), acting_log_probs(anchor_logits, stop_rule))
    if stop_rule == "threshold":
        kl = kl + kl_divergence(stop_log_probs(logits), stop_log_probs(anchor_logits))
    return kl


@torch.no_grad()
def anchor_rollout_logits(anchor: NavNet, obs: dict[str, torch.Tensor] | torch.Tensor, first: torch.Tensor,
                          h: torch.Tensor, chunk_len: int) -> tuple[torch.Tensor, torch.Tensor]:
    """pi_0's logits (T, B, A) over a whole rollout with its own memory ``h`` (B, H) carried in, and the memory after.

    ``obs`` is the observations, or the features (T, B, feature_dim) of an encoder pi_0 shares. Unrolled in
    ``chunk_len``-step pieces (the update's sequence length) to bound the memory of the map encoder.
    """
    pieces = []
    for lo in range(0, first.shape[0], chunk_len):
        done = first[lo: lo + chunk_len]
        if isinstance(obs, torch.Tensor):
            z, h = anchor.recur(obs[lo: lo + chunk_len], done, h)
            logits = anchor.head(z)
        else:
            logits, h = anchor({k: v[lo: lo + chunk_len] for k, v in obs.items()}, done, h)
        pieces.append(logits)
    return torch.cat(pieces), h


class ExplorationBonus:
    """Fine map cells each agent sees (FREE or OBSTACLE set) for the first time in its episode, step by step.

    Reads the :class:`EgoMap` of a map-reading network's :class:`MapObserver` (which updates it), or keeps one
    of its own, built only from the agent's observations (nothing privileged).
    """

    def __init__(self, batch: int, observer: MapObserver | None):
        self.observer = observer
        self.emap = observer.emap if observer is not None else EgoMap(batch)
        self.seen = np.zeros(batch, np.int64)

    def __call__(self, obs: dict[str, np.ndarray], first: np.ndarray) -> np.ndarray:
        """int64 (B,): cells first seen in ``obs`` (0 where ``first``); call once per step, after :func:`observe`."""
        if self.observer is None:
            self.emap.update(obs, first)
        seen = self.emap.seen_counts()
        new = np.where(first, 0, seen - self.seen)
        self.seen = seen
        return new


def sample_actions(logits: torch.Tensor, u: np.ndarray, stop_rule: str, end_threshold: float) -> np.ndarray:
    """Actions by the acting rule (see :func:`log_prob_entropy`) from uniforms ``u`` (B,)."""
    if stop_rule == "threshold":
        return choose_actions(logits, u, end_threshold)
    cdf = np.cumsum(torch.softmax(logits.float(), -1).numpy(), -1)
    return np.minimum((cdf < (u * cdf[:, -1])[:, None]).sum(-1), logits.shape[-1] - 1).astype(np.int64)


def default_ppo_run_dir(cfg: PPOConfig) -> Path | None:
    if cfg.run_dir:
        return Path(cfg.run_dir)
    return Path("runs/ppo") / Path(cfg.output).stem if cfg.output else None


def _initial_net(cfg: PPOConfig, init_net: NavNet | None) -> NavNet:
    """A copy of ``init_net``, else the ``init`` checkpoint, else fresh weights."""
    if init_net is not None:
        net = NavNet(init_net.config)
        net.load_state_dict(init_net.state_dict())
        return net
    if cfg.init:
        return load_checkpoint(init_checkpoint(cfg.init)).net
    return NavNet(NetConfig.of(cfg))


def train_ppo(cfg: PPOConfig, *, worlds: Sequence[Any] | None = None, init_net: NavNet | None = None,
              learner: dict[str, Any] | None = None, command: str = "") -> TrainResult:
    """Run PPO as configured; returns the trained network, its card, the logged rows and the learner state (value
    head and optimizer) that ``learner`` takes to continue the run later (torch's thread count is the caller's
    again afterwards)."""
    check_ppo_config(cfg)
    with torch_threads(cfg.threads or available_cores()) as threads:
        return _train_ppo(cfg, worlds, init_net, learner, command, threads)


def _train_ppo(cfg: PPOConfig, worlds: Sequence[Any] | None, init_net: NavNet | None,
               learner: dict[str, Any] | None, command: str, threads: int) -> TrainResult:
    run_dir = default_ppo_run_dir(cfg)
    precision = resolve_precision(cfg.precision)  # what "auto" means on this CPU; the card records it
    if run_dir:
        run_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(run_dir / "config.json", json.dumps(asdict(cfg), indent=1) + "\n")
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    worlds = list(worlds) if worlds is not None else load_house_set(cfg.houses).worlds
    net = _initial_net(cfg, init_net)
    anchor = copy.deepcopy(net).eval().requires_grad_(False)  # pi_0, frozen
    freeze = cfg.freeze_encoder  # the encoder keeps pi_0's weights: its features are computed once, while collecting
    agent, optimizer = _learner(net, freeze, cfg.learning_rate)
    if learner is not None:  # a previous run's critic and Adam moments: this run continues it
        agent.value.load_state_dict(learner["value"])
        optimizer.load_state_dict(copy.deepcopy(learner["optimizer"]))  # Adam steps its tensors in place
    B, T, L = cfg.num_envs, cfg.rollout_steps, cfg.chunk_len
    H = net.config.hidden
    n_iterations = -(-cfg.frames // (B * T))

    # storage of one rollout (CleanRL's buffers), numpy on the collection side
    obs_buf = {"depth": np.zeros((T, B, N_RAYS), np.float32), "semantic": np.zeros((T, B, N_RAYS), np.int64),
               "target": np.zeros((T, B), np.int64), "prev_action": np.zeros((T, B), np.int64),
               "collided": np.zeros((T, B), np.int64)}
    observer = MapObserver.of(net, B)
    if observer is not None:
        obs_buf["map"] = np.zeros((T, B, net.config.map_crop, net.config.map_crop), np.uint8)
    if net.config.shape_features:
        obs_buf["shape"] = np.zeros((T, B, net.config.n_rays, net.config.shape_features), np.float32)
    first_buf = np.zeros((T, B), np.bool_)
    actions_buf = np.zeros((T, B), np.int64)
    logprobs_buf = np.zeros((T, B), np.float32)
    values_buf = np.zeros((T, B), np.float32)
    rewards_buf = np.zeros((T, B), np.float32)
    labels_buf = np.zeros((T, B), np.int64)
    h0_buf = torch.zeros(T // L, B, H)
    feats_buf = torch.zeros(T, B, net.config.feature_dim) if freeze else None

    sampler = EpisodeSampler(worlds, min_distance=cfg.min_start_distance)
    sim = BatchSim(worlds, max_steps=cfg.max_episode_steps, shapes=bool(net.config.shape_features))
    teacher = (make_teacher(cfg.bc_teacher, sim, seed=cfg.seed, emap=observer.emap if observer else None)
               if cfg.bc_coef > 0 else None)
    obs, _ = sim.reset(*sampler.draw(rng, B))
    first = np.ones(B, dtype=bool)
    obs = observe(observer, obs, first)
    explore = ExplorationBonus(B, observer) if cfg.explore_bonus > 0 else None
    if explore is not None:
        explore(obs, first)
    h = net.initial_state(B)
    h_anchor = anchor.initial_state(B)
    episode_return = np.zeros(B)
    logger = RunLogger(run_dir, cfg.tensorboard, PPO_LOG_KEYS)
    progress = ProgressBar("PPO" if cfg.progress else None, n_iterations * B * T, transient=False).start()
    frames, updates = 0, 0
    eval_episodes = sample_episodes(worlds, cfg.eval_episodes, seed=cfg.seed * 100_003,
                                    floor=EpisodeFloor(min_geodesic=cfg.min_start_distance))

    def evaluate_held_in(network: NavNet) -> tuple[float, float]:
        """Success and SPL on the same fresh training-house episodes every time, so the curve is paired."""
        res, _ = run_episodes(worlds, eval_episodes, NeuralPolicy(network, end_threshold=cfg.end_threshold),
                              batch=min(cfg.eval_episodes, 128))
        s = summarize(res)
        return s["success"], s["spl"]

    if cfg.eval_every:  # pi_0 on the same episodes: the curve's starting point
        success0, spl0 = evaluate_held_in(net)
        logger.log({"iteration": 0, "frames": 0, "updates": 0, "wall_time": 0.0,
                    "eval/success": success0, "eval/spl": spl0})
    start = time.perf_counter()
    for iteration in range(1, n_iterations + 1):
        lr = cfg.learning_rate * ((1.0 - (iteration - 1) / n_iterations) if cfg.anneal_lr else 1.0)
        for group in optimizer.param_groups:
            group["lr"] = lr

        # 1. collect a (T, B) rollout with the current policy
        t0 = time.perf_counter()
        finished_returns, finished_success, finished_length = [], [], []
        bonus_sum = 0.0
        agent.eval()
        for t in range(T):
            if t % L == 0:
                h0_buf[t // L] = h
            for k in obs_buf:
                obs_buf[k][t] = obs[k]
            first_buf[t] = first
            if teacher is not None:
                labels_buf[t] = teacher.label(obs, first)
            with torch.no_grad():
                feats = net.encode({k: v[None] for k, v in obs_to_tensors(obs).items()})
                if feats_buf is not None:
                    feats_buf[t] = feats[0]
                logits, value, h = agent.from_features(feats, torch.from_numpy(first)[None], h)
                logits, value = logits[0], value[0]
                action = sample_actions(logits, rng.random(B), cfg.stop_rule, cfg.end_threshold)
                logprob, _, _ = log_prob_entropy(logits, torch.from_numpy(action), cfg.stop_rule)
            actions_buf[t], logprobs_buf[t], values_buf[t] = action, logprob.numpy(), value.numpy()
            obs, reward, terminated, truncated, info = sim.step(action)
            episode_return += reward
            finished = np.flatnonzero(terminated | truncated)
            first = np.zeros(B, dtype=bool)
            if finished.size:
                finished_returns += episode_return[finished].tolist()
                finished_success += info["success"][finished].tolist()
                finished_length += info["steps"][finished].tolist()
                episode_return[finished] = 0.0
                obs = sim.reset_at(finished, *sampler.draw(rng, finished.size))
                first[finished] = True
            obs = observe(observer, obs, first)
            # the cells revealed by this step's observation reward its action (nothing where an episode ended)
            bonus = cfg.explore_bonus * explore(obs, first) if explore is not None else 0.0
            rewards_buf[t] = reward + bonus
            bonus_sum += float(np.sum(bonus))
        frames += B * T
        collect_time = time.perf_counter() - t0

        # 2. advantages by GAE; a new episode at t+1 cuts the bootstrap
        with torch.no_grad():
            seq = {k: v[None] for k, v in obs_to_tensors(obs).items()}
            _, next_value, _ = agent(seq, torch.from_numpy(first)[None], h)
            next_value = next_value[0].numpy()
        advantages = np.zeros((T, B), np.float32)
        last_gae = np.zeros(B, np.float32)
        for t in reversed(range(T)):
            next_nonterminal = 1.0 - (first if t == T - 1 else first_buf[t + 1]).astype(np.float32)
            next_values = next_value if t == T - 1 else values_buf[t + 1]
            delta = rewards_buf[t] + cfg.gamma * next_values * next_nonterminal - values_buf[t]
            last_gae = delta + cfg.gamma * cfg.gae_lambda * next_nonterminal * last_gae
            advantages[t] = last_gae
        returns = advantages + values_buf

        # 3. learn: clipped surrogate + value + entropy (+ imitation, + the anchor), on chunk_len-step sequences
        agent.train()
        warmup = iteration <= cfg.value_warmup_iters
        b_obs = {k: torch.from_numpy(v) for k, v in obs_buf.items()}
        b_first, b_actions = torch.from_numpy(first_buf), torch.from_numpy(actions_buf)
        # pi_0 over the same observations (map included) with its own memory of the same histories
        b_anchor_logits, h_anchor = anchor_rollout_logits(anchor, b_obs if feats_buf is None else feats_buf,
                                                          b_first, h_anchor, L)
        b_logprobs, b_adv = torch.from_numpy(logprobs_buf), torch.from_numpy(advantages)
        b_returns, b_labels = torch.from_numpy(returns), torch.from_numpy(labels_buf)
        n_chunks = T // L
        seq_ids = np.arange(n_chunks * B)  # sequence s = chunk s // B of env s % B
        mb_size = seq_ids.size // cfg.num_minibatches
        stats: dict[str, list[float]] = {k: [] for k in ("v", "pg", "ent", "bc", "anchor", "kl", "clip")}
        for _epoch in range(cfg.update_epochs):
            rng.shuffle(seq_ids)
            for lo in range(0, seq_ids.size, mb_size):
                mb = seq_ids[lo: lo + mb_size]
                chunk, env = mb // B, mb % B
                tt = chunk[None, :] * L + np.arange(L)[:, None]  # (L, mb)
                idx = (torch.from_numpy(tt), torch.from_numpy(env)[None, :])
                with torch.autocast("cpu", dtype=torch.bfloat16, enabled=precision == "bf16"):
                    if feats_buf is None:
                        logits, new_value, _ = agent({k: v[idx] for k, v in b_obs.items()}, b_first[idx],
                                                     h0_buf[chunk, env], detach_value=warmup)
                    else:
                        logits, new_value, _ = agent.from_features(feats_buf[idx], b_first[idx],
                                                                   h0_buf[chunk, env], detach_value=warmup)
                logits, new_value = logits.float(), new_value.float()  # the losses in fp32 whatever the precision
                new_logprob, entropy, drawn = log_prob_entropy(logits, b_actions[idx], cfg.stop_rule)
                log_ratio = new_logprob - b_logprobs[idx]
                ratio = log_ratio.exp()
                w = drawn.float()
                with torch.no_grad():
                    approx_kl = (((ratio - 1) - log_ratio) * w).sum() / w.sum().clamp(min=1)
                    clipfrac = (((ratio - 1.0).abs() > cfg.clip_coef).float() * w).sum() / w.sum().clamp(min=1)
                adv = b_adv[idx]
                adv = (adv - adv.mean()) / (adv.std() + 1e-8)
                pg_loss = (torch.max(-adv * ratio, -adv * ratio.clamp(1 - cfg.clip_coef, 1 + cfg.clip_coef))
                           * w).sum() / w.sum().clamp(min=1)
                v_loss = 0.5 * ((new_value - b_returns[idx]) ** 2).mean()
                ent = entropy.mean()
                bc_loss = (F.cross_entropy(logits.reshape(-1, logits.shape[-1]), b_labels[idx].reshape(-1))
                           if teacher is not None else torch.zeros(()))
                kl_anchor = anchor_kl(logits, b_anchor_logits[idx], cfg.stop_rule).mean()
                if warmup:
                    loss = cfg.vf_coef * v_loss
                else:
                    loss = pg_loss - cfg.ent_coef * ent + cfg.vf_coef * v_loss + cfg.bc_coef * bc_loss
                    if cfg.kl_coef:
                        loss = loss + cfg.kl_coef * kl_anchor
                optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), cfg.max_grad_norm)
                optimizer.step()
                updates += 1
                for key, val in (("v", v_loss), ("pg", pg_loss), ("ent", ent), ("bc", bc_loss),
                                 ("anchor", kl_anchor), ("kl", approx_kl), ("clip", clipfrac)):
                    stats[key].append(float(val.detach()))
            if cfg.target_kl and not warmup and stats["kl"][-1] > cfg.target_kl:
                break
        y_var = np.var(returns)
        explained = float("nan") if y_var == 0 else float(1 - np.var(returns - values_buf) / y_var)

        elapsed = time.perf_counter() - start
        row: dict[str, Any] = {
            "iteration": iteration, "frames": frames, "updates": updates, "wall_time": elapsed,
            "charts/learning_rate": lr, "charts/SPS": frames / elapsed, "charts/collect_fps": B * T / collect_time,
            "charts/episodes": len(finished_returns),
            "charts/episodic_return": float(np.mean(finished_returns)) if finished_returns else "",
            "charts/episode_success": float(np.mean(finished_success)) if finished_success else "",
            "charts/episode_length": float(np.mean(finished_length)) if finished_length else "",
            "charts/explore_bonus": bonus_sum / (B * T), "losses/kl_anchor": float(np.mean(stats["anchor"])),
            "losses/value_loss": float(np.mean(stats["v"])), "losses/policy_loss": float(np.mean(stats["pg"])),
            "losses/entropy": float(np.mean(stats["ent"])), "losses/bc_loss": float(np.mean(stats["bc"])),
            "losses/approx_kl": float(np.mean(stats["kl"])), "losses/clipfrac": float(np.mean(stats["clip"])),
            "losses/explained_variance": explained}
        if non_finite_weight(agent) is not None:  # PPO saves only at the end: nothing is written
            logger.close()
            if progress:
                progress.stop()
            check_finite(net, cfg, frames, 0)
            raise TrainingDiverged(f"training diverged after {frames:,} frames: the value head's weights hold NaN "
                                   f"or infinite values; no checkpoint was written; lower --learning-rate (now "
                                   f"{cfg.learning_rate:g}) or --max-grad-norm (now {cfg.max_grad_norm:g})")
        if cfg.eval_every and iteration % cfg.eval_every == 0:
            row["eval/success"], row["eval/spl"] = evaluate_held_in(net)
        logger.log(row)
        if progress:
            progress.update(frames,
                            description=f"PPO return={row['charts/episodic_return'] or 0:.2f} "
                                        f"success={row['charts/episode_success'] or 0:.2f}"
                                        + (f" eval={row['eval/success']:.2f}" if "eval/success" in row else ""))
    if progress:
        progress.stop()

    # the stop decision on fresh held-in episodes, then the final evaluation on the training houses
    net.eval().requires_grad_(True)
    end_threshold, calibration = cfg.end_threshold, None
    if cfg.calibrate_episodes:
        calibration = calibrate_end_threshold(net, worlds, episodes=cfg.calibrate_episodes, seed=cfg.seed + 4_241)
        end_threshold = calibration.threshold
    final = {"success": float("nan"), "success_ci95": [float("nan")] * 2, "spl": float("nan"), "episodes": 0}
    if cfg.final_eval_episodes:
        res, _ = run_episodes(worlds, sample_episodes(worlds, cfg.final_eval_episodes, seed=cfg.seed + 7_919),
                              NeuralPolicy(net, end_threshold=end_threshold), batch=128)
        final = summarize(res)
    wall = time.perf_counter() - start
    card = {
        "command": command, "algo": "ppo", "houses": cfg.houses, "n_houses": len(worlds), "frames": frames,
        "updates": updates, "wall_time_s": round(wall, 1), "seed": cfg.seed, "init": cfg.init,
        "parameters": count_parameters(net), "final_train_success": final["success"],
        "final_train_success_ci95": final["success_ci95"], "final_train_spl": final["spl"],
        "final_eval_episodes": final["episodes"], "end_threshold": end_threshold, "precision": precision,
        "end_threshold_calibration": calibration.card() if calibration else None,
        "torch_threads": threads, "cpus": os.cpu_count(), "config": card_config(cfg, net),
        "net_config": asdict(net.config)}
    logger.log({"iteration": n_iterations, "frames": frames, "updates": updates, "wall_time": wall,
                "eval/success": final["success"], "eval/spl": final["spl"]})
    logger.close()
    if cfg.output:
        save_checkpoint(cfg.output, net, {k: v for k, v in card.items() if k != "config"})
        atomic_write_text(Path(cfg.output).with_suffix(".json"), json.dumps(card, indent=1) + "\n")
    return TrainResult(net, card, logger.rows,
                       learner=copy.deepcopy({"value": agent.value.state_dict(), "optimizer": optimizer.state_dict()}))
