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


def plausible_object(house_file, rotation: float) -> str:
    """The first movable object that 2 units left and 1 up, turned to ``rotation``, breaks no plausibility rule (the
    scripted LLM's move; one a person would not believe is refused and re-asked)."""
    from adaptenv.adapt.generators import movable_ids
    from adaptenv.adapt.validation import EditValidator
    from adaptenv.scene.house import load_house

    house = load_house(house_file)
    v = EditValidator(house)
    return next(o for o in movable_ids(house) if (p := v.propose(o, -2.0, 1.0, rotation)).result.changed
                and not [q for q in p.problems if q.kind == "implausible"])


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
    # both houses measured again on 8 fresh draws of the episode: the expert solves every draw of a solvable house
    fresh = json.loads((out / "summary.json").read_text())["fresh"]
    assert fresh == {"draws": 8, "success_before": 1.0, "success_after": 1.0}
    assert "on 8 fresh action draws of the episode (no G rolled them out): success 1.00 -> 1.00" in text
    # one line on what G made; the expert solved the episode F analysed, which the line says
    line = json.loads((out / "summary.json").read_text())["edits_line"]
    assert line.startswith("G made ") and "F found no failure in 1 episode" in line
    assert line.split(";")[0] in text


def test_adapt_adapts_to_the_shipped_agent_unless_told_otherwise(house_file, tmp_path):
    from adaptenv.agents.policy import policy_name
    from adaptenv.agents.registry import resolve_policy

    result = runner.invoke(app, ["adapt", str(house_file), "--steps", "1", "--seed", "1", "--json",
                                 "-o", str(tmp_path / "out")])
    assert result.exit_code in (0, 1), result.output
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["policy"] == policy_name(resolve_policy("pretrained")) != "expert"
    assert summary["edits_line"].startswith("G made ") and summary["edits_line"].count(" of 1 edit") == 1


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
    oid = plausible_object(house_file, 0.0)
    assert oid in movable_ids(load_house(house_file))
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


# ----------------------------------------------------------------------------- LLM F and G through the CLI

KEY = "sk-cli-SECRET-0123456789abcdef"


def _server_module():
    import importlib.util
    import sys
    from pathlib import Path

    name = "adaptenv_tests_llm_server"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name("llm_server.py"))
        sys.modules[name] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(sys.modules[name])
    return sys.modules[name]


F_ANSWER = {"outcome": {"success": True, "failure_mode": None, "summary": "reached it"}, "concerns": [],
            "suggestions": [{"kind": "narrow_passage", "description": "tighter", "addresses": [], "priority": 0.9}]}


def _responses_answer(srv, plausible: str = ""):
    """Answer any Responses API request of F or G (``plausible``, else the first allowed object, moved left then back
    right, so that every move stays plausible; verification says yes)."""
    moves = []

    def reply(body):
        tools = body.get("tools") or []
        if not tools:
            return 200, srv.responses_text_reply(json.dumps(F_ANSWER), input_tokens=1200, output_tokens=150)
        if tools[0]["name"] == "propose_move_instruction":
            oid = plausible if plausible in (ids := tools[0]["parameters"]["properties"]["object_id"]["enum"]) \
                else ids[0]
            moves.append(oid)
            back = len(moves) % 2 == 0
            return 200, srv.responses_tool_reply("propose_move_instruction", {
                "object_id": oid, "x_direction": "right" if back else "left", "x_units": 2,
                "y_direction": "down" if back else "up", "y_units": 1,
                "rotation": 90}, input_tokens=1000, output_tokens=40)
        return 200, srv.responses_tool_reply("verify_move", {"matches_intent": True, "reason": "ok",
                                                             "revised_move": None}, input_tokens=1100, output_tokens=30)
    return reply


@pytest.fixture
def loopback(monkeypatch):
    for name in ("HTTP_PROXY", "HTTPS_PROXY", "ALL_PROXY", "http_proxy", "https_proxy", "all_proxy",
                 "OPENAI_BASE_URL", "OPENAI_API_KEY"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("NO_PROXY", "127.0.0.1,localhost")
    return monkeypatch


def _key_files(folder) -> list[str]:
    return [str(p) for p in folder.rglob("*") if p.is_file() and KEY.encode() in p.read_bytes()]


def test_adapt_llm_counts_every_call_records_the_model_and_never_writes_the_key(house_file, tmp_path, loopback):
    """F and G on the Responses API of a custom server (--api responses --base-url): 7 calls made, 7 counted."""
    srv = _server_module()
    loopback.setenv("ADAPTENV_LLM_API_KEY", KEY)
    with srv.ScriptedLLMServer({srv.RESPONSES_PATH: [_responses_answer(srv, plausible_object(house_file, 90.0))] * 20}, max_requests=20,
                               timeout_s=120) as server:
        result = runner.invoke(app, ["adapt", str(house_file), "--generator", "llm", "--analyzer", "llm",
                                     "--api", "responses", "--base-url", server.url, "--model", "m", "--steps", "3",
                                     "--seed", "1", "--price-in", "0.4", "--price-out", "1.6", "-o", str(tmp_path)])
        assert result.exit_code == 0, result.output
        requests = list(server.requests)
    assert {r.path for r in requests} == {srv.RESPONSES_PATH}
    summary = json.loads((tmp_path / "summary.json").read_text())
    usage = summary["usage"]
    assert usage["calls"] == len(requests) == 7, "F, then G and verification for each of 3 steps"
    assert {k: v["calls"] for k, v in usage["by_role"].items()} == {"F": 1, "G": 3, "verify": 3}
    assert usage["input_tokens"] == 1200 + 3 * 1000 + 3 * 1100 and usage["output_tokens"] == 150 + 3 * 40 + 3 * 30
    assert usage["cost_usd"] == pytest.approx((7500 * 0.4 + 360 * 1.6) / 1e6)
    assert summary["llm"] | {"model": "m", "api": "responses", "base_url": server.url, "prompts": "adaptenv",
                             "temperature": 0.0} == summary["llm"]
    assert "tokens F " in result.output and "tokens total" in result.output and "G step 3/3: applied" in result.output
    edits = json.loads((tmp_path / "edits.json").read_text())
    applied = [s for s in edits["steps"] if s["status"] == "applied"]
    assert summary["edits_applied"] == len(applied)
    assert _key_files(tmp_path) == [] and all(r.authorization == f"Bearer {KEY}" for r in requests)


def test_openai_base_url_is_honoured_and_the_cache_replays_offline(house_file, tmp_path, loopback):
    """OPENAI_BASE_URL + OPENAI_API_KEY as the SDK reads them; a second run from --llm-cache makes no request."""
    srv = _server_module()
    cache = tmp_path / "cache"
    with srv.ScriptedLLMServer({srv.RESPONSES_PATH: [_responses_answer(srv, plausible_object(house_file, 90.0))] * 10}, max_requests=10,
                               timeout_s=120) as server:
        loopback.setenv("OPENAI_BASE_URL", server.url)
        loopback.setenv("OPENAI_API_KEY", KEY)
        first = runner.invoke(app, ["adapt", str(house_file), "--generator", "llm", "--steps", "2", "--seed", "1",
                                    "--llm-cache", str(cache), "-o", str(tmp_path / "a")])
        assert first.exit_code == 0, first.output
        made = len(server.requests)
        assert made == 4 and f"at {server.url} (responses API" in first.output
    # the server is gone: the replay must come from the cache alone
    second = runner.invoke(app, ["adapt", str(house_file), "--generator", "llm", "--steps", "2", "--seed", "1",
                                 "--llm-cache", str(cache), "-o", str(tmp_path / "b")])
    assert second.exit_code == 0, second.output
    assert (tmp_path / "a" / "house.json").read_text() == (tmp_path / "b" / "house.json").read_text()
    usage = json.loads((tmp_path / "b" / "summary.json").read_text())["usage"]
    assert usage["calls"] == 0 and usage["cache_hits"] == made
    assert _key_files(tmp_path) == []


def test_unreachable_server_is_named_in_one_line(house_file, tmp_path, loopback):
    loopback.setenv("OPENAI_API_KEY", KEY)
    loopback.setenv("OPENAI_BASE_URL", "http://127.0.0.1:9/v1")
    result = runner.invoke(app, ["adapt", str(house_file), "--analyzer", "llm", "--steps", "1",
                                 "--llm-config", str(_llm_config(tmp_path)), "-o", str(tmp_path / "o")])
    assert "http://127.0.0.1:9/v1" in str(result.exception) and KEY not in str(result.exception)


def _llm_config(tmp_path):
    path = tmp_path / "llm.json"
    path.write_text(json.dumps({"max_retries": 0, "timeout_s": 2}))
    return path


def test_analyze_refuses_a_trajectory_from_another_house(house_file, adapted, tmp_path):
    from adaptenv.scene.house import save_house
    from adaptenv.scene.procedural import GenerationConfig, generate_house

    out, _ = adapted
    other = save_house(generate_house(11, GenerationConfig(n_rooms=3)), tmp_path / "other.json")
    result = runner.invoke(app, ["analyze", str(other), str(out / "trajectory_before.json")])
    assert isinstance(result.exception, ConfigError)
    message = str(result.exception)
    assert "trajectory_before.json" in message and "other.json" in message and "h'" in message
    assert "\n" not in message


def test_adapt_with_a_diagnosis_aims_g_at_failure_modes(house_file, tmp_path):
    result = runner.invoke(app, ["adapt", str(house_file), "--policy", "expert", "--steps", "1", "--seed", "1",
                                 "--diagnose", "2", "--generator", "failure-modes", "-o", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "diagnosis before:" in result.output and "regret 0.00" in result.output
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert len(summary["diagnosis"]["episodes"]) == len(summary["diagnosis_after"]["episodes"]) == 2
    steps = json.loads((tmp_path / "edits.json").read_text())["steps"]
    assert steps[0]["failure_mode"] == "search", "a solved scene gets the default plan, searches first"


def test_adapt_with_door_edits_opens_a_shut_door(tmp_path):
    from adaptenv.scene.house import load_house, save_house
    from adaptenv.scene.procedural import GenerationConfig, generate_house
    from adaptenv.scene.procedural.checks import closed_interior_doors

    shut = generate_house(0, GenerationConfig(n_rooms=6, closed_door_prob=0.4))
    path = save_house(shut, tmp_path / "shut.json")
    args = ["adapt", str(path), "--policy", "expert", "--steps", "2", "--seed", "1", "--diagnose", "2"]
    wrong = runner.invoke(app, [*args, "--door-edits", "-o", str(tmp_path / "x")])
    assert isinstance(wrong.exception, ConfigError) and "add --generator failure-modes" in str(wrong.exception)
    result = runner.invoke(app, [*args, "--generator", "failure-modes", "--door-edits", "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    doors = [e for e in json.loads((tmp_path / "out" / "edits.json").read_text())["edit_log"]
             if e["openness"] is not None and e["accepted"]]
    assert doors, "G opened a door"
    after = load_house(tmp_path / "out" / "house.json")
    assert set(closed_interior_doors(after)) == set(closed_interior_doors(shut)) - {e["object_id"] for e in doors}
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["valid"]


def test_adapt_relocate_targets_reaches_the_failure_mode_g(tmp_path, monkeypatch):
    import adaptenv.adapt.generators.failure_modes as fm
    from adaptenv.scene.house import save_house
    from adaptenv.scene.procedural import GenerationConfig, generate_house

    made = []
    real = fm.FailureModeGenerator.__init__

    def spy(self, **kw):
        real(self, **kw)
        made.append(self.relocate_targets)

    monkeypatch.setattr(fm.FailureModeGenerator, "__init__", spy)
    path = save_house(generate_house(0, GenerationConfig(n_rooms=4)), tmp_path / "h.json")
    args = ["adapt", str(path), "--policy", "expert", "--steps", "1", "--seed", "1", "--relocate-targets"]
    wrong = runner.invoke(app, [*args, "-o", str(tmp_path / "x")])
    assert isinstance(wrong.exception, ConfigError) and "add --generator failure-modes" in str(wrong.exception)
    assert not (tmp_path / "x").exists() and made == []
    result = runner.invoke(app, [*args, "--generator", "failure-modes", "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    assert made == [True]
