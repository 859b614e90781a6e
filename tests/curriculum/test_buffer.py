"""The PLR-robust / ACCEL level buffer: insertion, hand-worked replay probabilities, replay semantics, ACCEL."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adaptenv.curriculum.buffer import (
    LevelBufferConfig,
    LevelBufferState,
    can_replay,
    dropped_ids,
    empty_state,
    insert,
    insert_children,
    level_id_problem,
    rank_weights,
    regret_score,
    replay_distribution,
    sample_replay,
    select_parents,
    should_replay,
    spl_regret,
    success_regret,
    update_scores,
)
from adaptenv.errors import ConfigError


def filled(cfg: LevelBufferConfig, scores: list[float], t0: int = 0) -> LevelBufferState:
    """A buffer holding levels L0, L1, ... with the given scores, inserted at t0, t0+1, ..."""
    state = empty_state()
    for i, s in enumerate(scores):
        state = insert(state, cfg, f"L{i}", s, t0 + i)
    return state


# --------------------------------------------------------------------------- insertion


def test_insert_appends_until_full_then_replaces_the_lowest_score_only_if_higher():
    cfg = LevelBufferConfig(capacity=3)
    state = filled(cfg, [0.5, 0.1, 0.9])
    assert state.level_ids == ("L0", "L1", "L2") and state.size == 3 and state.n_inserted == 3

    lower = insert(state, cfg, "new-low", 0.05, t=10)
    assert lower == state  # not higher than the minimum (0.1): unchanged

    equal = insert(state, cfg, "new-eq", 0.1, t=10)
    assert equal == state  # ties do not evict

    higher = insert(state, cfg, "new", 0.3, t=10, parent_id="L2")
    assert higher.level_ids == ("L0", "new", "L2")  # took the slot of L1, the lowest score
    assert higher.scores == (0.5, 0.3, 0.9)
    assert higher.last_seen == (0, 10, 2)
    assert higher.parent_ids == (None, "L2", None)
    assert higher.n_inserted == 4
    assert dropped_ids(state, higher) == ["L1"]
    assert state.level_ids == ("L0", "L1", "L2")  # the input state is not mutated


def test_insert_evicts_the_stalest_among_equal_lowest_scores():
    cfg = LevelBufferConfig(capacity=3)
    state = filled(cfg, [0.2, 0.7, 0.2])
    state = update_scores(state, [0], [0.2], t=5)  # L0 seen recently, L2 last seen at t=2
    out = insert(state, cfg, "new", 0.4, t=6)
    assert out.level_ids == ("L0", "L1", "new")


def test_inserting_a_known_level_updates_it_instead_of_duplicating():
    cfg = LevelBufferConfig(capacity=3)
    state = filled(cfg, [0.5, 0.1])
    out = insert(state, cfg, "L1", 0.8, t=9)
    assert out.level_ids == ("L0", "L1") and out.scores == (0.5, 0.8) and out.last_seen == (0, 9)
    assert out.n_inserted == 2


def test_update_scores_sets_scores_and_last_seen_of_the_given_slots():
    cfg = LevelBufferConfig(capacity=4)
    state = filled(cfg, [0.1, 0.2, 0.3])
    out = update_scores(state, [2, 0], [0.9, 0.0], t=7)
    assert out.scores == (0.0, 0.2, 0.9) and out.last_seen == (7, 1, 7)
    with pytest.raises(IndexError):
        update_scores(state, [3], [0.5], t=7)
    with pytest.raises(ValueError, match="finite"):
        update_scores(state, [0], [float("nan")], t=7)


# --------------------------------------------------------------------------- replay distribution


def test_rank_and_staleness_probabilities_match_a_hand_worked_example():
    # scores 0.2, 0.8, 0.5 -> ranks 3, 1, 2. With T = 0.5, h = (1/rank)^2 = 1/9, 1, 1/4;
    # their sum is 49/36, so P_rank = 4/49, 36/49, 9/49.
    # last_seen 0, 5, 8 at t = 10 -> staleness 10, 5, 2 (sum 17), so P_stale = 10/17, 5/17, 2/17.
    # With staleness_coef 0.4: P = 0.6 * P_rank + 0.4 * P_stale.
    cfg = LevelBufferConfig(capacity=3, temperature=0.5, staleness_coef=0.4)
    state = LevelBufferState(level_ids=("a", "b", "c"), scores=(0.2, 0.8, 0.5), last_seen=(0, 5, 8),
                             parent_ids=(None, None, None), n_inserted=3)
    expected = [0.6 * 4 / 49 + 0.4 * 10 / 17,   # 0.0489796 + 0.2352941 = 0.2842737
                0.6 * 36 / 49 + 0.4 * 5 / 17,   # 0.4408163 + 0.1176471 = 0.5584634
                0.6 * 9 / 49 + 0.4 * 2 / 17]    # 0.1102041 + 0.0470588 = 0.1572629
    p = replay_distribution(state, cfg, t=10)
    np.testing.assert_allclose(p, expected, rtol=1e-12)
    np.testing.assert_allclose(p, [0.2842737, 0.5584634, 0.1572629], atol=1e-7)


def test_rank_weights_at_the_default_temperature_and_with_ties():
    # T = 0.3: h = rank^(-10/3): rank 1 -> 1, rank 2 -> 2^(-10/3) = 0.0992126, rank 3 -> 3^(-10/3) = 0.0256800.
    h = np.array([1.0, 0.0992126, 0.0256800])
    np.testing.assert_allclose(rank_weights(np.array([3.0, 2.0, 1.0]), 0.3), h / h.sum(), rtol=1e-5)
    # Equal scores share the best rank: scores 5, 5, 1 -> ranks 1, 1, 3.
    h = np.array([1.0, 1.0, 3.0 ** (-1 / 0.3)])
    np.testing.assert_allclose(rank_weights(np.array([5.0, 5.0, 1.0]), 0.3), h / h.sum(), rtol=1e-12)


def test_staleness_is_uniform_when_every_level_was_just_seen_and_t_cannot_go_back():
    cfg = LevelBufferConfig(capacity=2, temperature=1.0, staleness_coef=1.0)
    state = LevelBufferState(level_ids=("a", "b"), scores=(1.0, 0.0), last_seen=(4, 4), parent_ids=(None, None),
                             n_inserted=2)
    np.testing.assert_allclose(replay_distribution(state, cfg, t=4), [0.5, 0.5])
    with pytest.raises(ValueError, match="earlier"):
        replay_distribution(state, cfg, t=3)


@settings(max_examples=200, deadline=None)
@given(scores=st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=1, max_size=60),
       data=st.data(),
       temperature=st.floats(0.01, 5.0),
       staleness_coef=st.floats(0.0, 1.0))
def test_replay_probabilities_are_a_distribution_for_any_buffer(scores, data, temperature, staleness_coef):
    n = len(scores)
    last_seen = data.draw(st.lists(st.integers(0, 10**6), min_size=n, max_size=n))
    t = data.draw(st.integers(max(last_seen), 2 * 10**6))
    state = LevelBufferState(level_ids=tuple(f"L{i}" for i in range(n)), scores=tuple(scores),
                             last_seen=tuple(last_seen), parent_ids=(None,) * n, n_inserted=n)
    cfg = LevelBufferConfig(capacity=max(n, 1), temperature=temperature, staleness_coef=staleness_coef)
    p = replay_distribution(state, cfg, t)
    assert p.shape == (n,)
    assert np.all(np.isfinite(p)) and np.all(p >= 0)
    assert abs(p.sum() - 1.0) < 1e-9
    # The best-scored level is never less likely than the worst under pure rank prioritisation.
    rank_only = replay_distribution(state, dataclasses.replace(cfg, staleness_coef=0.0), t)
    assert rank_only[int(np.argmax(scores))] >= rank_only[int(np.argmin(scores))]


# --------------------------------------------------------------------------- replay semantics


def test_replay_only_after_the_minimum_fill():
    cfg = LevelBufferConfig(capacity=10, replay_prob=1.0, min_fill=0.5)
    rng = np.random.default_rng(0)
    state = empty_state()
    for i in range(4):
        state = insert(state, cfg, f"L{i}", 0.1 * i, i)
        assert not can_replay(state, cfg)
        assert not any(should_replay(state, cfg, rng) for _ in range(50))
    state = insert(state, cfg, "L4", 0.5, 4)  # 5 of 10 = half full
    assert can_replay(state, cfg)
    assert all(should_replay(state, cfg, rng) for _ in range(50))


def test_should_replay_uses_the_replay_probability():
    cfg = LevelBufferConfig(capacity=2, replay_prob=0.7, min_fill=0.5)
    state = filled(cfg, [0.1, 0.2])
    rng = np.random.default_rng(1)
    rate = np.mean([should_replay(state, cfg, rng) for _ in range(4000)])
    assert 0.67 < rate < 0.73


def test_sample_replay_returns_buffer_levels_only_and_follows_the_distribution():
    cfg = LevelBufferConfig(capacity=3, temperature=0.5, staleness_coef=0.4)
    state = LevelBufferState(level_ids=("a", "b", "c"), scores=(0.2, 0.8, 0.5), last_seen=(0, 5, 8),
                             parent_ids=(None, None, None), n_inserted=3)
    idxs = sample_replay(state, cfg, np.random.default_rng(2), t=10, k=20000)
    assert idxs.min() >= 0 and idxs.max() < state.size
    freq = np.bincount(idxs, minlength=3) / len(idxs)
    np.testing.assert_allclose(freq, replay_distribution(state, cfg, 10), atol=0.015)


def test_replay_never_falls_back_to_new_levels_after_the_first_episode():
    """minimax #6: in a long loop, every replay step (not only the first) draws levels from the buffer."""
    cfg = LevelBufferConfig(capacity=8, replay_prob=0.6, min_fill=0.5)
    rng = np.random.default_rng(3)
    state = empty_state()
    replay_steps, new_steps, next_new = [], [], 0
    for t in range(300):
        if should_replay(state, cfg, rng):
            held = set(state.level_ids)
            idxs = sample_replay(state, cfg, rng, t, k=4)
            assert {state.level_ids[i] for i in idxs} <= held
            state = update_scores(state, idxs, rng.random(len(idxs)).tolist(), t)
            assert set(state.level_ids) == held  # replay adds no level
            replay_steps.append(t)
        else:
            state = insert(state, cfg, f"new{next_new}", float(rng.random()), t)
            next_new += 1
            new_steps.append(t)
    assert replay_steps and replay_steps[0] >= cfg.min_size - 1
    assert len(replay_steps) > 150  # replay keeps happening long after the first episode
    assert replay_steps[-1] > 250
    assert 0.5 < len(replay_steps) / (300 - cfg.min_size) < 0.7


def test_sampling_and_parent_selection_are_deterministic_under_a_seed():
    cfg = LevelBufferConfig(capacity=16)
    state = filled(cfg, [0.05 * i for i in range(16)])

    def run(seed: int):
        rng = np.random.default_rng(seed)
        idxs = sample_replay(state, cfg, rng, t=20, k=8)
        return idxs.tolist(), select_parents(state, idxs, rng), should_replay(state, cfg, rng)

    assert run(7) == run(7)
    assert run(7) != run(8)


# --------------------------------------------------------------------------- ACCEL


def test_every_replayed_parent_gets_exactly_one_child_carrying_its_parent_id():
    """dcd #11: edits must go to every replayed level, not only the first one."""
    cfg = LevelBufferConfig(capacity=32)
    state = filled(cfg, [0.1 * (i % 7) for i in range(10)])
    idxs = np.array([3, 7, 1, 9, 7])  # k = 5 replayed slots, one level twice
    plans = select_parents(state, idxs, np.random.default_rng(4))
    assert len(plans) == len(idxs)
    assert [p.parent_slot for p in plans] == idxs.tolist()
    assert [p.parent_id for p in plans] == [state.level_ids[i] for i in idxs]
    assert len({p.child_id for p in plans}) == len(plans)  # distinct children, even for the repeated parent
    assert len({p.seed for p in plans}) == len(plans)

    child = insert_children(state, cfg, plans, [0.5] * len(plans), t=11)
    for p in plans:
        slot = child.index(p.child_id)
        assert slot is not None and child.parent_ids[slot] == p.parent_id
    assert child.size == state.size + len(plans)


def test_child_ids_do_not_grow_with_the_lineage_and_invalid_children_are_skipped():
    cfg = LevelBufferConfig(capacity=8)
    state = filled(cfg, [0.3])
    rng = np.random.default_rng(5)
    (first,) = select_parents(state, [0], rng)
    state = insert_children(state, cfg, [first], [0.4], t=2)
    (second,) = select_parents(state, [state.index(first.child_id)], rng)
    assert second.parent_id == first.child_id and second.child_id.count("~") == 1
    assert insert_children(state, cfg, [second], [None], t=3) == state


# --------------------------------------------------------------------------- serialization and config


def test_state_round_trips_through_json():
    cfg = LevelBufferConfig(capacity=4)
    state = filled(cfg, [0.25, -0.5, 1.0])
    state = insert(state, cfg, "child", 0.75, t=9, parent_id="L2")
    back = LevelBufferState.from_json(state.to_json())
    assert back == state and back.size == 4
    assert LevelBufferState.from_json(empty_state().to_json()) == empty_state()


def test_corrupt_state_json_names_the_field():
    text = '{"level_ids": ["a", "b"], "scores": [0.1], "last_seen": [0, 1], "parent_ids": [null, null], "n_inserted": 2}'
    with pytest.raises(ConfigError, match="scores has 1 entries"):
        LevelBufferState.from_json(text, source="ckpt/buffer.json")
    with pytest.raises(ConfigError, match="ckpt/buffer.json: bogus is not a known field"):
        LevelBufferState.from_json('{"bogus": 1}', source="ckpt/buffer.json")
    with pytest.raises(ConfigError, match="duplicate"):
        LevelBufferState.from_json('{"level_ids": ["a", "a"], "scores": [0, 0], "last_seen": [0, 0], '
                                   '"parent_ids": [null, null], "n_inserted": 2}')


@pytest.mark.parametrize("field,value", [("capacity", 0), ("temperature", 0.0), ("staleness_coef", 1.5),
                                         ("replay_prob", -0.1), ("min_fill", 2.0), ("score", "value_loss")])
def test_config_check_names_the_bad_field(field, value):
    with pytest.raises(ConfigError, match=field):
        dataclasses.replace(LevelBufferConfig(), **{field: value}).check()


# --------------------------------------------------------------------------- scores


def test_regret_scores_on_hand_worked_episodes():
    agent_success = [1, 0, 0, 1]
    agent_spl = [0.8, 0.0, 0.0, 0.5]
    expert_success = [1, 1, 0, 1]  # episode 3 is unsolvable for the expert
    # success regret: max(0, e - a) = 0, 1, 0, 0 -> 0.25
    assert success_regret(agent_success, expert_success) == pytest.approx(0.25)
    # 1 - SPL on solvable episodes: 0.2, 1.0, (0), 0.5 -> 1.7 / 4
    assert spl_regret(agent_spl, expert_success) == pytest.approx(0.425)
    assert regret_score(agent_success, agent_spl, expert_success) == pytest.approx(0.25)
    assert regret_score(agent_success, agent_spl, expert_success, "spl_regret") == pytest.approx(0.425)
    assert regret_score(agent_success, agent_spl, expert_success, "mixed") == pytest.approx(0.3375)
    # The agent succeeding where the expert fails is not negative regret.
    assert regret_score(1.0, 1.0, 0.0) == 0.0
    assert regret_score(0.0, 0.0, 1.0) == 1.0
    with pytest.raises(ValueError, match="kind"):
        regret_score(0.0, 0.0, 1.0, "bogus")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="episodes"):
        success_regret([1, 0], [1])


# --------------------------------------------------------------------------- level ids name only the run's own levels

@pytest.mark.parametrize("level_id", ["../../victim", "/tmp/victim", "a/b", "a\\b", "..", ".", "", "x\0y", "x" * 201])
def test_a_level_id_that_is_not_a_plain_name_is_refused_naming_it(level_id):
    assert level_id_problem(level_id) is not None
    data = {"level_ids": ["L0", level_id], "scores": [0.1, 0.2], "last_seen": [0, 1], "parent_ids": [None, None],
            "n_inserted": 2}
    with pytest.raises(ConfigError, match=r"^run/state.json: state.buffer: level id ") as err:
        LevelBufferState.from_dict(data, "run/state.json: state.buffer")
    assert repr(level_id) in str(err.value)
    parent = {**data, "level_ids": ["L0", "L1"], "parent_ids": [None, level_id]}  # a parent names a level too
    with pytest.raises(ConfigError, match="level id "):
        LevelBufferState.from_dict(parent)


def test_the_names_the_loop_gives_its_levels_are_plain():
    for name in ("house_00", "house_00~t01a00", "or0003", "dr0012", "procthor-10k-train-1~ra0001", "..x"):
        assert level_id_problem(name) is None, name
