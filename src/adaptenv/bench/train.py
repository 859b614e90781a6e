"""``adaptenv bench train``: the throughput of imitation learning on this machine.

Figures (median of repeated timings, houses of the ``pretrain-train`` preset, warm caches):

- labelled frames/s: BatchSim steps plus the expert's label for every agent (target >= 20,000/s);
- DAgger collection frames/s: the same plus the policy's own forward pass (what ``train`` collects at);
- gradient frames/s: cross-entropy steps on (chunk_len, batch_chunks) sequences on one torch thread
  (target >= 10,000/s), in the recipe's precision; and in fp32 and bf16 autocast timed alternately, with
  their ratio and the one ``auto`` picks on this CPU (``TrainConfig.precision``);
- inference steps/s of the policy at batch 256, and its parameter count;
- end to end (``train`` itself: collection with the policy in the loop plus the gradient steps, default
  TrainConfig, periodic evaluation off): frames/s of the default serial loop on every core over its
  training loop (the target, >= 10,000/s) and over the whole call (set-up and a one-episode final
  evaluation included), and of the loop with the learner thread (``--overlap``), timed alternately
  in this one process, and their ratio;
- ``--resume``: frames/s of a fresh run and of its resumed continuation (same iterations), and their ratio;
- with ``--algo ppo``: PPO end to end as the loop fine-tunes the map-reading agent, the whole network trained
  and its encoder frozen, timed alternately: frames/s and their ratio.

Each throughput is given per wall-clock second and per CPU-second of this process (all threads,
``time.process_time``), with the load average before and after: on a shared machine the wall
figures fall with the load, the CPU figures much less.

Imports sit inside the functions: this module is loaded by its ``adaptenv bench`` command, and a
benchmark loads what it measures (torch, numba, ray) only when it runs.
"""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from adaptenv.agents.config import PPOConfig

ARITHMETICS = ("fp32", "bf16")
"""The precisions the gradient step is timed in (``auto`` is one of them on any CPU)."""
LABEL_TARGET = 20_000
GRAD_TARGET = 10_000
END_TO_END_TARGET = 10_000


def wall_and_cpu(fn: Callable[[], object], repeats: int, warmup: int = 1) -> tuple[float, float]:
    """Median wall seconds and median CPU seconds (this process, all threads) of ``fn()``."""
    for _ in range(warmup):
        fn()
    walls, cpus = [], []
    for _ in range(repeats):
        w, c = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - w)
        cpus.append(time.process_time() - c)
    return statistics.median(walls), statistics.median(cpus)


def end_to_end(worlds: list, iterations: int, repeats: int, recipe: dict | None = None) -> dict:
    """``train`` frames/s of the default serial loop and with the learner thread, alternately (median of
    ``repeats`` each): over its training loop (collection with the policy plus gradient steps, by the run's own
    clock) and over the whole call (with the set-up and a one-episode final evaluation).

    ``recipe``: TrainConfig fields that differ from the defaults (network sizes, replay ratio).
    """
    from adaptenv.agents.config import TrainConfig
    from adaptenv.agents.train import train

    block = TrainConfig().num_envs * TrainConfig().rollout_steps

    def one(overlap: bool, n: int) -> tuple[float, float]:
        cfg = TrainConfig(frames=n * block, output="", run_dir="", eval_every=0, final_eval_episodes=1,
                          calibrate_episodes=0, progress=False, tensorboard=False, overlap=overlap,
                          **(recipe or {}))
        t = time.perf_counter()
        result = train(cfg, worlds=worlds)
        call = time.perf_counter() - t
        loop = max(r["wall_time"] for r in result.rows if "losses/loss" in r)
        return n * block / loop, n * block / call

    one(False, 1)  # warm the kernels and the per-(house, target) caches
    fps: dict[bool, list[tuple[float, float]]] = {False: [], True: []}
    for _ in range(repeats):
        for overlap in (False, True):
            fps[overlap].append(one(overlap, iterations))
    loop = {k: statistics.median(f[0] for f in v) for k, v in fps.items()}
    ratios = [b[0] / a[0] for a, b in zip(fps[False], fps[True], strict=True)]
    return {"dagger_end_to_end_frames_per_s": loop[False],
            "dagger_end_to_end_overlap_frames_per_s": loop[True],
            "dagger_whole_call_frames_per_s": statistics.median(f[1] for f in fps[False]),
            "dagger_overlap_speedup": statistics.median(ratios),
            "end_to_end_target_met": bool(loop[False] >= END_TO_END_TARGET),
            **fresh_and_resumed(worlds, iterations, recipe)}


def fresh_and_resumed(worlds: list, iterations: int, recipe: dict | None = None) -> dict:
    """``train`` frames/s of a fresh run and of its ``--resume`` continuation by as many iterations."""
    import tempfile

    from adaptenv.agents.config import TrainConfig
    from adaptenv.agents.train import train

    block = TrainConfig().num_envs * TrainConfig().rollout_steps
    with tempfile.TemporaryDirectory() as tmp:
        def one(n: int, resume: bool) -> float:
            cfg = TrainConfig(frames=n * block, output="", run_dir=tmp, eval_every=0, final_eval_episodes=1,
                              calibrate_episodes=0, progress=False, tensorboard=False, resume=resume,
                              **(recipe or {}))
            t = time.perf_counter()
            train(cfg, worlds=worlds)
            return iterations * block / (time.perf_counter() - t)

        fresh = one(iterations, False)
        resumed = one(2 * iterations, True)
    return {"dagger_fresh_frames_per_s": fresh, "dagger_resumed_frames_per_s": resumed,
            "dagger_resume_speed_ratio": resumed / fresh}


MAP_RECIPE = {"map": True, "teacher": "map-explorer", "precision": "auto", "max_episode_steps": 600}
"""The map-reading recipe's TrainConfig fields that differ from the defaults (docs/agent.md, "The map-reading pi_0")."""
MAP_END_TO_END_TARGET = 8_000


def map_side_by_side(worlds: list, iterations: int, repeats: int) -> dict:
    """``train`` frames/s over its training loop of today's default recipe and of the map recipe (MAP_RECIPE),
    timed alternately in this process (median of ``repeats`` each), and their ratio."""
    from adaptenv.agents.config import TrainConfig
    from adaptenv.agents.train import train

    block = TrainConfig().num_envs * TrainConfig().rollout_steps
    recipes = {"default": {}, "map": MAP_RECIPE}

    def one(recipe: dict, n: int) -> float:
        cfg = TrainConfig(frames=n * block, output="", run_dir="", eval_every=0, final_eval_episodes=1,
                          calibrate_episodes=0, progress=False, tensorboard=False, **recipe)
        result = train(cfg, worlds=worlds)
        return n * block / max(r["wall_time"] for r in result.rows if "losses/loss" in r)

    for recipe in recipes.values():
        one(recipe, 1)  # warm the kernels and the caches
    fps: dict[str, list[float]] = {k: [] for k in recipes}
    for _ in range(repeats):
        for name, recipe in recipes.items():
            fps[name].append(one(recipe, iterations))
    ratios = [m / d for d, m in zip(fps["default"], fps["map"], strict=True)]
    return {"dagger_end_to_end_frames_per_s_default": statistics.median(fps["default"]),
            "dagger_end_to_end_frames_per_s_map": statistics.median(fps["map"]),
            "map_over_default": statistics.median(ratios),
            "map_end_to_end_target_met": bool(statistics.median(fps["map"]) >= MAP_END_TO_END_TARGET)}


def run_map(*, as_json: bool = False, iterations: int = 3, repeats: int = 3,
            houses: str = "preset:pretrain-train") -> dict:
    """The map-reading recipe beside today's: teacher labelling and end-to-end training frames/s, side by side."""
    from adaptenv.agents.houses import load_house_set
    from adaptenv.agents.network import auto_precision
    from adaptenv.bench import emit
    from adaptenv.bench.teachers import bench_labelling

    worlds = load_house_set(houses).worlds
    load_before = os.getloadavg()[0]
    figures = {**bench_labelling(houses), **map_side_by_side(worlds, iterations, repeats),
               "recipe": MAP_RECIPE, "auto_precision": auto_precision(), "load_average_1min_before": load_before,
               "load_average_1min_after": os.getloadavg()[0]}
    emit("map recipe beside today's", figures, as_json,
         notes=[f"targets: map-explorer labelling >= 5,000/s, map recipe end to end >= {MAP_END_TO_END_TARGET:,}/s "
                "(2 cores)"])
    return figures


LOOP_PPO = {"init": "pretrained-ppo", "kl_coef": 0.03, "explore_bonus": 0.002, "max_episode_steps": 600,
            "min_start_distance": 6.0, "threads": 1}
"""The loop's PPO fine-tuning (configs/experiment-lever-ppo4.json's finetune_* settings) on the shipped map-reading agent."""


PPO_VARIANTS = {"full": {"precision": "fp32"}, "frozen_encoder": {"freeze_encoder": True, "precision": "fp32"}, "bf16": {"precision": "bf16"},
                "frozen_encoder_bf16": {"freeze_encoder": True, "precision": "bf16"}}
"""The PPO updates ``bench train --algo ppo`` times beside each other: fp32 whole network, encoder frozen, bf16, both."""


def loop_ppo_config(iterations: int, **overrides: object) -> PPOConfig:
    """The loop's PPO recipe (LOOP_PPO, with ``overrides``) for ``iterations`` rollouts, evaluation and outputs off."""
    from adaptenv.agents.config import PPOConfig

    block = PPOConfig().num_envs * PPOConfig().rollout_steps
    return PPOConfig(frames=iterations * block, output="", run_dir="", eval_every=0, final_eval_episodes=0,
                     calibrate_episodes=0, progress=False, tensorboard=False, value_warmup_iters=0,
                     **{**LOOP_PPO, **overrides})


def run_ppo(*, as_json: bool = False, iterations: int = 3, repeats: int = 3,
            houses: str = "preset:pretrain-train") -> dict:
    """PPO end to end as the loop fine-tunes (LOOP_PPO, evaluation off) with each of PPO_VARIANTS' updates, timed
    alternately (median of ``repeats`` each): frames/s and each variant's ratio to the full fp32 update."""
    from adaptenv.agents.houses import load_house_set
    from adaptenv.agents.network import auto_precision
    from adaptenv.agents.ppo import train_ppo
    from adaptenv.bench import emit

    worlds = load_house_set(houses).worlds

    def one(n: int, variant: dict) -> tuple[float, float]:
        cfg = loop_ppo_config(n, **variant)
        w, c = time.perf_counter(), time.process_time()
        train_ppo(cfg, worlds=worlds)
        return cfg.frames / (time.perf_counter() - w), cfg.frames / (time.process_time() - c)

    load_before = os.getloadavg()[0]
    for variant in PPO_VARIANTS.values():
        one(1, variant)  # warm-up
    runs: dict[str, list[tuple[float, float]]] = {name: [] for name in PPO_VARIANTS}
    for _ in range(repeats):
        for name, variant in PPO_VARIANTS.items():
            runs[name].append(one(iterations, variant))
    figures: dict = {}
    for name, timed in runs.items():
        figures[f"ppo_end_to_end_frames_per_s_{name}"] = statistics.median(w for w, _ in timed)
        figures[f"ppo_end_to_end_frames_per_cpu_s_{name}"] = statistics.median(c for _, c in timed)
    for name, key in (("frozen_encoder", "frozen_over_full"), ("bf16", "bf16_over_full"),
                      ("frozen_encoder_bf16", "frozen_bf16_over_full")):
        figures[key] = statistics.median(v[0] / f[0] for f, v in zip(runs["full"], runs[name], strict=True))
    figures.update({"auto_precision": auto_precision(), "ppo_frames_timed": loop_ppo_config(iterations).frames,
                    "repeats": repeats, "houses": len(worlds),
                    "recipe": LOOP_PPO, "load_average_1min_before": load_before,
                    "load_average_1min_after": os.getloadavg()[0]})
    emit("PPO throughput, the loop's recipe", figures, as_json,
         notes=["collection + 4 epochs x 4 minibatches per 8,192-frame rollout; one torch thread, as the loop"])
    return figures


def auto_note(auto: str, bf16_speedup: float) -> str:
    """One line on what precision ``auto`` picks on this CPU, beside the measured bf16/fp32 speed ratio."""
    why = "this CPU computes bf16 natively" if auto == "bf16" else "this CPU has no native bf16"
    return f"precision auto picks {auto} here ({why}); bf16 gradient steps ran {bf16_speedup:.2f} times fp32's speed"


def run(*, as_json: bool = False, envs: int = 256, steps: int = 200, houses: str = "preset:pretrain-train",
        iterations: int = 3, repeats: int = 2, recipe: dict | None = None, grad_rounds: int = 3,
        grad_repeats: int = 7) -> dict:
    """Measure and print the figures (table or JSON); returns them.

    ``recipe``: TrainConfig fields that differ from the defaults, for every figure (for example
    ``{"hidden": 128, "updates_per_iter": 4}``); they are reported with the figures. The gradient step
    is timed ``grad_repeats`` times per precision in each of ``grad_rounds`` alternating rounds.
    """
    import torch
    import torch.nn.functional as F

    from adaptenv.agents.config import TrainConfig
    from adaptenv.agents.houses import load_house_set
    from adaptenv.agents.network import (
        NavNet,
        NetConfig,
        auto_precision,
        configure_torch,
        count_parameters,
        obs_to_tensors,
    )
    from adaptenv.agents.train import sequence_logits
    from adaptenv.bench import emit
    from adaptenv.sim import task
    from adaptenv.sim.expert import ShortestPathExpert
    from adaptenv.sim.vector import BatchSim

    threads = configure_torch()
    cfg = TrainConfig(**(recipe or {}))
    worlds = load_house_set(houses).worlds
    rng = np.random.default_rng(0)
    expert = ShortestPathExpert()
    sim = BatchSim(worlds, max_steps=cfg.max_episode_steps)
    net = NavNet(NetConfig.of(cfg)).eval()

    def new(n: int):
        envs_ = rng.integers(0, len(worlds), n)
        return [task.sample_episode(worlds[e], rng) for e in envs_.tolist()], envs_

    eps, env_idx = new(envs)
    sim.reset(eps, env_idx)
    h = net.initial_state(envs)
    first = torch.zeros(envs, dtype=torch.bool)

    def collect(with_policy: bool) -> None:
        nonlocal h
        obs = sim.observe()
        for _ in range(steps):
            labels = expert.act_batch(sim.worlds, sim.env, sim.target_types, sim.x, sim.z, sim.yaw)
            if with_policy:
                with torch.no_grad():
                    _, h = net.step(obs_to_tensors(obs), first, h)
            obs, _, terminated, truncated, _ = sim.step(labels)
            done = np.flatnonzero(terminated | truncated)
            if done.size:
                e, idx = new(done.size)
                obs = sim.reset_at(done, e, idx)

    for _ in range(3):  # warm the per-(house, target) caches of every house
        collect(False)
    load_before = os.getloadavg()[0]
    t_label, c_label = wall_and_cpu(lambda: collect(False), repeats=3, warmup=0)
    t_collect, c_collect = wall_and_cpu(lambda: collect(True), repeats=3, warmup=0)

    L, N = cfg.chunk_len, cfg.batch_chunks
    obs = sim.observe()
    seq = obs_to_tensors({k: np.broadcast_to(np.resize(v, (N, *v.shape[1:])), (L, N, *v.shape[1:])).copy()
                          for k, v in obs.items()})
    labels = torch.randint(0, 7, (L, N))
    done = torch.zeros(L, N, dtype=torch.bool)
    train_net = NavNet(NetConfig.of(cfg))
    opt = torch.optim.Adam(train_net.parameters(), lr=1e-4)

    def grad_step(precision: str) -> None:
        logits = sequence_logits(train_net, seq, done, torch.zeros(N, cfg.hidden), precision)
        loss = F.cross_entropy(logits.reshape(-1, logits.shape[-1]), labels.reshape(-1))
        opt.zero_grad()
        loss.backward()
        opt.step()

    # both precisions, alternately, so their ratio is measured side by side
    rounds: dict[str, list[tuple[float, float]]] = {}
    for _ in range(grad_rounds):
        for p in ARITHMETICS:
            rounds.setdefault(p, []).append(wall_and_cpu(lambda p=p: grad_step(p), repeats=grad_repeats, warmup=2))
    grad = {p: (statistics.median(w for w, _ in r), statistics.median(c for _, c in r)) for p, r in rounds.items()}
    auto = auto_precision()
    t_grad, c_grad = grad[auto if cfg.precision == "auto" else cfg.precision]

    bobs = {k: np.resize(v, (256, *v.shape[1:])) for k, v in sim.observe().items()}
    policy_h = net.initial_state(256)
    d256 = torch.zeros(256, dtype=torch.bool)

    def infer() -> None:
        with torch.no_grad():
            net.step(obs_to_tensors(bobs), d256, policy_h)

    t_inf, c_inf = wall_and_cpu(infer, repeats=50, warmup=5)
    figures = {
        "labelled_frames_per_s": envs * steps / t_label,
        "labelled_frames_per_cpu_s": envs * steps / c_label,
        "dagger_collect_frames_per_s": envs * steps / t_collect,
        "dagger_collect_frames_per_cpu_s": envs * steps / c_collect,
        "gradient_frames_per_s": L * N / t_grad,
        "gradient_frames_per_cpu_s": L * N / c_grad,
        **{f"gradient_frames_per_s_{p}": L * N / grad[p][0] for p in ARITHMETICS},
        "gradient_bf16_speedup": grad["fp32"][0] / grad["bf16"][0],
        "auto_precision": auto,
        "inference_steps_per_s_b256": 256 / t_inf,
        "inference_steps_per_cpu_s_b256": 256 / c_inf,
        "parameters": count_parameters(net),
        "envs": envs, "houses": len(worlds), "torch_threads": threads,
        "label_target_met": bool(envs * steps / t_label >= LABEL_TARGET),
        "gradient_target_met": bool(L * N / t_grad >= GRAD_TARGET),
    }
    if iterations > 0:
        figures.update(end_to_end(worlds, iterations, repeats, recipe))
    figures["recipe"] = dict(recipe or {})
    figures["replay_ratio"] = cfg.updates_per_iter * cfg.batch_chunks * cfg.chunk_len / (cfg.num_envs * cfg.rollout_steps)
    figures["load_average_1min_before"] = load_before
    figures["load_average_1min_after"] = os.getloadavg()[0]
    emit("imitation-learning throughput", figures, as_json,
         notes=[f"targets: labelled >= {LABEL_TARGET:,}/s, gradient >= {GRAD_TARGET:,}/s, "
                f"end to end >= {END_TO_END_TARGET:,}/s (2 cores)", auto_note(auto, figures["gradient_bf16_speedup"])])
    return figures
