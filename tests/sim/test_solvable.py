"""Solvable means reachable by the agent: the expert succeeds on every episode the sampler calls solvable."""

from __future__ import annotations

import pytest

from adaptenv.agents.evaluate import run_episodes, sample_episodes
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.policy import ExpertPolicy
from adaptenv.sim.geodesic import is_solvable
from tests.conftest import REAL_HOUSE


@pytest.mark.parametrize(("spec", "episodes"), [("preset:tiny", 30), (str(REAL_HOUSE), 30)])
def test_expert_solves_every_sampled_solvable_episode(spec, episodes):
    worlds = load_house_set(spec).worlds
    eps = sample_episodes(worlds, episodes, seed=11)
    assert all(is_solvable(worlds[e], ep) for e, ep in eps)
    results, _ = run_episodes(worlds, eps, ExpertPolicy())
    failed = [(r.house, r.target_type, r.seed) for r in results if not r.success]
    assert not failed
