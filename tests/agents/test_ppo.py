"""PPO fine-tuning: the acting rule's log-probabilities, a value warm-up that leaves the policy alone, a tiny run."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from adaptenv.agents.config import FinetuneConfig, PPOConfig, field_docs
from adaptenv.agents.network import NavNet, NetConfig
from adaptenv.agents.ppo import check_ppo_config, log_prob_entropy, sample_actions, train_ppo
from adaptenv.agents.train import finetune
from adaptenv.errors import ConfigError
from adaptenv.sim.spec import END


def tiny_ppo(tmp_path, **overrides) -> PPOConfig:
    settings = dict(houses="preset:tiny", frames=1024, init="", output=str(tmp_path / "ppo.pt"),
                    run_dir=str(tmp_path / "run"), num_envs=16, rollout_steps=32, chunk_len=16, num_minibatches=2,
                    update_epochs=2, hidden=32, feature_dim=32, eval_every=0, final_eval_episodes=4,
                    calibrate_episodes=0, max_episode_steps=60, progress=False, tensorboard=False, threads=1,
                    value_warmup_iters=0)
    settings.update(overrides)
    return PPOConfig(**settings)


def test_every_ppo_and_finetune_field_has_help():
    for cls in (PPOConfig, FinetuneConfig):
        docs = field_docs(cls)
        assert set(docs) == set(cls.__dataclass_fields__) and all(len(d) > 5 for d in docs.values())


def test_config_checks_name_the_flag(tmp_path):
    with pytest.raises(ConfigError, match="--num-minibatches"):
        check_ppo_config(tiny_ppo(tmp_path, num_minibatches=3))
    with pytest.raises(ConfigError, match="--stop-rule"):
        check_ppo_config(tiny_ppo(tmp_path, stop_rule="never"))
    with pytest.raises(ConfigError, match="--bc-teacher"):
        check_ppo_config(tiny_ppo(tmp_path, bc_teacher="oracle"))


def test_threshold_rule_log_probs_are_the_motion_distribution():
    logits = torch.tensor([[0.0, 1.0, 0.5, 0.0, -1.0, 0.0, 3.0], [0.0, 1.0, 0.5, 0.0, -1.0, 0.0, -3.0]])
    # agent 0: p(end) ~ 0.8 >= 0.5, so it ends; agent 1 moves
    actions = sample_actions(logits, np.array([0.3, 0.3]), "threshold", 0.5)
    assert actions[0] == END and actions[1] != END
    lp, ent, drawn = log_prob_entropy(logits, torch.from_numpy(actions), "threshold")
    assert drawn.tolist() == [False, True] and lp[0] == 0
    motions = torch.log_softmax(logits[1, :END], -1)
    assert lp[1] == pytest.approx(float(motions[actions[1]]))
    assert ent[1] == pytest.approx(float(-(motions.exp() * motions).sum()), abs=1e-6)
    lp_all, _, drawn_all = log_prob_entropy(logits, torch.from_numpy(actions), "sample")
    assert drawn_all.all() and lp_all[0] == pytest.approx(float(torch.log_softmax(logits[0], -1)[END]))


def test_sample_rule_draws_from_the_full_softmax():
    logits = torch.log(torch.tensor([[0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.4]]))
    u = np.random.default_rng(0).random(4000)
    actions = np.array([sample_actions(logits, u[i: i + 1], "sample", 0.5)[0] for i in range(4000)])
    assert abs((actions == END).mean() - 0.4) < 0.03


@pytest.mark.slow
def test_value_warmup_leaves_the_policy_untouched(tmp_path):
    init = NavNet(NetConfig(hidden=32, feature_dim=32))
    before = {k: v.clone() for k, v in init.state_dict().items()}
    result = train_ppo(tiny_ppo(tmp_path, output="", run_dir="", value_warmup_iters=2, frames=1024), init_net=init)
    assert all(torch.equal(v, result.net.state_dict()[k]) for k, v in before.items())
    moved = train_ppo(tiny_ppo(tmp_path, output="", run_dir="", frames=1024), init_net=init)
    assert any(not torch.equal(v, moved.net.state_dict()[k]) for k, v in before.items())


@pytest.mark.slow
@pytest.mark.parametrize("bc_teacher", ["expert", "explorer"])
def test_tiny_ppo_run_writes_checkpoint_card_and_metrics(tmp_path, bc_teacher):
    result = train_ppo(tiny_ppo(tmp_path, bc_coef=0.5, bc_teacher=bc_teacher, calibrate_episodes=4), command="test")
    card = json.loads((tmp_path / "ppo.json").read_text())
    assert card["algo"] == "ppo" and card["frames"] == 1024 and card["command"] == "test"
    assert card["end_threshold"] == card["end_threshold_calibration"]["threshold"]
    rows = [r for r in result.rows if "losses/value_loss" in r]
    assert len(rows) == 2 and all(np.isfinite(r["losses/value_loss"]) and r["losses/bc_loss"] > 0 for r in rows)
    header = (tmp_path / "run" / "metrics.csv").read_text().splitlines()[0]
    assert "charts/episodic_return" in header and "losses/approx_kl" in header


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["dagger", "ppo"])
def test_finetune_with_a_named_config(tiny_set, algo):
    net = NavNet(NetConfig(hidden=32, feature_dim=32))
    before = {k: v.clone() for k, v in net.state_dict().items()}
    cfg = FinetuneConfig(algo=algo, frames=1024, num_envs=16, learning_rate=1e-3, final_eval_episodes=3)
    new, card = finetune(net, tiny_set.worlds, cfg, seed=0)
    assert new is not net and card["frames"] == 1024
    assert all(torch.equal(v, net.state_dict()[k]) for k, v in before.items())
    assert any(not torch.equal(v, new.state_dict()[k]) for k, v in before.items())
    with pytest.raises(ConfigError, match="algo"):
        finetune(net, tiny_set.worlds, FinetuneConfig(algo="sac"), seed=0)
