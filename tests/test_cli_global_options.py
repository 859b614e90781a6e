"""Global options (``--assets``) work before the command and after it, with the same result."""

from __future__ import annotations

import json

import typer.main
from typer.testing import CliRunner

from adaptenv.cli import app
from adaptenv.scene.assets import ASSETS_ENV, use_assets
from adaptenv.scene.house import save_house
from tests.sim import helpers as H

SOFA = "0a1b2c3d4e5f4a5b8c9d0e1f2a3b4c5d"


def test_assets_before_or_after_the_command_give_the_same_result(tmp_path, monkeypatch):
    table = tmp_path / "my_assets.json"
    table.write_text(json.dumps({"assets": {SOFA: {"type": "Sofa", "size": [2.0, 0.9, 0.9]}}}), encoding="utf-8")
    monkeypatch.setenv(ASSETS_ENV, "")
    use_assets(table)
    house = save_house(H.two_rooms(objects=[H.Obj(SOFA, 2.0, 0.6)], agent=(2.0, 2.0, 0.0)), tmp_path / "house.json")
    runner = CliRunner()
    outputs = {}
    for where, args in [("none", ["validate", str(house)]),
                        ("before", ["--assets", str(table), "validate", str(house)]),
                        ("after", ["validate", str(house), "--assets", str(table)])]:
        monkeypatch.setenv(ASSETS_ENV, "")  # each run starts without the table
        outputs[where] = runner.invoke(app, args)
    assert outputs["none"].exit_code == 1 and "pass --assets FILE" in outputs["none"].output
    assert outputs["before"].exit_code == outputs["after"].exit_code == 0
    assert outputs["before"].output == outputs["after"].output
    images = {}
    for where, args in [("before", ["--assets", str(table), "render", str(house)]),
                        ("after", ["render", str(house), "--assets", str(table)])]:
        monkeypatch.setenv(ASSETS_ENV, "")
        res = runner.invoke(app, [*args, "-o", str(tmp_path / f"{where}.png"), "--size", "256"])
        assert res.exit_code == 0, res.output
        images[where] = (tmp_path / f"{where}.png").read_bytes()
    assert images["before"] == images["after"]


def test_every_command_takes_the_global_options():
    def leaves(cmd):
        subs = getattr(cmd, "commands", None)
        return [c for s in subs.values() for c in leaves(s)] if subs is not None else [cmd]

    commands = leaves(typer.main.get_command(app))
    assert len(commands) > 20
    assert all(any(p.name == "assets" for p in c.params) for c in commands)
    assert all(any(p.name == "skip_unknown_assets" for p in c.params) for c in commands)


def test_loop_options_default_to_the_loop_configs_defaults():
    """`adaptenv loop` and an experiment config that names nothing fine-tune alike: the recipe that made pretrained."""
    from dataclasses import fields

    from adaptenv.curriculum.loop import LoopConfig

    loop = typer.main.get_command(app).commands["loop"]
    options = {p.name: p.default for p in loop.params}
    shared = [f for f in fields(LoopConfig) if f.name.startswith("finetune_") and f.name in options]
    assert len(shared) >= 12
    for f in shared:
        assert options[f.name] == f.default, f.name
    assert (LoopConfig.finetune_algo, LoopConfig.finetune_max_steps, LoopConfig.policy) == ("ppo", 600, "pretrained")
