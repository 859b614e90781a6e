"""Gymnasium front ends: check_env, same-seed determinism, reset-to-a-level, vector env autoreset."""

from __future__ import annotations

import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import adaptenv  # noqa: F401  (registers the ids)
from adaptenv.errors import ConfigError
from adaptenv.render.topdown import env_frame
from adaptenv.sim.env import NavEnv, NavVectorEnv, make_sync_vector_env
from adaptenv.sim.spec import END, MOVE_AHEAD, N_ACTIONS, NO_ACTION, ROTATE_LEFT, class_id
from adaptenv.sim.world import compile_world
from tests.sim.helpers import LOW_TARGET, Obj, one_room

ENV_IDS = ["adaptenv/ObjectNav-v0"]


@pytest.fixture(scope="module")
def small_house():
    return one_room((6.0, 3.0), objects=[Obj(LOW_TARGET, 5.5, 1.5)])


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env_passes_without_warnings(env_id, real_house_path):
    env = gymnasium.make(env_id, houses=[real_house_path], render_mode="rgb_array")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    assert [str(w.message) for w in caught] == []


def _rollout(env: NavEnv, seed: int, n: int = 60) -> list:
    obs, info = env.reset(seed=seed)
    out = [(obs["depth"].tolist(), obs["semantic"].tolist(), info["pose"], info["target_type"])]
    rng = np.random.default_rng(seed)
    for _ in range(n):
        obs, reward, terminated, truncated, info = env.step(int(rng.integers(N_ACTIONS - 1)))
        out.append((obs["depth"].tolist(), reward, terminated, truncated, info["pose"]))
        if terminated or truncated:
            obs, info = env.reset()
            out.append(info["pose"])
    return out


def test_same_seed_rollouts_are_identical(real_house_path, small_house):
    houses = [real_house_path, small_house]
    a, b = NavEnv(houses=houses), NavEnv(houses=houses)
    assert _rollout(a, 7) == _rollout(b, 7)
    assert _rollout(a, 7) != _rollout(a, 8)


def test_spaces_contain_the_observations(real_house_path):
    env = NavEnv(houses=[real_house_path], max_steps=20)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    for a in [MOVE_AHEAD, ROTATE_LEFT, MOVE_AHEAD] * 8:
        obs, reward, terminated, truncated, info = env.step(a)
        assert env.observation_space.contains(obs)
        assert isinstance(reward, float) and isinstance(terminated, bool) and isinstance(truncated, bool)
        if truncated:
            break
    assert truncated and not terminated and info["steps"] == 20
    assert env.action_space == gymnasium.spaces.Discrete(N_ACTIONS)


def test_reset_to_a_level_with_options(small_house):
    env = NavEnv()
    world = compile_world(small_house, name="level")
    for level in (small_house, world):
        obs, info = env.reset(seed=0, options={"house": level, "target_type": "GarbageCan",
                                               "start": (4.0, 1.5, 90.0)})
        assert info["pose"] == (4.0, 1.5, 90.0)
        assert obs["target"] == class_id("GarbageCan") and obs["prev_action"] == NO_ACTION
        obs, reward, terminated, truncated, info = env.step(END)
        assert terminated and not truncated and info["success"] and info["spl"] == 1.0
        assert reward == pytest.approx(-0.01 + 10.0)
    with pytest.raises(ConfigError, match="options"):
        env.reset(options={"houze": small_house})


def test_terminated_without_success_reports_spl_zero(small_house):
    env = NavEnv(houses=[small_house])
    env.reset(seed=1, options={"start": (0.8, 1.5, 270.0)})
    _, _, terminated, _, info = env.step(END)
    assert terminated and not info["success"] and info["spl"] == 0.0
    assert {"collisions", "geodesic", "pose", "path_length"} <= set(info)


def test_render_rgb_array(small_house):
    env = NavEnv(houses=[small_house], render_mode="rgb_array", renderer=env_frame)
    env.reset(seed=0)
    for a in (MOVE_AHEAD, ROTATE_LEFT, MOVE_AHEAD):
        env.step(a)
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    assert len(env.trajectory().steps) == 3
    assert NavEnv(houses=[small_house]).render() is None


def test_the_simulator_does_not_import_the_renderer(small_house):
    """Rendering sits above the simulator: a NavEnv renders through the renderer it is given. (The file helpers and
    the limits on what is read belong to no layer: every layer may use them.)"""
    with pytest.raises(ConfigError, match="needs a renderer"):
        NavEnv(houses=[small_house], render_mode="rgb_array")
    import subprocess
    import sys

    code = ("import sys, adaptenv.sim.env, adaptenv.sim.vector, adaptenv.sim.rollout; "
            "print(sorted(m for m in sys.modules if m.startswith('adaptenv.') and not m.startswith(('adaptenv.sim', "
            "'adaptenv.scene', 'adaptenv.errors', 'adaptenv.vocabulary', 'adaptenv._gym', 'adaptenv._numba_cache', "
            "'adaptenv.configfile', 'adaptenv.files', 'adaptenv.limits'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", f"the simulator imported upper layers: {out}"


def test_vector_env_steps_and_autoresets(real_house_path, small_house):
    venv = gymnasium.make_vec("adaptenv/ObjectNav-v0", num_envs=5, vectorization_mode="vector_entry_point",
                              houses=[real_house_path, small_house], max_steps=4)
    assert isinstance(venv.unwrapped, NavVectorEnv)
    obs, info = venv.reset(seed=3)
    assert venv.observation_space.contains(obs)
    actions = np.array([END, ROTATE_LEFT, ROTATE_LEFT, MOVE_AHEAD, ROTATE_LEFT])
    obs, reward, terminated, truncated, info = venv.step(actions)
    assert terminated.tolist() == [True, False, False, False, False]
    for _ in range(3):
        obs, reward, terminated, truncated, info = venv.step(np.full(5, ROTATE_LEFT))
    assert truncated[1:].all() and not terminated.any()
    assert obs["prev_action"][0] == ROTATE_LEFT  # slot 0 was reset one step after it ended
    obs, reward, terminated, truncated, info = venv.step(np.full(5, ROTATE_LEFT))
    assert reward[1:].tolist() == [0.0] * 4 and not (terminated | truncated)[1:].any()
    assert obs["prev_action"][1:].tolist() == [NO_ACTION] * 4 and info["steps"][1:].tolist() == [0] * 4
    assert venv.observation_space.contains(obs)
    venv.close()


def test_vector_env_same_seed_is_deterministic(real_house_path):
    def run(seed: int) -> list:
        venv = NavVectorEnv(num_envs=3, houses=[real_house_path], max_steps=5)
        obs, _ = venv.reset(seed=seed)
        trace = [obs["depth"].copy()]
        rng = np.random.default_rng(0)
        for _ in range(12):
            obs, reward, *_ = venv.step(rng.integers(N_ACTIONS, size=3))
            trace += [obs["depth"].copy(), reward.copy()]
        return trace

    for x, y in zip(run(1), run(1), strict=True):
        np.testing.assert_array_equal(x, y)


def test_sync_vector_env_factory(small_house):
    venv = make_sync_vector_env(2, houses=[small_house])
    obs, _ = venv.reset(seed=0)
    assert obs["depth"].shape == (2, 32)
    obs, *_ = venv.step(np.array([MOVE_AHEAD, ROTATE_LEFT]))
    assert venv.observation_space.contains(obs)
    venv.close()


@pytest.mark.slow
def test_builtin_procedural_houses_are_used_without_houses():
    env = NavEnv()
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert info["house"].startswith("house_")
