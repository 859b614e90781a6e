"""The memory-wipe check: WipeMemory wipes at exactly K, 2K, ...; memory_check and ``adaptenv memory-check``."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from adaptenv.agents.evaluate import run_episodes, sample_episodes
from adaptenv.agents.memory import WipeMemory, memory_check
from adaptenv.agents.network import NavNet, NetConfig, NeuralPolicy
from adaptenv.agents.policy import ExpertPolicy
from adaptenv.cli import app
from adaptenv.errors import ConfigError


class SpyPolicy:
    """State: steps since each agent's episode start; ``forget`` records (agent, step) and changes nothing."""

    name = "spy"

    def __init__(self) -> None:
        self.wiped: list[tuple[int, int]] = []

    def initial_state(self, batch: int) -> np.ndarray:
        return np.zeros(batch, dtype=np.int64)

    def forget(self, state: np.ndarray, indices: np.ndarray) -> np.ndarray:
        self.wiped += [(int(i), int(state[i])) for i in indices]
        return state

    def act(self, obs, state: np.ndarray, done: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        state = np.where(done, 0, state)
        return np.zeros(len(done), dtype=np.int64), state + 1


class CounterPolicy:
    """No ``forget``: the state (an array or tensor, one row per agent) counts steps since the last reset."""

    name = "counter"

    def __init__(self, tensor: bool) -> None:
        self.tensor = tensor
        self.seen: list[np.ndarray] = []

    def initial_state(self, batch: int):
        return torch.zeros(batch, 2) if self.tensor else np.zeros((batch, 2))

    def act(self, obs, state, done: np.ndarray):
        state = state.clone() if self.tensor else state.copy()
        state[torch.as_tensor(done) if self.tensor else done] = 0
        self.seen.append(np.asarray(state[:, 0]).copy())
        return np.zeros(len(done), dtype=np.int64), state + 1


def drive(policy, lengths: list[list[int]]) -> None:
    """Run ``policy`` on agents whose episodes have the given lengths (agent i plays lengths[i] back to back)."""
    starts = [set(np.cumsum([0, *ls[:-1]]).tolist()) for ls in lengths]
    state = policy.initial_state(len(lengths))
    for t in range(max(sum(ls) for ls in lengths)):
        done = np.array([t in s for s in starts])
        _, state = policy.act({}, state, done)


def test_wipes_at_exactly_k_2k_of_each_episode():
    lengths = [[7, 12, 5], [24], [3, 3, 3, 3, 3, 3, 3, 3]]
    spy = SpyPolicy()
    drive(WipeMemory(spy, every=4), lengths)
    expected = sorted((i, s) for i, ls in enumerate(lengths) for n in ls for s in range(4, n, 4))
    assert sorted(spy.wiped) == expected  # agent 0: 4 (first), 4, 8 (second), 4 (third); agent 2: never
    spy = SpyPolicy()
    drive(WipeMemory(spy, every=0), lengths)
    assert spy.wiped == []


@pytest.mark.parametrize("tensor", [False, True])
def test_array_and_tensor_states_get_their_rows_zeroed(tensor):
    counter = CounterPolicy(tensor)
    drive(WipeMemory(counter, every=3), [[10], [4, 6]])
    steps = np.array([list(range(10)), [*range(4), *range(6)]]).T
    assert np.array_equal(np.stack(counter.seen), steps % 3)  # the count restarts at every wipe and episode


def test_every_zero_or_beyond_the_episode_acts_like_the_policy(tiny_set):
    torch.manual_seed(3)
    net = NavNet(NetConfig(hidden=32, feature_dim=32, conv_channels=8))
    eps = sample_episodes(tiny_set.worlds, 5, seed=4)

    def actions(wrap):
        policy = NeuralPolicy(net, seed=7)  # samples motions: per-episode generators only when bound
        _, recs = run_episodes(tiny_set.worlds, eps, wrap(policy), batch=3, max_steps=50, record=lambda r: True)
        return [recs[k].actions for k in sorted(recs)]

    plain = actions(lambda p: p)
    assert actions(lambda p: WipeMemory(p, 0)) == plain
    assert actions(lambda p: WipeMemory(p, 51)) == plain
    assert actions(lambda p: WipeMemory(p, 5)) != plain


def test_scan_only_policy_fails_when_wiped_every_step(tiny_set):
    """Measured: 1.0 never wiped, 0.0 wiped every step (it never becomes confident enough to end)."""
    result = memory_check("pretrained-scan", tiny_set, episodes=6, every=[1], seed=0, batch=6, max_steps=150)
    never, every_step = result["runs"]
    assert [never["every"], every_step["every"]] == [0, 1]
    assert never["success"] >= 0.5 and every_step["success"] == 0.0
    assert every_step["success_diff"]["diff"] == -never["success"]


def test_runs_are_paired_so_a_wipe_that_never_fires_changes_nothing(tiny_set):
    result = memory_check("pretrained", tiny_set, episodes=4, every=[1000], seed=1, batch=2, max_steps=80)
    never, late = result["runs"]
    assert late["success"] == never["success"] and late["spl"] == never["spl"]
    assert late["success_diff"] == {"diff": 0.0, "se": 0.0, "ci95": [0.0, 0.0]}


def test_a_policy_whose_memory_cannot_be_wiped_is_a_config_error(tiny_set):
    with pytest.raises(ConfigError, match=r"expert policy.*forget\(state, indices\)"):
        WipeMemory(ExpertPolicy(), 8).initial_state(2)
    WipeMemory(ExpertPolicy(), 0).initial_state(2)  # never wiping needs nothing
    res = CliRunner().invoke(app, ["evaluate", "--policy", "expert", "--houses", "preset:tiny", "--wipe-every", "8"])
    assert isinstance(res.exception, ConfigError) and str(res.exception).startswith("--wipe-every: the expert policy")
    res = CliRunner().invoke(app, ["memory-check", "--policy", "expert", "--houses", "preset:tiny", "-n", "2"])
    assert isinstance(res.exception, ConfigError) and str(res.exception).startswith("--policy expert:")
    res = CliRunner().invoke(app, ["memory-check", "--houses", "preset:tiny", "--every", "-2"])
    assert isinstance(res.exception, ConfigError) and str(res.exception).startswith("--every -2:")


def test_cli_memory_check_prints_the_table_and_writes_json(tmp_path):
    res = CliRunner().invoke(app, ["memory-check", "--policy", "pretrained", "--houses", "preset:tiny", "-n", "3",
                                   "--every", "4", "--every", "2", "-o", str(tmp_path)], env={"COLUMNS": "120"})
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "memory_check.json").read_text())
    assert [r["every"] for r in doc["runs"]] == [0, 4, 2]
    assert doc["episodes"] == 3 and doc["command"].startswith("adaptenv memory-check --policy pretrained")
    assert all(r["episodes"] == 3 and "ci95" in r["success_diff"] for r in doc["runs"])
    assert "never" in res.output and "vs never (95%)" in res.output


def test_cli_evaluate_records_the_wipe(tmp_path):
    res = CliRunner().invoke(app, ["evaluate", "--policy", "pretrained", "--houses", "preset:tiny", "-n", "2",
                                   "--wipe-every", "16", "-o", str(tmp_path)])
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["wipe_every"] == 16 and "--wipe-every 16" in summary["command"]


def test_workers_give_the_same_rows(tiny_set):
    """Workers resolve the spec with the run's seed and wrap it themselves: the same numbers as one process."""
    one = memory_check("pretrained", tiny_set, episodes=4, every=[4], seed=3, workers=1, batch=2, max_steps=60)
    two = memory_check("pretrained", tiny_set, episodes=4, every=[4], seed=3, workers=2, batch=2, max_steps=60)
    assert one["runs"] == two["runs"]
