"""The scarce-homes setting: a loop from fresh weights, ``swap`` of the homes, levels grounded in the homes."""

from __future__ import annotations

import pytest
import torch

from adaptenv.curriculum import buffer as lb
from adaptenv.curriculum import methods as M
from adaptenv.curriculum.executor import InProcessExecutor
from adaptenv.curriculum.loop import LoopConfig, LoopState
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


def test_the_loops_fine_tuning_learns_a_scratch_network_in_the_recognising_mode():
    """What run_loop does with ``policy: scratch-shape``: resolve pi_0 from the seed, fine-tune it by DAgger from the
    map explorer with the loop's recipe; the network keeps its map and its perception."""
    from adaptenv.agents.houses import load_house_set
    from adaptenv.agents.registry import resolve_policy
    from adaptenv.agents.train import finetune
    from adaptenv.curriculum.loop import finetune_config

    # two collections of 8 x 32 frames: the learning rate is annealed to zero at the end of an iteration's frames
    cfg = LoopConfig(policy="scratch-shape", finetune_frames=512, finetune_envs=8, finetune_teacher="map-explorer",
                     finetune_lr=1e-3, finetune_max_steps=600, seed=3)
    pi0 = resolve_policy(cfg.policy, seed=cfg.seed)
    tuned = finetune(pi0.net, load_house_set("preset:tiny").worlds[:1], finetune_config(cfg, pi0.end_threshold), seed=0)
    assert tuned.net.config == pi0.net.config and tuned.net.config.perception == "shape" and tuned.net.config.map_channels
    assert any(not torch.equal(a, b) for a, b in zip(pi0.net.state_dict().values(), tuned.net.state_dict().values(),
                                                     strict=True))
    assert tuned.card["frames"] >= 512 and tuned.card["updates"] > 0
