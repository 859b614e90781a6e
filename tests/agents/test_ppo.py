"""PPO fine-tuning: the acting rule's log-probabilities, a value warm-up that leaves the policy alone, a tiny run,
the KL anchor to the warm start, the exploration bonus, a map-reading network."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from adaptenv.agents.config import FinetuneConfig, PPOConfig, field_docs
from adaptenv.agents.evaluate import sample_episodes
from adaptenv.agents.network import MapObserver, NavNet, NetConfig, observe
from adaptenv.agents.ppo import (
    ExplorationBonus,
    anchor_kl,
    anchor_rollout_logits,
    check_ppo_config,
    log_prob_entropy,
    sample_actions,
    train_ppo,
)
from adaptenv.agents.train import finetune, ppo_rollout_steps
from adaptenv.errors import ConfigError
from adaptenv.sim.egomap import MAP_CHANNELS
from adaptenv.sim.spec import ACTIONS, END
from adaptenv.sim.vector import BatchSim


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
    with pytest.raises(ConfigError, match="--kl-coef"):
        check_ppo_config(tiny_ppo(tmp_path, kl_coef=-1.0))
    with pytest.raises(ConfigError, match="--explore-bonus"):
        check_ppo_config(tiny_ppo(tmp_path, explore_bonus=-0.1))
    with pytest.raises(ConfigError, match="--precision must be one of auto, fp32, bf16"):
        check_ppo_config(tiny_ppo(tmp_path, precision="fp16"))


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


def test_anchor_kl_is_the_kl_of_the_acting_rule():
    torch.manual_seed(0)
    logits, logits0 = torch.randn(5, 3, 7, requires_grad=True), torch.randn(5, 3, 7)
    p, q = torch.softmax(logits, -1), torch.softmax(logits0, -1)
    full = (p * (p / q).log()).sum(-1)
    assert torch.allclose(anchor_kl(logits, logits0, "sample"), full, atol=1e-6)
    pm, qm = p[..., :END] / p[..., :END].sum(-1, keepdim=True), q[..., :END] / q[..., :END].sum(-1, keepdim=True)
    pe, qe = p[..., END], q[..., END]
    stop = pe * (pe / qe).log() + (1 - pe) * ((1 - pe) / (1 - qe)).log()
    threshold = anchor_kl(logits, logits0, "threshold")
    assert torch.allclose(threshold, stop + (pm * (pm / qm).log()).sum(-1), atol=1e-5)
    threshold.sum().backward()  # the masked end logit leaves no NaN in the gradient
    assert torch.isfinite(logits.grad).all()
    for rule in ("sample", "threshold"):
        assert anchor_kl(logits0, logits0.clone(), rule).abs().max() < 1e-6


def bonus_run(tiny_set, with_observer: bool, n: int = 4) -> tuple[list[np.ndarray], np.ndarray]:
    """New cells at each step of ``n`` agents that turn right in place 13 times from their starts, and the cells
    their maps gained after the first view."""
    eps = sample_episodes(tiny_set.worlds, n, seed=5)
    sim = BatchSim(tiny_set.worlds)
    obs, _ = sim.reset([e for _, e in eps], [i for i, _ in eps])
    observer = MapObserver(n) if with_observer else None
    bonus = ExplorationBonus(n, observer)
    assert (observer is not None and bonus.emap is observer.emap) == with_observer  # reuses the network's map
    first = np.ones(n, bool)
    new = [bonus(observe(observer, obs, first), first)]
    start = bonus.emap.seen_counts()
    for _ in range(13):
        obs, *_ = sim.step(np.full(n, ACTIONS.index("r")))
        first = np.zeros(n, bool)
        new.append(bonus(observe(observer, obs, first), first))
    return new, bonus.emap.seen_counts() - start


@pytest.mark.parametrize("with_observer", [False, True])
def test_exploration_bonus_counts_newly_seen_cells_only(tiny_set, with_observer):
    new, gained = bonus_run(tiny_set, with_observer)
    assert (new[0] == 0).all()  # an episode's first view earns nothing
    assert (new[1] > 0).all()  # the first turn brings 30 degrees of new view
    assert max(n.max() for n in new[:13]) > 10
    assert all((n >= 0).all() for n in new)
    assert (new[13] == 0).all()  # after twelve 30-degree turns the view repeats: nothing new
    assert np.array_equal(sum(new), gained)


@pytest.mark.slow
def test_value_warmup_leaves_the_policy_untouched(tmp_path):
    init = NavNet(NetConfig(hidden=32, feature_dim=32))
    before = {k: v.clone() for k, v in init.state_dict().items()}
    # no final evaluation: only the weights are compared
    result = train_ppo(tiny_ppo(tmp_path, output="", run_dir="", value_warmup_iters=2, frames=1024,
                                final_eval_episodes=0), init_net=init)
    assert all(torch.equal(v, result.net.state_dict()[k]) for k, v in before.items())
    moved = train_ppo(tiny_ppo(tmp_path, output="", run_dir="", frames=1024, final_eval_episodes=0), init_net=init)
    assert any(not torch.equal(v, moved.net.state_dict()[k]) for k, v in before.items())


def anchor_rows(result) -> list[float]:
    return [r["losses/kl_anchor"] for r in result.rows if "losses/kl_anchor" in r]


@pytest.mark.slow
@pytest.mark.parametrize("stop_rule", ["threshold", "sample"])
def test_kl_anchor_is_zero_before_the_policy_moves(tmp_path, stop_rule):
    init = NavNet(NetConfig(hidden=32, feature_dim=32))
    # one iteration, one minibatch, one epoch: the only update sees pi == pi_0 (same memory, same states)
    result = train_ppo(tiny_ppo(tmp_path, output="", run_dir="", frames=512, num_minibatches=1, update_epochs=1,
                                kl_coef=1.0, stop_rule=stop_rule, final_eval_episodes=0), init_net=init)
    assert anchor_rows(result) == [pytest.approx(0.0, abs=1e-7)]


@pytest.mark.slow
def test_bf16_updates_differ_from_the_collecting_policy_only_by_rounding(tmp_path):
    torch.manual_seed(0)
    init = NavNet(NetConfig(hidden=32, feature_dim=32, conv_channels=8, map_channels=MAP_CHANNELS))
    # one update that sees pi == pi_0: in fp32 the minibatch pass equals collection's, in bf16 it is rounded
    rows = {p: [r for r in train_ppo(tiny_ppo(tmp_path, output="", run_dir="", frames=512, num_minibatches=1,
                                              update_epochs=1, kl_coef=1.0, final_eval_episodes=0, precision=p),
                                     init_net=init).rows if "losses/kl_anchor" in r] for p in ("fp32", "bf16")}
    assert [r["charts/episodic_return"] for r in rows["fp32"]] == [r["charts/episodic_return"] for r in rows["bf16"]]
    assert rows["fp32"][0]["losses/kl_anchor"] == pytest.approx(0.0, abs=1e-9)
    assert 0.0 < rows["bf16"][0]["losses/kl_anchor"] < 1e-3 and 0.0 < rows["bf16"][0]["losses/approx_kl"] < 1e-3


@pytest.mark.slow
def test_a_large_kl_coef_keeps_the_policy_near_its_warm_start(tmp_path):
    torch.manual_seed(0)
    init = NavNet(NetConfig(hidden=32, feature_dim=32))
    runs = {k: train_ppo(tiny_ppo(tmp_path, output="", run_dir="", frames=2048, learning_rate=3e-3, kl_coef=k,
                                  final_eval_episodes=0), init_net=init) for k in (0.0, 10.0)}
    free, anchored = anchor_rows(runs[0.0]), anchor_rows(runs[10.0])
    assert len(free) == len(anchored) == 4 and free[-1] > free[0]  # unanchored, the policy drifts from pi_0
    assert anchored[-1] < 0.25 * free[-1]


@pytest.mark.slow
def test_ppo_fine_tunes_a_map_reading_network_with_anchor_and_bonus(tmp_path):
    torch.manual_seed(0)
    init = NavNet(NetConfig(hidden=32, feature_dim=32, conv_channels=8, map_channels=MAP_CHANNELS))
    before = {k: v.clone() for k, v in init.state_dict().items()}
    result = train_ppo(tiny_ppo(tmp_path, kl_coef=1.0, explore_bonus=0.002, final_eval_episodes=2), init_net=init)
    rows = [r for r in result.rows if "losses/kl_anchor" in r]
    assert len(rows) == 2 and all(np.isfinite(r["losses/policy_loss"]) for r in rows)
    assert all(r["charts/explore_bonus"] > 0 for r in rows)
    assert rows[0]["losses/kl_anchor"] < 1e-3  # pi_0 reads the same maps
    after = result.net.state_dict()
    # the stored maps reach the gradient: the map encoder learns
    assert any(not torch.equal(v, after[k]) for k, v in before.items() if k.startswith("map_encoder"))
    header = (tmp_path / "run" / "metrics.csv").read_text().splitlines()[0]
    assert "losses/kl_anchor" in header and "charts/explore_bonus" in header


@pytest.mark.slow
def test_the_map_explorer_labels_ppo_states_on_the_students_own_map(tmp_path, monkeypatch):
    from adaptenv.agents import ppo as ppo_module
    from adaptenv.agents import teachers

    made = []
    real = teachers.make_teacher
    monkeypatch.setattr(ppo_module, "make_teacher", lambda *a, **kw: made.append(kw) or real(*a, **kw))
    torch.manual_seed(0)
    init = NavNet(NetConfig(hidden=32, feature_dim=32, conv_channels=8, map_channels=MAP_CHANNELS))
    result = train_ppo(tiny_ppo(tmp_path, output="", run_dir="", bc_coef=0.5, bc_teacher="map-explorer",
                                final_eval_episodes=0), init_net=init)
    assert [kw["emap"] is not None for kw in made] == [True]
    assert all(np.isfinite(r["losses/bc_loss"]) and r["losses/bc_loss"] > 0 for r in result.rows
               if "losses/bc_loss" in r)


def test_anchor_logits_from_shared_features_equal_those_from_observations():
    torch.manual_seed(0)
    net = NavNet(NetConfig(hidden=32, feature_dim=32, conv_channels=8, map_channels=MAP_CHANNELS)).eval()
    c, (T, B) = net.config, (8, 3)
    obs = {"depth": torch.rand(T, B, c.n_rays), "semantic": torch.randint(0, c.n_classes, (T, B, c.n_rays)),
           "target": torch.randint(0, c.n_classes, (T, B)), "prev_action": torch.randint(0, 7, (T, B)),
           "collided": torch.randint(0, 2, (T, B)),
           "map": torch.randint(0, 256, (T, B, c.map_crop, c.map_crop), dtype=torch.uint8)}
    first = torch.rand(T, B) < 0.2
    h0 = torch.randn(B, c.hidden)
    from_obs, h_obs = anchor_rollout_logits(net, obs, first, h0, 4)
    with torch.no_grad():
        feats = net.encode(obs)
    from_feats, h_feats = anchor_rollout_logits(net, feats, first, h0, 4)
    assert torch.allclose(from_obs, from_feats, atol=1e-6) and torch.allclose(h_obs, h_feats, atol=1e-6)


@pytest.mark.slow
def test_a_frozen_encoder_keeps_its_weights_and_collects_as_the_full_update_does(tmp_path):
    torch.manual_seed(0)
    init = NavNet(NetConfig(hidden=32, feature_dim=32, conv_channels=8, map_channels=MAP_CHANNELS))
    before = {k: v.clone() for k, v in init.state_dict().items()}
    runs = {freeze: train_ppo(tiny_ppo(tmp_path, output="", run_dir="", kl_coef=1.0, final_eval_episodes=0,
                                       learning_rate=1e-3, freeze_encoder=freeze), init_net=init)
            for freeze in (False, True)}
    encoder = {f"{name}." for name, m in init.named_children() if any(m is e for e in init.encoder_modules())}
    assert encoder >= {"map_encoder.", "conv.", "features."} and not encoder & {"gru.", "head."}
    for freeze, result in runs.items():
        after = result.net.state_dict()
        moved = {k for k, v in before.items() if not torch.equal(v, after[k])}
        in_encoder = {k for k in moved if any(k.startswith(e) for e in encoder)}
        assert (not in_encoder) if freeze else in_encoder  # only the full update moves the encoder
        assert any(k.startswith(("gru.", "head.")) for k in moved)
        assert all(p.requires_grad for p in result.net.parameters())  # the returned network is trainable again
    full, frozen = ([r for r in runs[f].rows if "losses/kl_anchor" in r] for f in (False, True))
    # the first rollout is collected by the same weights from the same seeds: the same episodes end
    assert full[0]["charts/episodes"] == frozen[0]["charts/episodes"]
    assert full[0]["charts/episodic_return"] == pytest.approx(frozen[0]["charts/episodic_return"])
    assert frozen[0]["losses/kl_anchor"] < 1e-3  # pi_0 reads the same stored features


@pytest.mark.slow
@pytest.mark.parametrize("bc_teacher", ["expert", "explorer"])
def test_tiny_ppo_run_writes_checkpoint_card_and_metrics(tmp_path, bc_teacher):
    # no final evaluation (test_ppo_fine_tunes_a_map_reading_network_with_anchor_and_bonus runs one)
    result = train_ppo(tiny_ppo(tmp_path, bc_coef=0.5, bc_teacher=bc_teacher, calibrate_episodes=4,
                                final_eval_episodes=0), command="test")
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
    ppo_settings = {"kl_coef": 0.5, "explore_bonus": 0.001, "precision": "bf16", "bc_coef": 0.2}
    cfg = FinetuneConfig(algo=algo, frames=2048, num_envs=16, learning_rate=1e-3, final_eval_episodes=3,
                         **(ppo_settings if algo == "ppo" else {}))
    res = finetune(net, tiny_set.worlds, cfg, seed=0)  # PPO: one 16 x 128-step rollout; DAgger: four of 32
    new, card = res.net, res.card
    assert new is not net and card["frames"] == 2048
    if algo == "ppo":
        assert {k: card["config"][k] for k in ppo_settings} == ppo_settings
        assert card["config"]["bc_teacher"] == cfg.teacher
        # a second call continues the first one's critic and Adam moments (the loop's later iterations)
        again = finetune(new, tiny_set.worlds, cfg, seed=1, learner=res.learner)

        def steps(r):
            return {int(s["step"]) for s in r.learner["optimizer"]["state"].values()}

        # the first call's one iteration trains the fresh critic alone (its value warm-up); the second moves all
        assert res.card["config"]["value_warmup_iters"] == 1 and steps(res) == {res.card["updates"]}
        assert steps(again) == {again.card["updates"], res.card["updates"] + again.card["updates"]}
        assert again.card["config"]["value_warmup_iters"] == 0
    else:
        assert res.learner is None
        with pytest.raises(ConfigError, match="PPO only"):
            finetune(net, tiny_set.worlds, FinetuneConfig(algo=algo, kl_coef=0.5), seed=0)
    assert all(torch.equal(v, net.state_dict()[k]) for k, v in before.items())
    moved = again.net if algo == "ppo" else new  # PPO's first call only warmed up its fresh critic
    assert any(not torch.equal(v, moved.state_dict()[k]) for k, v in before.items())
    if algo == "ppo":
        assert all(torch.equal(v, new.state_dict()[k]) for k, v in before.items())
    with pytest.raises(ConfigError, match="algo"):
        finetune(net, tiny_set.worlds, FinetuneConfig(algo="sac"), seed=0)


def test_periodic_evaluation_is_paired_and_starts_at_the_warm_start(tmp_path, monkeypatch):
    """The curve starts with pi_0 before any update, and every point scores the same episodes, started at least
    min_start_distance from the target."""
    import adaptenv.agents.ppo as ppo

    seen = []

    def spy(worlds, episodes, policy, **kw):
        seen.append(([(k, e.seed, e.start) for k, e in episodes],
                     [p.detach().clone() for p in policy.net.parameters()]))
        return real(worlds, episodes, policy, **kw)

    real = ppo.run_episodes
    monkeypatch.setattr(ppo, "run_episodes", spy)
    rows = train_ppo(tiny_ppo(tmp_path, frames=2048, eval_every=1, eval_episodes=6, final_eval_episodes=0,
                              min_start_distance=1.0, learning_rate=3e-3)).rows
    assert rows[0]["iteration"] == 0 and rows[0]["frames"] == 0 and "eval/success" in rows[0]
    assert len(seen) == 5 and all(episodes == seen[0][0] for episodes, _ in seen)
    assert any(not torch.equal(a, b) for a, b in zip(seen[0][1], seen[-1][1], strict=True))  # moved


def test_ppo_rollouts_shrink_to_a_budget_under_one_full_rollout():
    assert ppo_rollout_steps(344064, 64) == 128 and ppo_rollout_steps(8192, 64) == 128
    assert ppo_rollout_steps(512, 16) == 32 and ppo_rollout_steps(1024, 16) == 64
    assert ppo_rollout_steps(100, 2) == 64  # 2 envs x one 32-step sequence cannot split into 4 minibatches


@pytest.mark.slow
def test_ppo_fine_tuning_spends_a_small_budget_not_a_full_rollout(tiny_set):
    net = NavNet(NetConfig(hidden=32, feature_dim=32))
    cfg = FinetuneConfig(algo="ppo", frames=512, num_envs=16, max_episode_steps=100, final_eval_episodes=1)
    card = finetune(net, tiny_set.worlds, cfg, seed=0).card
    assert card["frames"] == 512 and card["config"]["rollout_steps"] == 32
