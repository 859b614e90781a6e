"""The recognising mode: rays report the shape of what they hit, and no class reaches the network."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env

from adaptenv.agents.checkpoint import load_checkpoint, save_checkpoint
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.network import NavNet, NetConfig, obs_to_tensors
from adaptenv.errors import ConfigError
from adaptenv.scene.occupancy import LABEL_OBJECT0
from adaptenv.sim.egomap import MAP_CHANNELS, TARGET, EgoMap
from adaptenv.sim.env import NavEnv, NavVectorEnv
from adaptenv.sim.perception import CLASS_OBJECT, N_SHAPE, check_perception, object_shapes
from adaptenv.sim.spec import N_RAYS, class_id
from adaptenv.sim.vector import BatchSim, EpisodeSampler


@pytest.fixture(scope="module")
def tiny_worlds():
    return load_house_set("preset:tiny").worlds


@pytest.fixture(scope="module")
def tiny_houses():
    return load_house_set("preset:tiny").houses


def _rollout(worlds, steps=40, agents=32, seed=0):
    """Observations of random agents in a BatchSim with shapes, one per step."""
    sim = BatchSim(worlds, max_steps=300, shapes=True)
    rng = np.random.default_rng(seed)
    obs, _ = sim.reset(*EpisodeSampler(worlds).draw(rng, agents))
    out = [obs]
    for _ in range(steps):
        obs, *_ = sim.step(rng.integers(0, 6, agents))
        out.append(obs)
    return out


def test_object_rays_report_the_shape_of_an_object_of_their_class(tiny_worlds):
    """Every ray that hits an object reads the height and footprint sides of an object of the class the scan saw."""
    shapes_by_class = {}
    for w in tiny_worlds:
        for k, fp in enumerate(w.geometry.floor_objects):
            shapes_by_class.setdefault(class_id(fp.object_type), []).append(object_shapes(w)[k])
    hits = misses = 0
    for obs in _rollout(tiny_worlds):
        sem, shape = obs["semantic"], obs["shape"]
        assert shape.shape == (len(sem), N_RAYS, N_SHAPE)
        assert (shape[sem < CLASS_OBJECT] == 0).all()
        for i, r in zip(*np.nonzero(sem >= CLASS_OBJECT), strict=True):
            rows = np.array(shapes_by_class[int(sem[i, r])])
            if np.isclose(rows, shape[i, r]).all(1).any():
                hits += 1
            else:
                misses += 1
    assert hits > 1000
    assert misses <= 0.001 * hits  # grazing rays may end in a neighbouring cell


def test_object_shapes_are_the_catalog_sizes(tiny_worlds):
    w = tiny_worlds[0]
    table = object_shapes(w)
    for k, fp in enumerate(w.geometry.floor_objects):
        assert table[k].tolist() == pytest.approx([fp.height, max(fp.size), min(fp.size)])
    assert LABEL_OBJECT0 > 3  # object labels never collide with wall, door or window labels


def test_the_labelled_observation_has_no_shape_key_unless_asked(tiny_worlds):
    sim = BatchSim(tiny_worlds)
    obs, _ = sim.reset(*EpisodeSampler(tiny_worlds).draw(np.random.default_rng(0), 4))
    assert "shape" not in obs


def _batch(worlds, with_map=True):
    obs = _rollout(worlds, steps=12, agents=8)[-1]
    if with_map:
        emap = EgoMap(8)
        emap.update(obs, np.ones(8, bool))
        obs["map"] = emap.crop()
    return obs


def test_the_recognising_network_cannot_read_classes(tiny_worlds):
    """Relabelling every object class, the target bits of the map or the target flag leaves a shape network's
    output unchanged; a labelled network's output changes (the check can fail)."""
    obs = _batch(tiny_worlds)
    assert (obs["semantic"] >= CLASS_OBJECT).any()
    other = dict(obs)
    other["semantic"] = np.where(obs["semantic"] >= CLASS_OBJECT, obs["semantic"] + 7, obs["semantic"])
    other["map"] = obs["map"] | np.uint8(TARGET | TARGET << 4)
    done = torch.ones(8, dtype=torch.bool)
    for shape_net, should_match in ((True, True), (False, False)):
        torch.manual_seed(0)
        net = NavNet(NetConfig(map_channels=MAP_CHANNELS, shape_features=N_SHAPE if shape_net else 0)).eval()
        with torch.no_grad():
            a, _ = net.step(obs_to_tensors(obs), done, net.initial_state(8))
            b, _ = net.step(obs_to_tensors(other), done, net.initial_state(8))
        assert torch.allclose(a, b) == should_match


def test_the_recognising_network_reads_shapes(tiny_worlds):
    obs = _batch(tiny_worlds, with_map=False)
    other = {**obs, "shape": obs["shape"] * 2.0}
    net = NavNet(NetConfig(shape_features=N_SHAPE)).eval()
    done = torch.ones(8, dtype=torch.bool)
    with torch.no_grad():
        a, _ = net.step(obs_to_tensors(obs), done, net.initial_state(8))
        b, _ = net.step(obs_to_tensors(other), done, net.initial_state(8))
    assert not torch.allclose(a, b)
    with pytest.raises(ValueError, match="shape"):
        net.step(obs_to_tensors({k: v for k, v in obs.items() if k != "shape"}), done, net.initial_state(8))


def test_a_shape_checkpoint_round_trips(tmp_path):
    net = NavNet(NetConfig(shape_features=N_SHAPE))
    save_checkpoint(tmp_path / "p.pt", net, {})
    loaded = load_checkpoint(tmp_path / "p.pt")
    assert loaded.net.config.perception == "shape" and loaded.policy().perception == "shape"


@pytest.mark.parametrize("env_cls", [NavEnv, NavVectorEnv])
def test_the_gym_envs_report_shapes_and_no_classes(env_cls, tiny_houses):
    kwargs = {"num_envs": 3} if env_cls is NavVectorEnv else {}
    env = env_cls(houses=tiny_houses, map=True, perception="shape", **kwargs)
    obs, _ = env.reset(seed=0)
    seen_objects = False
    for _ in range(30):
        obs, *_ = env.step(env.action_space.sample())
        assert obs in env.observation_space
        assert np.asarray(obs["semantic"]).max() <= CLASS_OBJECT
        assert not np.asarray(obs["map"])[..., [2, 6], :, :].any()
        seen_objects |= bool((np.asarray(obs["shape"]) > 0).any())
    assert seen_objects


def test_the_shape_env_passes_gymnasiums_checker(tiny_houses):
    check_env(NavEnv(houses=tiny_houses, map=True, perception="shape"), skip_render_check=True)


def test_an_unknown_perception_is_one_config_error():
    with pytest.raises(ConfigError, match="--perception 'camera' is unknown; use one of labels, shape"):
        check_perception("camera")
