"""Policy interface, neural network, checkpoints and the --policy registry."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from adaptenv.agents.checkpoint import load_checkpoint, save_checkpoint
from adaptenv.agents.network import NavNet, NetConfig, NeuralPolicy, count_parameters
from adaptenv.agents.policy import Policy, PolicyContext, RandomPolicy, bind_policy
from adaptenv.agents.registry import resolve_policy
from adaptenv.errors import ConfigError
from adaptenv.sim.spec import N_ACTIONS, N_RAYS, NO_ACTION, n_classes


def fake_obs(batch: int, seed: int = 0) -> dict[str, np.ndarray]:
    """A random but well-formed batched observation."""
    rng = np.random.default_rng(seed)
    return {"depth": rng.random((batch, N_RAYS), dtype=np.float32),
            "semantic": rng.integers(0, n_classes(), (batch, N_RAYS)),
            "target": rng.integers(4, n_classes(), batch),
            "prev_action": rng.integers(0, NO_ACTION + 1, batch),
            "collided": rng.integers(0, 2, batch)}


def small_net(seed: int = 0) -> NavNet:
    torch.manual_seed(seed)
    return NavNet(NetConfig(hidden=32, feature_dim=32, conv_channels=8))


def rollout_actions(policy, steps: int = 5, batch: int = 6) -> np.ndarray:
    state = policy.initial_state(batch)
    done = np.ones(batch, dtype=bool)
    out = []
    for t in range(steps):
        actions, state = policy.act(fake_obs(batch, seed=t), state, done)
        out.append(actions)
        done = np.zeros(batch, dtype=bool)
    return np.stack(out)


def test_random_policy_is_seeded_and_in_range():
    a = rollout_actions(RandomPolicy(seed=3))
    assert np.array_equal(a, rollout_actions(RandomPolicy(seed=3)))
    assert not np.array_equal(a, rollout_actions(RandomPolicy(seed=4)))
    assert a.min() >= 0 and a.max() < N_ACTIONS


def test_bound_random_policy_depends_only_on_episode_seed():
    """Per-episode seeding: the same episode gets the same actions whatever its slot."""
    def run(seeds):
        policy = RandomPolicy(seed=1)
        ctx = PolicyContext.empty([], len(seeds))
        ctx.seeds[:] = seeds
        bind_policy(policy, ctx)
        state = policy.initial_state(len(seeds))
        done = np.ones(len(seeds), dtype=bool)
        acts = []
        for _ in range(8):
            a, state = policy.act(fake_obs(len(seeds)), state, done)
            acts.append(a)
            done[:] = False
        return np.stack(acts)

    a = run([10, 11, 12])
    b = run([12, 10])
    assert np.array_equal(a[:, 0], b[:, 1]) and np.array_equal(a[:, 2], b[:, 0])


def test_network_shapes_and_done_resets_memory():
    net = small_net()
    assert count_parameters(net) > 0
    policy = NeuralPolicy(net)
    assert isinstance(policy, Policy)
    obs = fake_obs(4)
    h = policy.initial_state(4)
    _, h1 = policy.act(obs, h, np.ones(4, dtype=bool))
    _, h2 = policy.act(obs, h1, np.zeros(4, dtype=bool))
    _, h3 = policy.act(obs, h2, np.ones(4, dtype=bool))
    assert h1.shape == (4, 32)
    assert not torch.allclose(h1, h2)
    assert torch.allclose(h1, h3)  # done wipes the memory: same as a fresh start


def test_sequence_forward_matches_stepping():
    net = small_net().eval()
    T, B = 6, 3
    obs_seq = [fake_obs(B, seed=t) for t in range(T)]
    done = np.zeros((T, B), dtype=bool)
    done[0] = True
    done[3, 1] = True
    from adaptenv.agents.network import obs_to_tensors

    seq = {k: torch.stack([obs_to_tensors(o)[k] for o in obs_seq]) for k in obs_seq[0]}
    with torch.no_grad():
        logits, _ = net(seq, torch.as_tensor(done), net.initial_state(B))
        h = net.initial_state(B)
        for t in range(T):
            step_logits, h = net.step(obs_to_tensors(obs_seq[t]), torch.as_tensor(done[t]), h)
            torch.testing.assert_close(step_logits, logits[t], rtol=1e-5, atol=1e-5)


def test_checkpoint_roundtrip_gives_identical_actions(tmp_path):
    net = small_net(seed=5)
    path = save_checkpoint(tmp_path / "p.pt", net, {"frames": 123})
    ckpt = load_checkpoint(path)
    assert ckpt.meta["frames"] == 123
    a = rollout_actions(NeuralPolicy(net))
    b = rollout_actions(ckpt.policy())
    assert np.array_equal(a, b)
    c = rollout_actions(resolve_policy(str(path)))
    assert np.array_equal(a, c)


def test_bad_checkpoint_is_one_clear_error(tmp_path):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(ConfigError, match="bad.pt"):
        load_checkpoint(bad)
    with pytest.raises(ConfigError, match="no such checkpoint"):
        resolve_policy(str(tmp_path / "missing.pt"))


@pytest.mark.parametrize("edit, text", [
    (lambda doc: doc["net_config"].__setitem__("fea\nure_dim", 1), "net_config holds fea\\nure_dim"),
    (lambda doc: doc["state_dict"].__setitem__("head.2.bias", doc["state_dict"]["head.2.bias"].to(torch.complex64)),
     "weight head.2.bias is of type torch.complex64, not floating point"),
], ids=["line-break-in-a-field-name", "complex-weights"])
def test_a_tampered_checkpoint_is_refused_in_one_line(edit, text, tmp_path):
    doc = torch.load(save_checkpoint(tmp_path / "p.pt", small_net(seed=1)), weights_only=True)
    edit(doc)
    torch.save(doc, tmp_path / "bad.pt")
    with pytest.raises(ConfigError) as err:
        load_checkpoint(tmp_path / "bad.pt")
    assert "\n" not in str(err.value) and text in str(err.value)


def test_registry_builtins_and_unknown():
    assert isinstance(resolve_policy("random"), RandomPolicy)
    assert resolve_policy("random:7").seed == 7
    with pytest.raises(ConfigError, match="unknown policy"):
        resolve_policy("walk-randomly")
    with pytest.raises(ConfigError, match="no attribute"):
        resolve_policy("adaptenv.agents.policy:nope")
    with pytest.raises(ConfigError, match="not a policy"):
        resolve_policy("adaptenv.sim.spec:ACTIONS")


def test_registry_loads_user_policy_from_module_and_file(tmp_path):
    file = tmp_path / "mine.py"
    file.write_text(
        "import numpy as np\n"
        "class Spinner:\n"
        "    def initial_state(self, batch):\n        return None\n"
        "    def act(self, obs, state, done):\n"
        "        return np.full(len(done), 3, dtype=np.int64), state\n"
        "policy = Spinner()\n"
        "def make():\n    return Spinner()\n")
    for spec in (f"{file}:policy", f"{file}:Spinner", f"{file}:make"):
        policy = resolve_policy(spec)
        actions, _ = policy.act(fake_obs(2), policy.initial_state(2), np.ones(2, dtype=bool))
        assert actions.tolist() == [3, 3]
    assert isinstance(resolve_policy("adaptenv.agents.policy:RandomPolicy"), RandomPolicy)


def test_choose_actions_ends_only_when_confident():
    from adaptenv.agents.network import choose_actions
    from adaptenv.sim.spec import END

    p = torch.tensor([[0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.9],   # confident end
                      [0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5],   # unsure: a motion (the only one)
                      [0.0, 0.0, 0.3, 0.3, 0.0, 0.0, 0.4]])  # motions 2 or 3 by the uniform draw
    logits = torch.log(p + 1e-12)
    assert choose_actions(logits, None, 0.8).tolist() == [END, 0, 2]
    assert choose_actions(logits, np.array([0.2, 0.2, 0.2]), 0.8).tolist() == [END, 0, 2]
    assert choose_actions(logits, np.array([0.9, 0.9, 0.9]), 0.8).tolist() == [END, 0, 3]
    assert choose_actions(logits, np.array([0.9, 0.9, 0.9]), 0.45).tolist() == [END, END, 3]


def test_shipped_scan_only_checkpoint_loads_with_its_card():
    import json

    from adaptenv.agents.registry import pretrained_path

    policy = resolve_policy("pretrained-scan")
    card = json.loads(pretrained_path("pretrained-scan").with_suffix(".json").read_text())
    # the threshold the policy acts with is the one its card says was calibrated
    assert policy.name == "pretrained-scan" and policy.net.config.map_channels == 0 and policy.end_threshold == card["end_threshold_calibration"]["threshold"]
    assert card["houses"] == "preset:pretrain-train" and card["final_train_success"] >= 0.8
    assert card["command"].startswith("adaptenv train") and "selection" in card
    actions = rollout_actions(policy)
    assert actions.min() >= 0 and actions.max() < N_ACTIONS


def test_shipped_map_reading_checkpoint_loads_with_its_card():
    import json

    from adaptenv.agents.network import MapState
    from adaptenv.agents.registry import init_checkpoint, pretrained_path

    policy = resolve_policy("pretrained-map")
    card = json.loads(pretrained_path("pretrained-map").with_suffix(".json").read_text())
    assert policy.name == "pretrained-map" and policy.net.config.map_channels > 0
    assert policy.end_threshold == card["end_threshold_calibration"]["threshold"]
    assert "--map" in card["command"] and "--teacher map-explorer" in card["command"] and "selection" in card
    assert isinstance(policy.initial_state(2), MapState)
    assert init_checkpoint("pretrained-map") == pretrained_path("pretrained-map")


def test_shipped_ppo_checkpoint_loads_with_its_card_and_selection():
    import json

    from adaptenv.agents.network import MapState
    from adaptenv.agents.registry import init_checkpoint, pretrained_path

    policy = resolve_policy("pretrained-ppo")
    card = json.loads(pretrained_path("pretrained-ppo").with_suffix(".json").read_text())
    assert policy.name == "pretrained-ppo" and policy.net.config.map_channels > 0
    assert policy.end_threshold == card["end_threshold"] == card["end_threshold_calibration"]["threshold"]
    assert card["algo"] == "ppo" and card["command"].startswith("adaptenv ppo") and "--kl-coef" in card["command"]
    assert [s["stage"] for s in card["stages"]] == [1, 2, 3] and card["stages"][0]["init"] == "pretrained-map"
    assert card["frames_total"] == sum(s["frames"] for s in card["stages"])
    assert "docs/results/ppo-pi0/DECLARED.md" in card["selection"]
    assert '": "/' not in json.dumps(card) and " /" not in card["command"], "no absolute paths in the card"
    assert isinstance(policy.initial_state(2), MapState)
    assert init_checkpoint("pretrained-ppo") == pretrained_path("pretrained-ppo")


def test_the_default_policy_is_the_strongest_shipped_agent_and_runs_record_its_weights():
    import hashlib

    from adaptenv.agents.registry import init_checkpoint, pretrained_path, weights_record

    assert pretrained_path("pretrained") == pretrained_path("pretrained-ppo"), "pretrained: the PPO map agent"
    assert init_checkpoint("pretrained") == pretrained_path("pretrained-ppo")
    assert resolve_policy("pretrained").net.config.map_channels > 0
    record = weights_record("pretrained")
    digest = hashlib.sha256(pretrained_path("pretrained-ppo").read_bytes()).hexdigest()
    assert record == {"name": "pretrained", "file": "pretrained-ppo.pt", "sha256": digest}
    assert weights_record("pretrained-scan")["sha256"] != digest
    assert weights_record("expert") is None and weights_record("no/such.pt") is None


def test_a_users_policy_is_held_to_the_contract_naming_the_episode(tmp_path):
    from adaptenv.agents.registry import CheckedPolicy
    from adaptenv.errors import PolicyError

    file = tmp_path / "rogue.py"
    file.write_text(
        "import numpy as np\n"
        "class Rogue:\n"
        "    name = 'rogue'\n"
        "    def __init__(self):\n        self.answers = []\n"
        "    def initial_state(self, batch):\n        return None\n"
        "    def act(self, obs, state, done):\n"
        "        return np.asarray(self.answers.pop(0)), state\n"
        "policy = Rogue()\n")
    policy = resolve_policy(f"{file}:policy")
    assert isinstance(policy, CheckedPolicy) and policy.name == "rogue"  # its own attributes show through
    policy.policy.answers = [[0, 6], [1.0, 2], [3, 7], [1, 2, 3], [[1, 2]], [float("nan"), 1], [True, False]]
    state = policy.initial_state(2)
    first, _ = policy.act(fake_obs(2), state, np.ones(2, dtype=bool))
    assert first.dtype == np.int64 and first.tolist() == [0, 6]
    assert policy.act(fake_obs(2), state, np.zeros(2, dtype=bool))[0].tolist() == [1, 2]  # whole floats pass
    with pytest.raises(PolicyError, match=r"rogue.py:policy returned action 7 in episode 2; an action is a whole "
                                          r"number from 0 to 6 \(m, b, l, r, ls, rs, end\)"):
        policy.act(fake_obs(2), state, np.array([False, True]))  # slot 1 began the third episode
    for shape in ("3 actions for 2 episodes", "2 actions for 2 episodes"):  # a list of 3; a (1, 2) array
        with pytest.raises(PolicyError, match=shape if shape.startswith("3") else "one action per episode"):
            policy.act(fake_obs(2), state, np.zeros(2, dtype=bool))
    for bad in ("nan", "True"):
        with pytest.raises(PolicyError, match=f"returned action {bad} in episode 0"):
            policy.act(fake_obs(2), state, np.zeros(2, dtype=bool))


def test_adaptenvs_own_policies_are_not_wrapped():
    from adaptenv.agents.registry import CheckedPolicy

    assert not isinstance(resolve_policy("adaptenv.agents.policy:RandomPolicy"), CheckedPolicy)


def test_scratch_specs_build_fresh_map_reading_networks_drawn_from_the_seed():
    from adaptenv.agents.registry import init_checkpoint

    state = torch.get_rng_state()
    a, b, c = (resolve_policy(spec, seed=s) for spec, s in (("scratch-shape", 1), ("scratch-shape", 1), ("scratch", 2)))
    assert torch.equal(torch.get_rng_state(), state), "torch's global generator is left as it was"
    assert isinstance(a, NeuralPolicy) and a.net.config.perception == "shape" and a.net.config.map_channels
    assert c.net.config.perception == "labels" and c.net.config.map_channels
    assert all(torch.equal(x, y) for x, y in zip(a.net.state_dict().values(), b.net.state_dict().values(), strict=True))
    other = resolve_policy("scratch-shape", seed=2).net.state_dict()
    assert any(not torch.equal(x, other[k]) for k, x in a.net.state_dict().items())
    with pytest.raises(ConfigError, match="no network to start from"):
        init_checkpoint("scratch")
