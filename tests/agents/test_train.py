"""Imitation training: the loss falls, runs resume after an interruption, fine-tuning returns a policy."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from adaptenv.agents.checkpoint import load_checkpoint
from adaptenv.agents.network import available_cores
from adaptenv.agents.train import (
    SequenceBuffer,
    TrainConfig,
    beta_at,
    field_docs,
    finetune_policy,
    train,
)
from adaptenv.errors import ConfigError


def tiny_config(tmp_path, **overrides) -> TrainConfig:
    """A few-thousand-frame run on the tiny preset with a small network."""
    settings = dict(houses="preset:tiny", frames=4096, output=str(tmp_path / "p.pt"), run_dir=str(tmp_path / "run"),
                    num_envs=16, rollout_steps=32, chunk_len=16, batch_chunks=16, updates_per_iter=8,
                    hidden=32, feature_dim=32, learning_rate=3e-3, eval_every=0, final_eval_episodes=6,
                    save_every=16, progress=False, tensorboard=False, max_episode_steps=100, threads=1,
                    calibrate_episodes=0)
    settings.update(overrides)
    return TrainConfig(**settings)


def test_every_config_field_has_help():
    docs = field_docs(TrainConfig)
    assert set(docs) == set(TrainConfig.__dataclass_fields__)
    assert all(len(d) > 10 for d in docs.values())


def test_beta_schedule_and_config_checks(tmp_path):
    cfg = tiny_config(tmp_path, beta_start=1.0, beta_end=0.2, beta_decay_fraction=0.5)
    assert beta_at(cfg, 0) == 1.0
    assert beta_at(cfg, 1024) == pytest.approx(0.6)
    assert beta_at(cfg, 4096) == pytest.approx(0.2)
    with pytest.raises(ConfigError, match="multiple of --chunk-len"):
        train(tiny_config(tmp_path, rollout_steps=20))
    with pytest.raises(ConfigError, match="--resume: the run folder .*nothing does not exist"):
        train(tiny_config(tmp_path, run_dir=str(tmp_path / "nothing"), resume=True))
    (tmp_path / "empty").mkdir()
    with pytest.raises(ConfigError, match="--resume: no saved state at .*state.pt"):
        train(tiny_config(tmp_path, run_dir=str(tmp_path / "empty"), resume=True))


def test_buffer_samples_aligned_chunks():
    buf = SequenceBuffer(capacity_blocks=2, steps=8, envs=3, chunk_len=4, hidden=2, n_rays=1)
    for k in range(3):  # the third block overwrites the first
        block = {"label": np.full((8, 3), k, np.uint8), "target": np.arange(8, dtype=np.uint8)[:, None].repeat(3, 1),
                 "h0": np.full((2, 3, 2), k, np.float16)}
        buf.add(block)
    assert buf.size == 2 and buf.frames == 48
    batch = buf.sample(50, np.random.default_rng(0))
    assert batch["label"].shape == (4, 50)
    assert set(batch["label"].unique().tolist()) <= {1, 2}
    starts = batch["target"][0]
    assert set(starts.tolist()) <= {0, 4}  # chunks start at multiples of chunk_len
    assert (batch["target"] - starts == np.arange(4)[:, None]).all()
    assert (batch["h0"][:, 0] == batch["label"][0].float()).all()  # stored state of that block


@pytest.mark.slow
def test_training_lowers_the_loss_and_writes_its_outputs(tmp_path):
    cfg = tiny_config(tmp_path)
    result = train(cfg, command="test")
    losses = [r["losses/loss"] for r in result.rows if "losses/loss" in r]
    assert len(losses) == 8
    assert np.mean(losses[-2:]) < losses[0] - 0.2
    card = json.loads((tmp_path / "p.json").read_text())
    assert card["frames"] == 4096 and card["command"] == "test" and 0.0 <= card["final_train_success"] <= 1.0
    assert json.loads((tmp_path / "run" / "config.json").read_text())["frames"] == 4096
    header = (tmp_path / "run" / "metrics.csv").read_text().splitlines()[0]
    assert "losses/loss" in header and "eval/success" in header
    assert load_checkpoint(tmp_path / "p.pt").meta["frames"] == 4096


@pytest.mark.slow
def test_bf16_gradient_steps_learn_as_fp32_does_and_unknown_precisions_are_refused(tmp_path):
    rows = {p: train(tiny_config(tmp_path / p, precision=p)).rows for p in ("fp32", "bf16")}
    losses = {p: [r["losses/loss"] for r in rs if "losses/loss" in r] for p, rs in rows.items()}
    assert losses["bf16"] != losses["fp32"]  # the autocast is on: other arithmetic, other numbers
    assert losses["bf16"][0] == pytest.approx(losses["fp32"][0], abs=0.02)  # the same weights and data at first
    assert np.mean(losses["bf16"][-2:]) < losses["bf16"][0] - 0.2  # and it learns as the fp32 run does
    assert abs(np.mean(losses["bf16"][-2:]) - np.mean(losses["fp32"][-2:])) < 0.1
    with pytest.raises(ConfigError, match="--precision must be one of auto, fp32, bf16"):
        train(tiny_config(tmp_path, precision="fp16"))


@pytest.mark.slow
def test_resume_after_interruption_continues_from_the_checkpoint(tmp_path, monkeypatch):
    cfg = tiny_config(tmp_path, save_every=8)  # a save after every iteration (8 updates)
    calls = {"n": 0}
    real_add = SequenceBuffer.add

    def interrupted_add(self, block):
        calls["n"] += 1
        if calls["n"] == 4:
            raise KeyboardInterrupt
        real_add(self, block)

    monkeypatch.setattr(SequenceBuffer, "add", interrupted_add)
    with pytest.raises(KeyboardInterrupt):
        train(cfg)
    monkeypatch.setattr(SequenceBuffer, "add", real_add)
    saved = torch.load(tmp_path / "run" / "state.pt", weights_only=True)  # tensors and plain data: no code runs
    assert saved["frames"] == 3 * 512 and saved["iteration"] == 3 and saved["buffer"]["size"] == 3
    result = train(tiny_config(tmp_path, resume=True))
    iterations = [r["iteration"] for r in result.rows if "losses/loss" in r]
    assert iterations == list(range(4, 9))  # continues after the saved iteration
    assert result.card["frames"] == 4096 and result.card["updates"] == 64


@pytest.mark.slow
def test_finetune_returns_a_new_policy(tiny_set, tmp_path):
    base = train(tiny_config(tmp_path, frames=1024, output="", run_dir=""))
    before = {k: v.clone() for k, v in base.net.state_dict().items()}
    policy = finetune_policy(base.policy(), tiny_set.houses, 1024, num_envs=16, rollout_steps=32, chunk_len=16,
                      batch_chunks=16, updates_per_iter=4, final_eval_episodes=4, tensorboard=False, threads=1)
    assert policy.net is not base.net
    assert any(not (v == policy.net.state_dict()[k]).all() for k, v in before.items())
    assert all((v == base.net.state_dict()[k]).all() for k, v in before.items())  # the input is untouched


@pytest.mark.slow
def test_overlapped_learning_does_not_depend_on_timing(tmp_path):
    import numba

    threads = numba.get_num_threads()
    runs = [train(tiny_config(tmp_path, frames=2048, output="", run_dir="", final_eval_episodes=1, overlap=True))
            for _ in range(2)]
    assert numba.get_num_threads() == threads  # the collector's one-thread setting ends with the run
    a, b = (r.net.state_dict() for r in runs)
    assert all(torch.equal(a[k], b[k]) for k in a)
    serial = train(tiny_config(tmp_path, frames=2048, output="", run_dir="", final_eval_episodes=1, overlap=False))
    assert any(not torch.equal(a[k], serial.net.state_dict()[k]) for k in a)  # the collecting weights lag


def _iteration_seconds(rows: list[dict], first: int) -> list[float]:
    """Wall seconds of each logged training iteration from the ``first``-th iteration on."""
    it = [(r["iteration"], r["wall_time"]) for r in rows if "losses/loss" in r]
    return [w1 - w0 for (i0, w0), (i1, w1) in zip(it, it[1:], strict=False) if i1 == i0 + 1 and i1 > first]


@pytest.mark.slow
def test_resumed_run_is_about_as_fast_as_a_fresh_one(tmp_path):
    cfg = tiny_config(tmp_path, frames=4096, save_every=10**6, final_eval_episodes=1)
    train(tiny_config(tmp_path / "warm", frames=1024, final_eval_episodes=1))  # compile and warm the caches
    fresh = train(cfg)
    resumed = train(tiny_config(tmp_path, frames=8192, resume=True, save_every=10**6, final_eval_episodes=1))
    t_fresh = float(np.median(_iteration_seconds(fresh.rows, first=2)))
    t_resumed = float(np.median(_iteration_seconds(resumed.rows, first=10)))
    assert len(_iteration_seconds(resumed.rows, first=10)) >= 5
    assert t_resumed < 2.5 * t_fresh, (t_fresh, t_resumed)


@pytest.mark.slow
def test_bench_train_measures_the_recipe_it_is_given(capsys):
    from adaptenv.agents.config import TrainConfig
    from adaptenv.agents.network import NavNet, NetConfig, count_parameters
    from adaptenv.bench.train import run

    quick = {"envs": 8, "steps": 4, "houses": "preset:tiny", "iterations": 0, "grad_rounds": 1, "grad_repeats": 1}
    small_net = {"hidden": 32, "feature_dim": 32, "conv_channels": 8}
    small = run(as_json=True, **quick, recipe={**small_net, "updates_per_iter": 4})
    assert small["recipe"]["hidden"] == 32
    d = TrainConfig()
    assert small["parameters"] < count_parameters(NavNet(NetConfig.of(d))) / 4
    default_ratio = d.updates_per_iter * d.batch_chunks * d.chunk_len / (d.num_envs * d.rollout_steps)
    assert small["replay_ratio"] == default_ratio / 2 == 1.0
    # both precisions are timed in every run; the headline figure is the recipe's own
    assert small["auto_precision"] in ("fp32", "bf16")  # the default, auto, is what this CPU computes natively
    assert small["gradient_frames_per_s"] == small[f"gradient_frames_per_s_{small['auto_precision']}"]
    assert small["gradient_bf16_speedup"] == pytest.approx(
        small["gradient_frames_per_s_bf16"] / small["gradient_frames_per_s_fp32"])
    bf16 = run(as_json=True, **quick, recipe={**small_net, "precision": "bf16"})
    assert bf16["gradient_frames_per_s"] == bf16["gradient_frames_per_s_bf16"]
    assert '"benchmark": "imitation-learning throughput"' in capsys.readouterr().out
    run(**quick, recipe=small_net)  # the table says what auto picks here
    assert f"precision auto picks {small['auto_precision']} here" in capsys.readouterr().out


def test_serial_training_uses_every_available_core_and_the_learner_thread_one(tmp_path, monkeypatch):
    monkeypatch.setattr("os.cpu_count", lambda: 4)
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    assert available_cores() == 4
    monkeypatch.setenv("OMP_NUM_THREADS", "1")  # what an executor's worker sets
    assert available_cores() == 1
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    before = torch.get_num_threads()
    try:
        serial = train(tiny_config(tmp_path, frames=512, output="", run_dir="", final_eval_episodes=1, threads=0))
        overlap = train(tiny_config(tmp_path, frames=512, output="", run_dir="", final_eval_episodes=1, threads=0,
                                    overlap=True))
    finally:
        torch.set_num_threads(before)
    assert serial.card["torch_threads"] == 2
    assert overlap.card["torch_threads"] == 1


@pytest.mark.slow
def test_bench_end_to_end_times_the_training_loop_apart_from_the_call():
    from adaptenv.agents.houses import load_house_set
    from adaptenv.bench.train import end_to_end

    figs = end_to_end(load_house_set("preset:tiny").worlds, iterations=1, repeats=1,
                      recipe={"hidden": 32, "feature_dim": 32, "conv_channels": 8, "threads": 1})
    # the loop excludes the set-up and the final evaluation, so it is faster than the whole call
    assert figs["dagger_end_to_end_frames_per_s"] > figs["dagger_whole_call_frames_per_s"] > 0
    assert figs["dagger_end_to_end_overlap_frames_per_s"] > 0 and figs["dagger_resume_speed_ratio"] > 0


def test_training_gives_back_the_callers_torch_threads(tmp_path):
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        result = train(tiny_config(tmp_path, frames=512, output="", run_dir="", final_eval_episodes=1, threads=2))
        assert result.card["torch_threads"] == 2 and torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)


def test_bench_ppo_times_each_update_alternately_with_the_loops_recipe(monkeypatch):
    from adaptenv.agents import ppo
    from adaptenv.bench.train import LOOP_PPO, PPO_VARIANTS, run_ppo

    seen = []
    monkeypatch.setattr(ppo, "train_ppo", lambda cfg, worlds: seen.append(cfg))
    figs = run_ppo(as_json=True, iterations=2, repeats=2, houses="preset:tiny")
    # one warm-up each, then the variants in turn, every run with the loop's recipe and evaluation off
    updates = [(False, "fp32"), (True, "fp32"), (False, "bf16"), (True, "bf16")]
    assert list(PPO_VARIANTS) == ["full", "frozen_encoder", "bf16", "frozen_encoder_bf16"]
    assert [(c.freeze_encoder, c.precision) for c in seen] == updates * 3
    assert all(c.init == LOOP_PPO["init"] and c.kl_coef == LOOP_PPO["kl_coef"] and c.eval_every == 0 for c in seen)
    assert [c.frames // (c.num_envs * c.rollout_steps) for c in seen] == [1] * 4 + [2] * 8
    assert {"ppo_end_to_end_frames_per_s_bf16", "bf16_over_full", "frozen_over_full", "frozen_bf16_over_full"} <= set(figs)


def test_run_configs_size_a_fresh_networks_map_encoder():
    """--map-dim reaches a fresh network of adaptenv train and adaptenv ppo: the map encoder's output size."""
    from adaptenv.agents.config import PPOConfig
    from adaptenv.agents.network import NavNet, NetConfig

    assert NetConfig.of(PPOConfig(map_dim=24)).map_dim == 24
    assert NavNet(NetConfig.of(TrainConfig(map=True, map_dim=24))).map_encoder[-2].out_features == 24
