"""Difficulty on request in the closed loop: the config fields are checked before any work, an experiment gives
them to its adapting methods only, and a generation job edits toward the target."""

from __future__ import annotations

import pytest

from adaptenv.curriculum.experiment import ExperimentConfig
from adaptenv.curriculum.loop import LoopConfig
from adaptenv.curriculum.methods import ADAPTING_METHODS
from adaptenv.errors import ConfigError


def test_adapting_methods_are_those_with_g():
    assert {"ours", "ours-noselect", "ours-llm"} <= set(ADAPTING_METHODS)
    assert not {"none", "random", "dr", "accel", "plr", "sfl"} & set(ADAPTING_METHODS)


@pytest.mark.parametrize(("fields", "says"), [
    ({"target_success": 1.0}, "target_success 1.0: the target success rate must lie strictly between 0 and 1"),
    ({"target_success": -0.5}, "strictly between 0 and 1"),
    ({"target_success": 0.5, "target_tolerance": 1.5}, "target_tolerance 1.5"),
    ({"target_success": 0.5, "target_episodes": 0}, "target_episodes must be at least 1"),
    ({"target_success": 0.5, "target_choices": 0}, "target_choices must be a whole number from 1 to 64"),
    ({"target_success": 0.5, "target_draws": 17}, "target_draws must be a whole number from 1 to 16"),
    ({"target_success": 0.5, "target_stop_gap": 0.2}, "target_stop_gap 0.2: editing must stop within the tolerance"),
    ({"target_success": 0.5, "method": "dr"}, "target_success applies to the methods that adapt scenes"),
    ({"target_success": "half"}, "target_success"),
])
def test_loop_config_refuses_a_bad_target_in_one_line(fields, says):
    with pytest.raises(ConfigError) as err:
        LoopConfig(**fields).check("run.json")
    assert says in str(err.value) and str(err.value).startswith("run.json") and "\n" not in str(err.value)


def test_loop_config_takes_a_target_and_off_is_the_default():
    assert LoopConfig().target_success is None
    assert LoopConfig(target_success=0.25, target_tolerance=0.05, target_episodes=10).check().target_success == 0.25


def test_an_experiment_gives_the_target_to_its_adapting_methods_only():
    cfg = ExperimentConfig(methods=["none", "dr", "ours"], seeds=[0],
                           loop={"target_success": 0.5, "target_episodes": 8, "target_choices": 3,
                                 "target_draws": 2, "target_stop_gap": 0.05}).check()
    assert cfg.loop_config("ours", 0).target_success == 0.5 and cfg.loop_config("ours", 0).target_episodes == 8
    assert cfg.loop_config("ours", 0).target_choices == 3 and cfg.loop_config("ours", 0).target_draws == 2
    assert cfg.loop_config("ours", 0).target_stop_gap == 0.05
    assert cfg.loop_config("dr", 0).target_success is None and cfg.loop_config("none", 0).target_episodes == 20
    with pytest.raises(ConfigError, match="target_success"):
        ExperimentConfig(methods=["ours"], seeds=[0], loop={"target_success": 2.0}).check("exp.json")


@pytest.mark.slow
def test_a_generation_job_edits_toward_the_target():
    from adaptenv.agents.houses import load_house_set
    from adaptenv.agents.registry import load_pretrained
    from adaptenv.curriculum.jobs import GenerateJob, PolicyWeights, run_generate
    from adaptenv.report.data import parse_edits

    hs = load_house_set("preset:tiny")
    house = hs.houses[hs.names.index("tiny_0002")]
    weights = PolicyWeights.of(load_pretrained("pretrained-scan"))
    made = run_generate(GenerateJob("builtin", house, "tiny", 1, (0, 1, 7), weights=weights, target_success=0.5,
                                    target_tolerance=0.1, target_episodes=4, target_choices=2, target_draws=2))
    t = made.edit_log["target_success"]
    assert t["target"] == 0.5 and t["episodes"] == 4 and t["draws"] == 2 and made.edits == t["edits"] <= 1
    assert t["rounds"] <= t["proposed"] <= 2 * t["rounds"]  # two edits proposed per round
    assert made.success_before == t["success_before"] and made.success_after == t["success"]
    assert made.regret_before is not None and made.regret_after is not None and made.rollout_steps > 0
    assert abs(made.success_after - 0.5) <= abs(made.success_before - 0.5) + 1e-9  # never farther than it began
    generator, rows = parse_edits(made.edit_log)  # the report reads the rounds as a generator's steps
    assert generator == "builtin" and len(rows) == t["proposed"]
