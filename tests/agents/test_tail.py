"""Tail success: the hardest 10% of houses chosen with one seed, scored with another."""

from __future__ import annotations

import numpy as np
import pytest

from adaptenv.agents.houses import load_house_set
from adaptenv.agents.policy import ExpertPolicy
from adaptenv.agents.tail import hardest, house_episodes, tail_success


def test_hardest_takes_lowest_success_then_lowest_spl_then_index():
    success = np.array([1.0, 0.2, 0.2, 0.9, 0.2, 1.0, 1.0, 1.0, 1.0, 1.0])
    spl = np.array([0.5, 0.3, 0.1, 0.4, 0.3, 0.5, 0.5, 0.5, 0.5, 0.5])
    assert hardest(success, spl, 0.1) == [2]
    assert hardest(success, spl, 0.3) == [2, 1, 4]
    assert hardest(success[:3], spl[:3], 0.1) == [2]  # at least one house


def test_house_episodes_depend_on_house_and_seed_only():
    worlds = load_house_set("preset:tiny").worlds
    a = house_episodes(worlds, [0, 2], 3, seed=0)
    b = house_episodes(worlds, [2], 3, seed=0)
    assert [e for e, _ in a] == [0, 0, 0, 2, 2, 2]
    assert [ep.start for _, ep in a[3:]] == [ep.start for _, ep in b]
    assert [ep.start for _, ep in house_episodes(worlds, [2], 3, seed=1)] != [ep.start for _, ep in b]


class _FailsIn:
    """The expert, except that it turns on the spot in one house (it never finds the target there)."""

    def __init__(self, house: int):
        self.house, self.expert = house, ExpertPolicy()

    def bind(self, context):
        self.context = context
        self.expert.bind(context)

    def initial_state(self, batch):
        return self.expert.initial_state(batch)

    def act(self, obs, state, done):
        actions, state = self.expert.act(obs, state, done)
        return np.where(self.context.env_idx == self.house, 2, actions), state


def test_tail_success_scores_the_hardest_house_on_new_draws():
    worlds = load_house_set("preset:tiny").worlds
    res = tail_success(_FailsIn(1), worlds, per_house=4, fraction=0.3, select_seed=0, score_seed=1, batch=12)
    assert res.tail_houses == (1,)
    assert res.tail_success == 0.0 and res.scoring_episodes == 4
    assert res.mean_success == pytest.approx(8 / 12)
    assert tail_success(ExpertPolicy(), worlds, per_house=2, fraction=0.3).tail_success == 1.0
    with pytest.raises(ValueError, match="differ"):
        tail_success(ExpertPolicy(), worlds, select_seed=3, score_seed=3)
