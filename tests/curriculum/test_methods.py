"""Curriculum methods as strategies: registry, named random streams, regret against the measured expert."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from adaptenv.agents.evaluate import EpisodeResult
from adaptenv.curriculum import methods as M
from adaptenv.curriculum.executor import InProcessExecutor
from adaptenv.curriculum.jobs import Rollout, needs_policy, run_generate, run_rollout
from adaptenv.curriculum.loop import LoopConfig, run_loop
from adaptenv.sim.task import Episode


def _result(success: bool, spl: float) -> EpisodeResult:
    return EpisodeResult(index=0, house="h", env=0, target_type="Bed", seed=0, success=success, spl=spl, sel=0.0,
                         steps=10, collisions=0, path_length=1.0, optimal=1.0, final_geodesic=0.0)


def _rollout(success: bool, spl: float, expert: bool) -> Rollout:
    return Rollout([Episode("Bed", (0.0, 0.0, 0.0), 0)], [_result(success, spl)], [None], [expert])


def _rollouts(successes: list[bool], experts: list[bool] | None = None, explorer: list[bool] | None = None) -> Rollout:
    n = len(successes)
    return Rollout([Episode("Bed", (0.0, 0.0, 0.0), k) for k in range(n)], [_result(s, 0.5 * s) for s in successes],
                   [None] * n, experts or [True] * n, explorer or [])


def test_every_method_is_registered_by_its_name():
    assert set(M.METHODS) == {"none", "random", "dr", "dr-matched", "sfl", "oracle", "rearrange", "swap", "plr", "accel",
                              "ours",
                              "ours-noselect",
                              "ours-randomscene", "ours-nof", "ours-dr", "ours-learned", "ours-llm"}
    assert all(cls.name == name for name, cls in M.METHODS.items())
    assert M.METHODS["ours"].generator == "failure-modes" and M.METHODS["ours-nof"].generator == "regret-only"
    assert M.METHODS["ours-noselect"].generator == "builtin" and M.METHODS["ours-llm"].generator == "llm"
    assert M.METHODS["ours-learned"].generator == "learned"
    assert M.METHODS["ours-randomscene"].uniform and not M.METHODS["ours"].uniform


def test_regret_uses_the_experts_measured_success():
    assert M.level_score(_rollout(False, 0.0, True)) == 1.0
    assert M.level_score(_rollout(False, 0.0, False)) == 0.0, "a level the expert fails is not prioritised"
    assert M.level_score(_rollout(True, 0.7, True)) == 0.0


def test_scores_average_every_rollout_of_a_scene():
    half = _rollouts([True, False, True, False])
    assert half.success_rate == 0.5 and half.steps == 40
    assert M.level_score(half, "learnability") == pytest.approx(0.25), "p(1-p) peaks at p = 0.5"
    assert M.level_score(_rollouts([True] * 4), "learnability") == 0.0, "always solved: nothing to learn"
    assert M.level_score(_rollouts([False] * 4), "learnability") == 0.0, "never solved: nothing to learn"
    assert M.level_score(_rollouts([True, False, False, False]), "learnability") == pytest.approx(0.1875)
    assert M.level_score(half, "regret") == pytest.approx(0.5)
    assert M.level_score(_rollouts([False] * 4, experts=[True, True, False, False]), "regret") == pytest.approx(0.5)
    assert M.level_score(_rollouts([False] * 4, explorer=[True, True, True, False]),
                         "explorer_regret") == pytest.approx(0.75)
    with pytest.raises(ValueError, match="explorer"):
        M.level_score(half, "explorer_regret")


def test_diagnosed_scenes_are_scored_by_the_same_rule():
    assert M.diagnosed_score(0.5, 0.1, "learnability") == 0.25
    assert M.diagnosed_score(0.5, 0.1, "regret") == 0.1
    assert M.diagnosed_score(None, None, "regret") == 0.0


class _Scored:
    """An Iteration stand-in for SFL's make_scenes: only the config is read."""

    def __init__(self, k: int) -> None:
        self.cfg = LoopConfig(scenes_per_iteration=k)


def test_sfl_keeps_the_most_learnable_scenes():
    rolled = ["a", "b", "c", "d", "e", "f"]
    rates = [[True] * 4, [True, False, True, False], [False] * 4, [True, True, True, False],
             [True, False, False, False], [True, False, True, False]]
    kept = M.SFL().make_scenes(_Scored(2), rolled, [_rollouts(r) for r in rates])
    assert kept == ["b", "f"], "the two scenes at p = 0.5, in rollout order"
    kept = M.SFL().make_scenes(_Scored(4), rolled, [_rollouts(r) for r in rates])
    assert kept == ["b", "d", "e", "f"], "then p = 0.25 and 0.75 (0.1875 each); solved and unsolved ones last"


def test_rollout_jobs_play_every_episode_and_the_first_is_the_old_one(tiny_policy):
    from adaptenv.agents.checkpoint import load_checkpoint
    from adaptenv.curriculum.jobs import PolicyWeights, RolloutJob
    from adaptenv.scene.procedural import generate_preset

    (name, house), *_ = generate_preset("tiny")
    weights = PolicyWeights.of(load_checkpoint(tiny_policy).policy())
    one = run_rollout(RolloutJob(weights, house, name, 123))
    four = run_rollout(RolloutJob(weights, house, name, 123, episodes=4, explorer=True))
    assert len(four.results) == len(four.expert_successes) == len(four.explorer_successes) == 4
    assert four.episode == one.episode and four.result.success == one.result.success
    assert len({(e.target_type, e.start) for e in four.episodes}) > 1, "different episodes, not one replayed"
    assert four.steps == sum(r.steps for r in four.results) >= one.steps


def test_streams_are_named_and_independent():
    cfg = LoopConfig(seed=3)
    it = M.Iteration(t=2, cfg=cfg, state=None, store=None, buffer=None, buffer_cfg=None, weights=None,
                     executor=None, run_dir=None)
    draws = {s: it.rng(s).random() for s in M.Stream}
    assert len(set(draws.values())) == len(M.Stream)
    assert it.rng(M.Stream.REPLAY).random() == draws[M.Stream.REPLAY]
    assert it.seed(M.Stream.FRESH_HOUSES, 0) != it.seed(M.Stream.FRESH_HOUSES, 1)


def _buffer_iteration(scores: list[float], t: int = 1) -> M.Iteration:
    from adaptenv.curriculum import buffer as lb

    cfg = LoopConfig(seed=0, scenes_per_iteration=2)
    bcfg = lb.LevelBufferConfig(capacity=16, min_fill=0.0, replay_prob=1.0).check()
    buf = lb.empty_state()
    for k, s in enumerate(scores):
        buf = lb.insert(buf, bcfg, f"s{k}", s, 0)
    return M.Iteration(t=t, cfg=cfg, state=None, store=None, buffer=buf, buffer_cfg=bcfg, weights=None,
                       executor=None, run_dir=None)


def test_ours_picks_high_regret_scenes_and_randomscene_picks_uniformly():
    scores = [0.0] * 8 + [1.0, 0.75]
    high, uniform = 0, 0
    for t in range(1, 201):
        it = _buffer_iteration(scores, t)
        picked = M.Ours()._pick(it, 2, M.Stream.REPLAY)
        assert len(set(picked)) == 2, "distinct scenes"
        high += sum(p in ("s8", "s9") for p in picked)
        uniform += sum(p in ("s8", "s9") for p in M.OursRandomScene()._pick(it, 2, M.Stream.REPLAY))
    assert high > 0.45 * 400 and uniform < 0.3 * 400 and high > 2 * uniform  # uniform expects 20%


class TrainOnRolled(M.Method):
    """A toy method for the test: fine-tune on exactly the scenes it rolled out."""

    name = "rolled-only"

    def train_on(self, it, rolled, new):
        return list(rolled)


@pytest.mark.slow
def test_a_new_method_is_one_class_and_one_registry_line(tiny_policy, tmp_path, monkeypatch):
    monkeypatch.setitem(M.METHODS, TrainOnRolled.name, TrainOnRolled)
    cfg = LoopConfig(method="rolled-only", policy=str(tiny_policy), houses="preset:tiny", heldout={"tiny": "preset:tiny"},
                     iterations=1, scenes_per_iteration=2, edit_steps=1, finetune_frames=512, finetune_envs=16,
                     heldout_episodes=2, gallery=0)
    records = run_loop(cfg, tmp_path / "run")
    scenes = json.loads((tmp_path / "run" / "iter_0001" / "scenes.json").read_text())
    assert scenes["trained_on"] == scenes["rolled_out"] and len(scenes["rolled_out"]) == 2
    assert records[1].grad_updates > 0 and np.isfinite(records[1].heldout["tiny"].success)


class RecordingExecutor(InProcessExecutor):
    """In process, keeping every (function, item) the loop sends."""

    def __init__(self) -> None:
        self.calls: list[tuple] = []

    def map(self, fn, items, *, desc=None):
        items = list(items)
        self.calls += [(fn, x) for x in items]
        return super().map(fn, items, desc=desc)


def test_only_generators_that_use_the_policy_get_it():
    assert not needs_policy("random")
    assert all(needs_policy(k) for k in ("builtin", "llm", "failure-modes", "regret-only"))


@pytest.mark.slow
def test_random_generate_jobs_carry_no_weights_and_make_the_same_child(tiny_policy, tmp_path):
    ex = RecordingExecutor()
    cfg = LoopConfig(method="random", policy=str(tiny_policy), houses="preset:tiny", heldout={"tiny": "preset:tiny"},
                     iterations=1, scenes_per_iteration=2, edit_steps=2, finetune_frames=512, finetune_envs=16,
                     heldout_episodes=2, gallery=1)
    run_loop(cfg, tmp_path / "run", executor=ex)
    jobs = [x for fn, x in ex.calls if fn is run_generate]
    assert len(jobs) == 2 and all(j.kind == "random" and j.weights is None and j.rollout is None for j in jobs)
    # pi_t would change nothing: the same job carrying the weights and rollout makes the identical child
    rollouts = [x for fn, x in ex.calls if fn is run_rollout]
    with_policy = dataclasses.replace(jobs[0], weights=rollouts[0].weights, rollout=run_rollout(rollouts[0]))
    a, b = run_generate(jobs[0]), run_generate(with_policy)
    assert a.edits > 0 and a.house.model_dump() == b.house.model_dump() and a.edit_log == b.edit_log


class _Store:
    """Keeps what a method stores, by name."""

    def __init__(self) -> None:
        self.houses: dict = {}

    def put(self, name, house):
        self.houses[name] = house
        return name

    def house(self, name):
        return self.houses[name]


def test_oracle_draws_fresh_houses_from_the_heldout_suites_generators():
    from adaptenv.curriculum.loop import LoopState
    from adaptenv.scene.procedural import generate_house, preset_spec

    it = M.Iteration(t=1, cfg=LoopConfig(seed=0), state=LoopState(), store=_Store(), buffer=None, buffer_cfg=None,
                     weights=None, executor=None, run_dir=None)
    names = M.fresh_houses(it, 2, oracle=True)
    large, clutter = (it.store.houses[n] for n in names)
    assert names == ["or0000", "or0001"] and it.state.generated == 2
    for n, (house, preset) in enumerate(((large, "suite-large"), (clutter, "suite-clutter"))):
        seed = it.seed(M.Stream.ORACLE_HOUSES, n) % 2**31
        assert house.to_dict() == generate_house(seed, preset_spec(preset).config()).to_dict()
        assert house.to_dict() != generate_house(seed).to_dict()
    assert 7 <= len(large.rooms) <= 10  # suite-large's room range
    dr = M.fresh_houses(it, 1)[0]
    assert dr == "dr0002" and len(it.store.houses[dr].rooms) <= 6  # plain DR keeps the default 2-6 rooms


def test_rearrange_rearranges_the_training_homes_with_seeds_no_suite_uses():
    from adaptenv.curriculum.loop import LoopState
    from adaptenv.scene.procedural import generate_preset, preset_spec, rearrange_house

    homes = generate_preset("tiny")
    store = _Store()
    for name, house in homes:
        store.put(name, house)
    state = LoopState(pool=[name for name, _ in homes])
    it = M.Iteration(t=2, cfg=LoopConfig(seed=0, scenes_per_iteration=2), state=state, store=store, buffer=None,
                     buffer_cfg=None, weights=None, executor=None, run_dir=None)
    names = M.METHODS["rearrange"]().scenes_to_roll_out(it)
    assert names == ["tiny_0002~ra0000", "tiny_0000~ra0001"], "round robin over the pool, as the other methods"
    assert it.state.generated == 2
    for n, (name, (home, house)) in enumerate(zip(names, (homes[2], homes[0]), strict=True)):
        moved = store.houses[name]
        seed = it.seed(M.Stream.REARRANGE, n) % 2**31
        assert moved.to_dict() == rearrange_house(house, seed, preset_spec("pretrain-rearranged").config()).to_dict()
        assert [r.id for r in moved.rooms] == [r.id for r in house.rooms], f"{home}: the same rooms"
        assert moved.to_dict() != house.to_dict(), f"{home}: its furniture moved"
