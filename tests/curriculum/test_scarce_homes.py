"""The scarce-homes setting: a loop from fresh weights, ``swap`` of the homes, levels grounded in the homes."""

from __future__ import annotations

import pytest
import torch

from adaptenv.curriculum import buffer as lb
from adaptenv.curriculum import methods as M
from adaptenv.curriculum.executor import InProcessExecutor
from adaptenv.curriculum.loop import LoopConfig, LoopState, run_loop
from adaptenv.scene.procedural import generate_preset, preset_spec
from adaptenv.scene.procedural.variations import vary_house


class _Store:
    def __init__(self):
        self.houses = {}

    def put(self, name, house, focus=()):
        self.houses[name] = house
        return name

    def house(self, name):
        return self.houses[name]


def _iteration(**cfg) -> M.Iteration:
    homes = generate_preset("tiny")
    store = _Store()
    for name, house in homes:
        store.put(name, house)
    return M.Iteration(t=1, cfg=LoopConfig(seed=0, scenes_per_iteration=2, edit_steps=1, **cfg),
                       state=LoopState(pool=[n for n, _ in homes]), store=store, buffer=lb.empty_state(),
                       buffer_cfg=lb.LevelBufferConfig(capacity=8, min_fill=0.0, replay_prob=1.0).check(),
                       weights=None, executor=InProcessExecutor(), run_dir=None)


def test_swap_trains_on_variations_of_the_homes_from_the_runs_own_stream():
    it = _iteration()
    homes = dict(it.store.houses)
    names = M.METHODS["swap"]().scenes_to_roll_out(it)
    assert names == ["tiny_0000~sw0000", "tiny_0001~sw0001"] and it.state.generated == 2
    for n, name in enumerate(names):
        home = homes[name.split("~")[0]]
        seed = it.seed(M.Stream.SWAP, n) % 2**31
        assert it.store.houses[name].to_dict() == vary_house(home, seed, preset_spec("pretrain-swapped").config()).to_dict()
        assert it.store.houses[name].to_dict() != home.to_dict(), "other assets or materials"
    assert M.METHODS["swap"]().make_scenes(it, names, []) == names  # trained on, as dr trains on its houses


@pytest.mark.parametrize("method", ["plr", "accel", "sfl", "ours"])
def test_grounded_methods_take_their_new_levels_from_the_homes(method):
    it = _iteration(grounded=True, seed_buffer=False, appearance_edits=True)
    pool = list(it.state.pool)
    names = M.METHODS[method]().scenes_to_roll_out(it)
    want = it.cfg.scenes_per_iteration * (it.cfg.sfl_candidates if method == "sfl" else 1)
    assert len(names) == want and all("~g" in n for n in names)
    assert all(it.parents[n] in pool for n in names), "every level is an edit of a home"
    assert [it.parents[n] for n in names] == [pool[k % len(pool)] for k in range(want)], "round robin"
    again = _iteration(grounded=True, seed_buffer=False, appearance_edits=True)
    assert [again.store.house(n).to_dict() for n in M.METHODS[method]().scenes_to_roll_out(again)] == \
        [it.store.house(n).to_dict() for n in names], "the same levels from the same seed"


def test_without_grounded_the_same_methods_draw_fresh_houses_and_dr_always_does():
    it = _iteration(seed_buffer=False)
    assert all(n.startswith("dr") for n in M.METHODS["plr"]().scenes_to_roll_out(it))
    grounded = _iteration(grounded=True)
    assert all(n.startswith("dr") for n in M.METHODS["dr"]().scenes_to_roll_out(grounded)), "the upper bound"


def test_a_loop_learns_from_scratch_in_the_recognising_mode(tmp_path):
    cfg = LoopConfig(method="swap", policy="scratch-shape", houses="preset:tiny", heldout={"tiny": "preset:tiny"},
                     iterations=1, scenes_per_iteration=1, finetune_frames=256, finetune_envs=8,
                     finetune_teacher="map-explorer", finetune_max_steps=600, finetune_lr=1e-3, heldout_episodes=2,
                     gallery=0, seed=3)
    records = run_loop(cfg, tmp_path / "run")
    from adaptenv.agents.checkpoint import load_checkpoint
    from adaptenv.agents.registry import resolve_policy

    pi0, pi1 = (load_checkpoint(tmp_path / "run" / f"iter_{t:04d}" / "policy.pt").net for t in (0, 1))
    assert pi0.config.perception == "shape" and pi1.config.perception == "shape" and pi0.config.map_channels
    fresh = resolve_policy("scratch-shape", seed=3).net
    assert all(torch.equal(a, b) for a, b in zip(pi0.state_dict().values(), fresh.state_dict().values(), strict=True))
    assert any(not torch.equal(a, b) for a, b in zip(pi0.state_dict().values(), pi1.state_dict().values(), strict=True))
    assert records[-1].grad_updates > 0 and records[-1].env_steps >= 256
