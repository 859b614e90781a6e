"""``adaptenv analyze`` and ``adaptenv adapt``: a tiny end-to-end run and the one-line errors."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from adaptenv.cli import app
from adaptenv.errors import ConfigError

runner = CliRunner()


@pytest.fixture(scope="module")
def house_file(tmp_path_factory):
    from adaptenv.scene.house import save_house
    from adaptenv.scene.procedural import GenerationConfig, generate_house

    return save_house(generate_house(5, GenerationConfig(n_rooms=4)), tmp_path_factory.mktemp("h") / "h.json")


@pytest.fixture(scope="module")
def adapted(house_file, tmp_path_factory):
    out = tmp_path_factory.mktemp("out")
    result = runner.invoke(app, ["adapt", str(house_file), "--policy", "expert", "--steps", "2", "--seed", "1",
                                 "-o", str(out)])
    assert result.exit_code == 0, result.output
    return out, result.output


def test_adapt_writes_a_house_that_validates(adapted):
    out, text = adapted
    assert "edits applied:" in text and "expert solvable: True" in text
    check = runner.invoke(app, ["validate", str(out / "house.json")])
    assert check.exit_code == 0, check.output
    assert (out / "before.png").is_file() and (out / "after.png").is_file()


def test_analyze_text_and_json(house_file, adapted):
    out, _ = adapted
    text = runner.invoke(app, ["analyze", str(house_file), str(out / "trajectory_before.json")])
    assert text.exit_code == 0 and text.output.startswith("Task: Find a")
    js = runner.invoke(app, ["analyze", str(house_file), str(out / "trajectory_before.json"), "--json"])
    assert js.exit_code == 0
    doc = json.loads(js.output)
    assert doc["source"] == "builtin" and doc["outcome"]["success"] is True


def test_llm_without_server_is_a_clear_error(house_file, tmp_path, monkeypatch):
    monkeypatch.delenv("OPENAI_API_KEY", raising=False)
    result = runner.invoke(app, ["adapt", str(house_file), "--generator", "llm", "-o", str(tmp_path)])
    assert isinstance(result.exception, ConfigError)
    assert "--generator llm needs a model server" in str(result.exception)
    assert not (tmp_path / "house.json").exists()


def test_unknown_generator(house_file, tmp_path):
    result = runner.invoke(app, ["adapt", str(house_file), "--generator", "genetic", "-o", str(tmp_path)])
    assert isinstance(result.exception, ConfigError) and "use one of builtin, llm, random" in str(result.exception)


def test_adapt_with_llm_generator_against_a_local_server(house_file, tmp_path, monkeypatch):
    """End to end through the CLI: the real openai SDK talking to a scripted server on 127.0.0.1."""
    import importlib.util
    import sys
    from pathlib import Path

    from adaptenv.adapt.generators import movable_ids
    from adaptenv.scene.house import load_house

    name = "adaptenv_tests_llm_server"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name("llm_server.py"))
        sys.modules[name] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(sys.modules[name])
    srv = sys.modules[name]
    monkeypatch.delenv("OPENAI_API_KEY", raising=False)
    oid = movable_ids(load_house(house_file))[0]
    move = {"object_id": oid, "x_direction": "left", "x_units": 2, "y_direction": "up", "y_units": 1, "rotation": 0}
    replies = {srv.CHAT_PATH: [(200, srv.chat_tool_reply("propose_move_instruction", move)),
                               (200, srv.chat_tool_reply("verify_move", {"matches_intent": True, "reason": "ok",
                                                                         "revised_move": None}))]}
    with srv.ScriptedLLMServer(replies, max_requests=4, timeout_s=60) as server:
        result = runner.invoke(app, ["adapt", str(house_file), "--generator", "llm", "--base-url", server.url,
                                     "--model", "m", "--steps", "1", "--seed", "1", "-o", str(tmp_path)])
        assert result.exit_code == 0, result.output
        assert len(server.requests) == 2
    edits = json.loads((tmp_path / "edits.json").read_text())
    assert edits["generator"] == "llm" and edits["steps"][0]["edit"]["object_id"] == oid
    assert edits["usage"]["calls"] == 2
    assert runner.invoke(app, ["validate", str(tmp_path / "house.json")]).exit_code == 0


def test_adapt_with_a_diagnosis_aims_g_at_failure_modes(house_file, tmp_path):
    result = runner.invoke(app, ["adapt", str(house_file), "--policy", "expert", "--steps", "1", "--seed", "1",
                                 "--diagnose", "2", "--generator", "failure-modes", "-o", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "diagnosis before:" in result.output and "regret 0.00" in result.output
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert len(summary["diagnosis"]["episodes"]) == len(summary["diagnosis_after"]["episodes"]) == 2
    steps = json.loads((tmp_path / "edits.json").read_text())["steps"]
    assert steps[0]["failure_mode"] == "search", "a solved scene gets the default plan, searches first"
