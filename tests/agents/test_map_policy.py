"""The map-reading policy: the network reads the map it builds, runners drive it unchanged, training stores the map."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from adaptenv.agents.checkpoint import load_checkpoint, save_checkpoint
from adaptenv.agents.evaluate import run_episodes, sample_episodes
from adaptenv.agents.network import (
    MapObserver,
    MapState,
    NavNet,
    NetConfig,
    NeuralPolicy,
    obs_to_tensors,
    unpack_map,
)
from adaptenv.agents.train import TrainConfig, train
from adaptenv.sim.egomap import MAP_CHANNELS, unpack
from adaptenv.sim.vector import BatchSim


def map_net(seed: int = 0) -> NavNet:
    torch.manual_seed(seed)
    return NavNet(NetConfig(hidden=32, feature_dim=32, conv_channels=8, map_channels=MAP_CHANNELS))


def first_obs(tiny_set, n: int = 4):
    """The first observations of ``n`` episodes in the tiny houses, and their BatchSim."""
    worlds = tiny_set.worlds
    eps = sample_episodes(worlds, n, seed=3)
    sim = BatchSim(worlds)
    obs, _ = sim.reset([e for _, e in eps], [i for i, _ in eps])
    return sim, obs


def test_unpack_map_matches_the_numpy_unpacking():
    packed = np.random.default_rng(0).integers(0, 256, (3, 32, 32), dtype=np.uint8)
    ours = unpack_map(torch.from_numpy(packed), MAP_CHANNELS).contiguous().numpy()
    assert np.array_equal(ours, unpack(packed))


def test_packed_and_unpacked_maps_give_the_same_features_in_either_precision():
    """Packed crops are unpacked straight to the autocast dtype; the features equal those of the Gym env's float map."""
    net = map_net()
    rng = np.random.default_rng(1)
    packed = rng.integers(0, 256, (2, 3, 32, 32), dtype=np.uint8)
    obs = {"depth": torch.rand(2, 3, net.config.n_rays), "semantic": torch.randint(0, 5, (2, 3, net.config.n_rays)),
           "target": torch.randint(0, 5, (2, 3)), "prev_action": torch.zeros(2, 3, dtype=torch.int64),
           "collided": torch.zeros(2, 3, dtype=torch.int64)}
    for autocast in (False, True):
        with torch.no_grad(), torch.autocast("cpu", torch.bfloat16, enabled=autocast):
            a = net.encode({**obs, "map": torch.from_numpy(packed)})
            b = net.encode({**obs, "map": torch.from_numpy(unpack(packed))})
        assert a.shape == (2, 3, net.config.feature_dim) and torch.equal(a, b)
    assert unpack_map(torch.from_numpy(packed[0]), MAP_CHANNELS, torch.bfloat16).dtype == torch.bfloat16


def test_the_map_changes_the_network_output_and_is_required(tiny_set):
    net = map_net().eval()
    _, obs = first_obs(tiny_set)
    with_map = MapObserver(4)(obs, np.ones(4, bool))
    t = obs_to_tensors(with_map)
    h = net.initial_state(4)
    first = torch.ones(4, dtype=torch.bool)
    with torch.no_grad():
        a, _ = net.step(t, first, h)
        b, _ = net.step({**t, "map": torch.zeros_like(t["map"])}, first, h)
    assert not torch.allclose(a, b)  # the map reaches the logits
    with pytest.raises(ValueError, match="MapObserver"):
        net.step(obs_to_tensors(obs), first, h)


def test_map_policy_state_carries_the_map_and_forget_wipes_chosen_agents(tiny_set):
    sim, obs = first_obs(tiny_set)
    policy = NeuralPolicy(map_net())
    state = policy.initial_state(4)
    assert isinstance(state, MapState)
    done = np.ones(4, bool)
    for _ in range(5):
        actions, state = policy.act(obs, state, done)
        obs, *_ = sim.step(actions)
        done[:] = False
    emap = state.observer.emap
    assert (emap.grid != 0).any(axis=(1, 2)).all() and state.h.abs().sum() > 0
    state = policy.forget(state, np.array([1, 3]))
    assert not emap.grid[[1, 3]].any() and emap.grid[[0, 2]].any()
    assert np.all(emap.pose[[1, 3]] == 0.0)
    assert torch.all(state.h[[1, 3]] == 0) and torch.all(state.h[[0, 2]].abs().sum(-1) > 0)


def test_map_policy_checkpoint_roundtrip_and_batch_independent_episodes(tiny_set, tmp_path):
    net = map_net(seed=4)
    ckpt = load_checkpoint(save_checkpoint(tmp_path / "m.pt", net, {}))
    assert ckpt.net.config.map_channels == MAP_CHANNELS
    worlds = tiny_set.worlds
    episodes = sample_episodes(worlds, 6, seed=1)
    a, _ = run_episodes(worlds, episodes, NeuralPolicy(net), batch=6, max_steps=40)
    b, _ = run_episodes(worlds, episodes, ckpt.policy(), batch=2, max_steps=40)
    assert [(r.steps, r.success) for r in a] == [(r.steps, r.success) for r in b]


@pytest.mark.slow
def test_training_a_map_network_stores_maps_and_lowers_the_loss(tmp_path, monkeypatch):
    from adaptenv.agents import train as train_module

    seen = []
    real_add = train_module.SequenceBuffer.add

    def spy(self, block):
        seen.append(block["map"].copy())
        real_add(self, block)

    monkeypatch.setattr(train_module.SequenceBuffer, "add", spy)
    cfg = TrainConfig(houses="preset:tiny", frames=4096, output="", run_dir="", num_envs=16, rollout_steps=32,
                      chunk_len=16, batch_chunks=16, updates_per_iter=8, hidden=32, feature_dim=32,
                      learning_rate=3e-3, eval_every=0, final_eval_episodes=4, progress=False, tensorboard=False,
                      max_episode_steps=100, threads=1, calibrate_episodes=0, map=True)
    result = train(cfg)
    assert result.net.config.map_channels == MAP_CHANNELS
    assert len(seen) == 8 and all(b.shape == (32, 16, 32, 32) for b in seen)
    assert all((b != 0).mean() > 0.05 for b in seen)  # real maps, not zeros
    losses = [r["losses/loss"] for r in result.rows if "losses/loss" in r]
    assert np.mean(losses[-2:]) < losses[0] - 0.2


def test_the_network_reads_the_gym_envs_unpacked_map_as_the_packed_one(tiny_set):
    from adaptenv.sim.env import NavVectorEnv

    env = NavVectorEnv(num_envs=3, houses=list(tiny_set.worlds), map=True)
    obs, _ = env.reset(seed=0)
    net = map_net().eval()
    packed = {**obs, "map": env.emap.crop()}
    first, h = torch.ones(3, dtype=torch.bool), net.initial_state(3)
    with torch.no_grad():
        a, _ = net.step(obs_to_tensors(obs), first, h)
        b, _ = net.step(obs_to_tensors(packed), first, h)
    torch.testing.assert_close(a, b)
