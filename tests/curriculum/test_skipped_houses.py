"""The loop's run.json and the experiment's summary count the unusable houses their sets skipped."""

from __future__ import annotations

import json

import pytest

from adaptenv.curriculum.experiment import ExperimentConfig, run_experiment, summary_markdown
from adaptenv.curriculum.loop import LoopConfig, run_loop
from adaptenv.curriculum.records import RunInfo
from adaptenv.scene.house import save_house
from tests.sim import helpers as H


@pytest.fixture
def one_unusable(tmp_path):
    """A held-out folder with one usable house and one without any ObjectNav target."""
    d = tmp_path / "houses"
    save_house(H.corridor_house(), d / "a_good.json")
    save_house(H.one_room(), d / "b_no_target.json")
    return d


def loop_fields(policy, heldout) -> dict:
    return dict(policy=str(policy), houses="preset:tiny", heldout={"mixed": str(heldout)}, iterations=1,
                scenes_per_iteration=1, edit_steps=1, finetune_frames=256, finetune_envs=8, heldout_episodes=2,
                gallery=0, buffer_capacity=2, diagnose_episodes=1)


def test_loop_run_json_counts_skipped_houses(one_unusable, tiny_policy, tmp_path):
    records = run_loop(LoopConfig(method="none", **loop_fields(tiny_policy, one_unusable)), tmp_path / "run")
    assert records[-1].heldout["mixed"].episodes == 2
    info = RunInfo.model_validate_json((tmp_path / "run" / "run.json").read_text())
    assert set(info.skipped_houses) == {"preset:tiny", str(one_unusable)}
    assert info.skipped_houses["preset:tiny"].count == 0
    mixed = info.skipped_houses[str(one_unusable)]
    assert mixed.count == 1 and list(mixed.houses) == ["b_no_target"]
    assert "no ObjectNav target object" in mixed.houses["b_no_target"]


def test_experiment_summary_counts_skipped_houses(one_unusable, tiny_policy, tmp_path):
    cfg = ExperimentConfig(methods=["none"], seeds=[0], reference="none",
                           loop=loop_fields(tiny_policy, one_unusable))
    summary = run_experiment(cfg, tmp_path / "exp")
    doc = json.loads((tmp_path / "exp" / "summary.json").read_text())
    assert doc["skipped_houses"] == summary["skipped_houses"]
    assert doc["skipped_houses"][str(one_unusable)]["count"] == 1
    assert "b_no_target" in doc["skipped_houses"][str(one_unusable)]["houses"]
    assert doc["skipped_houses"]["preset:tiny"]["count"] == 0
    md = (tmp_path / "exp" / "summary.md").read_text()
    line = next(x for x in md.splitlines() if x.startswith("Skipped houses"))
    assert f"{one_unusable}: 1 (b_no_target)" in line and "preset:tiny" not in line
    nothing = {"methods": {}, "tests": {}, "reference": "none", "seeds": [0],
               "skipped_houses": {"preset:tiny": {"count": 0, "houses": {}}}}
    assert "Skipped houses: none" in summary_markdown(nothing)
