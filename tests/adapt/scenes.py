"""Scenes the adapt tests build: a house, its world, an episode, the expert's trajectory and F's analysis."""

from __future__ import annotations

import numpy as np

from adaptenv.adapt.analysis import analyze_trajectory
from adaptenv.agents.policy import ExpertPolicy
from adaptenv.agents.rollout import draw_episode, rollout
from adaptenv.scene.procedural import GenerationConfig, generate_house
from adaptenv.sim.world import compile_world


def procedural_scene(house_seed: int, n_rooms: int, episode_key: list[int]) -> tuple:
    """(house, world, episode, expert trajectory, analysis) for a procedural house and an episode of >= 2.5 m."""
    house = generate_house(house_seed, GenerationConfig(n_rooms=n_rooms))
    world = compile_world(house, "h")
    ep = draw_episode(world, np.random.default_rng(episode_key))
    traj = rollout(world, ep, ExpertPolicy())
    return house, world, ep, traj, analyze_trajectory(traj, world)
