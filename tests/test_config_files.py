"""Config files (experiment, loop, LLM backend, level buffer state, asset tables) are typed: a wrong type or an
unknown key is one ConfigError naming the file and the field path, raised before any work or output folder."""

from __future__ import annotations

import json
import re
import sys
from dataclasses import asdict
from pathlib import Path

import pytest

from adaptenv.adapt.llm import load_llm_config
from adaptenv.cli import main
from adaptenv.curriculum.buffer import LevelBufferState
from adaptenv.curriculum.experiment import ExperimentConfig
from adaptenv.curriculum.loop import LoopConfig, run_loop
from adaptenv.errors import ConfigError
from adaptenv.scene.assets import ASSETS_ENV, read_asset_table

REPO = Path(__file__).resolve().parents[1]

#: (experiment config, the words its error must hold): each one loaded without complaint, or with a
#: traceback, before configs were typed.
BAD_EXPERIMENTS = [
    ({"seeds": "abc"}, 'seeds should be a JSON array, got "abc"'),
    ({"seeds": [0, "1"]}, r'seeds\[1\] should be a whole number, got "1"'),
    ({"loop": {"iterations": "three"}}, 'loop.iterations should be a whole number, got "three"'),
    ([1, 2], "should be a JSON object, got \\[1, 2\\]"),
    ({"sedes": [0]}, "sedes is not a known field; did you mean 'seeds'"),
    ({"loop": {"heldout": {"far": 3}}}, "loop.heldout.far should be a string, got 3"),
    ({"loop": {"focus_training": 1}}, "loop.focus_training should be true or false"),
    ({"loop": {"llm": {"timeout_s": "5"}}}, 'loop.llm.timeout_s should be a number, got "5"'),
    ({"loop": {"llm": {"modle": "m"}}}, "loop.llm.modle is not a known field; did you mean 'model'"),
    ({"seeds": [-1]}, "a seed is a whole number from 0 to"),
    ({"seeds": [1, 1]}, "seeds lists 1 twice"),
    ({"reference": "ourz"}, "reference 'ourz' is unknown"),
]


def write(path: Path, doc: object) -> Path:
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


@pytest.mark.parametrize("doc,words", BAD_EXPERIMENTS)
def test_experiment_config_types_are_checked_with_the_field_path(tmp_path, doc, words):
    path = write(tmp_path / "bad.json", doc)
    with pytest.raises(ConfigError, match=f"^{re.escape(str(path))}: .*{words}") as err:
        ExperimentConfig.load(path)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("doc,words", [BAD_EXPERIMENTS[0], BAD_EXPERIMENTS[2], BAD_EXPERIMENTS[3], BAD_EXPERIMENTS[5]])
def test_experiment_cli_prints_one_line_and_makes_no_folder(tmp_path, monkeypatch, capsys, doc, words):
    path, out = write(tmp_path / "bad.json", doc), tmp_path / "OUT"
    monkeypatch.setattr(sys, "argv", ["adaptenv", "experiment", "--config", str(path), "-o", str(out)])
    with pytest.raises(SystemExit) as exit_:
        main()
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 1 and not out.exists()
    assert err.startswith("error: ") and "\n" not in err and "Traceback" not in err
    assert str(path) in err and re.search(words, err), err


def test_every_shipped_config_and_saved_experiment_loads():
    paths = sorted((REPO / "configs").glob("*.json")) + sorted((REPO / "docs" / "results").rglob("experiment.json"))
    assert len(paths) >= 9
    for path in paths:
        cfg = ExperimentConfig.load(path)
        assert cfg.reference in cfg.methods, path


def test_loop_config_types_are_checked_before_the_run_folder(tmp_path):
    with pytest.raises(ConfigError, match='loop config: iterations should be a whole number, got "3"'):
        run_loop(LoopConfig(iterations="3"), tmp_path / "run")
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("doc,words", [
    ({"level_ids": "abc", "scores": [1, 2, 3], "last_seen": [0, 0, 0], "parent_ids": [None] * 3, "n_inserted": 3},
     'level_ids should be a JSON array, got "abc"'),
    ({"n_inserted": "3"}, 'n_inserted should be a whole number, got "3"'),
    ({"level_ids": ["a"], "scores": [0.5], "last_seen": [1.5], "parent_ids": [None], "n_inserted": 1},
     r"last_seen\[0\] should be a whole number, got 1.5"),
    ({"level_ids": [7], "scores": [0.5], "last_seen": [1], "parent_ids": [None], "n_inserted": 1},
     r"level_ids\[0\] should be a string, got 7"),
])
def test_level_buffer_state_file_with_a_wrong_type(tmp_path, doc, words):
    path = write(tmp_path / "buffer.json", doc)
    with pytest.raises(ConfigError, match=f"buffer.json: {words}"):
        LevelBufferState.from_json(path.read_text(), source=str(path))


def test_resumed_loop_names_the_bad_field_of_its_state_file(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    cfg = LoopConfig()
    write(run / "state.json", {"config": asdict(cfg), "state": {"iteration": 1, "buffer": {"scores": "high"}}})
    with pytest.raises(ConfigError, match=r"state.json: state.buffer: scores should be a JSON array"):
        run_loop(cfg, run, resume=True)
    write(run / "state.json", {"config": asdict(cfg), "state": {"iteration": "1"}})
    with pytest.raises(ConfigError, match=r"state.json: state.iteration should be a whole number"):
        run_loop(cfg, run, resume=True)


@pytest.mark.parametrize("entry,words", [
    ({"type": "Sofa", "size": [1, 1, 1], "colour": "red"}, "colour is not a known field"),
    ({"type": "Sofa", "sise": [1, 1, 1]}, "sise is not a known field; did you mean 'size'"),
    ({"type": "Sofa", "size": ["1", 1, 1]}, r'size\[0\] should be a number, got "1"'),
    ({"type": "Sofa", "size": [1, 1, 1], "split": "mine"}, "split should be 'train', 'val' or 'test'"),
    ({"type": "Sofa", "size": [1, 1, 1], "primary": 5}, "primary should be a string"),
    ({"type": "Sofa", "boundingBox": {"x": 1, "y": 1, "z": 1, "w": 1}}, "boundingBox.w is not a known field"),
])
def test_bad_asset_table_names_asset_and_field(tmp_path, entry, words):
    path = write(tmp_path / "assets.json", {"assets": {"x": entry}})
    with pytest.raises(ConfigError, match=f"--assets {re.escape(str(path))}: asset 'x': {words}"):
        read_asset_table(path)


def test_bad_asset_table_on_the_cli_is_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv(ASSETS_ENV, "")
    path = write(tmp_path / "assets.json", {"assets": {"x": {"type": "Sofa", "size": [1, 1, 1], "colour": "red"}},
                                            "license": "mine"})
    monkeypatch.setattr(sys, "argv", ["adaptenv", "--assets", str(path), "validate", str(tmp_path)])
    with pytest.raises(SystemExit) as exit_:
        main()
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 1 and "\n" not in err
    assert err == (f'error: --assets {path}: license is not a known field next to "assets" (allowed: assets, note, '
                   'source); remove it')


@pytest.mark.parametrize("doc,words", [
    ({"max_retries": "3"}, 'max_retries should be a whole number, got "3"'),
    ({"temperature": True}, "temperature should be a number"),
    ({"cache_dir": 5}, "cache_dir should be a string"),
    (["gpt-4.1-mini"], "should be a JSON object"),
])
def test_llm_config_file_with_a_wrong_type(tmp_path, doc, words):
    path = write(tmp_path / "llm.json", doc)
    with pytest.raises(ConfigError, match=rf"llm.json \(LLM config\): .*{words}"):
        load_llm_config(path)
