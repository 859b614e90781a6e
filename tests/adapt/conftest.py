"""Fixtures shared by the adapt tests."""

from __future__ import annotations

import pytest

from adaptenv.adapt.analysis import analyze_trajectory
from adaptenv.sim.rollout import expert_policy, run_episode
from adaptenv.sim.task import Episode
from adaptenv.sim.world import compile_world
from tests.sim import helpers as H


@pytest.fixture(scope="module")
def llm_scene():
    """The corridor house, its world, a GarbageCan episode, the expert's trajectory and F's analysis (LLM tests)."""
    house = H.corridor_house()
    world = compile_world(house, "corridor")
    ep = Episode("GarbageCan", (1.0, 0.5, 0.0))
    traj = run_episode(world, ep, expert_policy())
    return house, world, ep, traj, analyze_trajectory(traj, world)
