"""The LLM transport layer through the real openai SDK, offline (mock transport and a 127.0.0.1 server)."""

from __future__ import annotations

import base64
import io
import json
import pickle
import subprocess
import sys

import httpx2
import pytest
from PIL import Image
from pydantic import BaseModel

from adaptenv.adapt.llm import (
    BudgetExceeded,
    CallRecord,
    ChatCompletionsBackend,
    LLMAuthError,
    LLMConfig,
    LLMError,
    LLMRequestError,
    LLMUnavailableError,
    Message,
    OpenAIResponsesBackend,
    Prices,
    StructuredOutputError,
    Tokens,
    ToolCallError,
    Usage,
    load_llm_config,
    make_backend,
    move_tool,
    resolve_api_key,
)
from adaptenv.errors import AdaptenvError, ConfigError
from tests.adapt import llm_server as srv

KEY = "sk-test-SECRET-0123456789abcdef"
IDS = ["Sofa|1", "Chair|2"]
MOVE = {"object_id": "Sofa|1", "x_direction": "left", "x_units": 12.5, "y_direction": "up", "y_units": 3,
        "rotation": 90}


def _png(color: tuple[int, int, int] = (10, 20, 30)) -> bytes:
    buf = io.BytesIO()
    Image.new("RGB", (4, 4), color).save(buf, format="PNG")
    return buf.getvalue()


class Analysis(BaseModel):
    success: bool
    concerns: list[str]


class Mock:
    """A scripted httpx2 MockTransport: replies in order; records every request."""

    def __init__(self, *replies):
        self.replies = list(replies)
        self.requests: list[httpx2.Request] = []

    def __call__(self, request: httpx2.Request) -> httpx2.Response:
        self.requests.append(request)
        reply = self.replies.pop(0)
        if isinstance(reply, Exception):
            raise reply
        if isinstance(reply, type) and issubclass(reply, Exception):
            raise reply("scripted failure", request=request)
        status, body, *headers = reply
        return httpx2.Response(status, json=body, headers=headers[0] if headers else None)

    @property
    def bodies(self) -> list[dict]:
        return [json.loads(r.content) for r in self.requests]

    def client(self) -> httpx2.Client:
        return httpx2.Client(transport=httpx2.MockTransport(self))


def _responses(mock: Mock, sleeps: list[float] | None = None, **cfg) -> OpenAIResponsesBackend:
    config = LLMConfig(api_key=KEY, **cfg)
    return OpenAIResponsesBackend(config, http_client=mock.client(),
                                  sleep=(sleeps.append if sleeps is not None else _no_sleep))


def _chat(mock: Mock, sleeps: list[float] | None = None, **cfg) -> ChatCompletionsBackend:
    config = LLMConfig(provider="openai-compatible", base_url="http://127.0.0.1:9/v1", **cfg)
    return ChatCompletionsBackend(config, http_client=mock.client(),
                                  sleep=(sleeps.append if sleeps is not None else _no_sleep))


def _no_sleep(_: float) -> None:
    raise AssertionError("this test should not back off")


# ----- import, config, key handling -------------------------------------------------------------


def test_import_does_not_load_openai():
    code = "import sys, adaptenv.adapt.llm; print('openai' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_missing_openai_package_names_pip_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "openai", None)
    with pytest.raises(LLMError, match="pip install openai"):
        OpenAIResponsesBackend(LLMConfig(api_key=KEY))


def test_missing_key_for_openai_is_a_clear_error(monkeypatch):
    monkeypatch.delenv("OPENAI_API_KEY", raising=False)
    with pytest.raises(ConfigError, match="OPENAI_API_KEY"):
        make_backend(LLMConfig())
    monkeypatch.setenv("MY_KEY", KEY)
    assert resolve_api_key(LLMConfig(api_key_env="MY_KEY")) == KEY


def test_compatible_server_uses_placeholder_key_and_needs_base_url(monkeypatch):
    monkeypatch.delenv("OPENAI_API_KEY", raising=False)
    mock = Mock((200, srv.chat_tool_reply("propose_move_instruction", MOVE)))
    _chat(mock).call_tool("s", [Message.user("go")], None, move_tool(IDS))
    assert mock.requests[0].headers["authorization"] == "Bearer not-needed"
    with pytest.raises(ConfigError, match="base_url"):
        make_backend(LLMConfig(provider="openai-compatible"))


def test_key_never_in_config_or_backend_text():
    cfg = LLMConfig(api_key=KEY)
    backend = OpenAIResponsesBackend(cfg, http_client=Mock().client())
    texts = [repr(cfg), str(cfg), cfg.model_dump_json(), json.dumps(cfg.model_dump(mode="json")), repr(backend)]
    assert all(KEY not in t for t in texts)
    assert cfg.api_key.get_secret_value() == KEY


def test_load_llm_config_names_file_and_field(tmp_path):
    good = tmp_path / "llm.json"
    good.write_text(json.dumps({"provider": "openai-compatible", "base_url": "http://127.0.0.1:8000/v1",
                                "model": "m", "cache_dir": str(tmp_path / "c")}))
    cfg = load_llm_config(good)
    assert cfg.model == "m" and cfg.cache_dir == tmp_path / "c"
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"timeout_s": -1}))
    with pytest.raises(ConfigError, match=r"bad.json \(LLM config\): timeout_s should be greater than 0"):
        load_llm_config(bad)
    secret = tmp_path / "secret.json"
    secret.write_text(json.dumps({"model": "m", "api_key": KEY}))
    with pytest.raises(ConfigError, match="secret.json: field api_key holds an API key") as info:
        load_llm_config(secret)
    assert KEY not in str(info.value) and "api_key_env" in str(info.value)
    typo = tmp_path / "typo.json"
    typo.write_text(json.dumps({"modle": "x"}))
    with pytest.raises(ConfigError, match="modle is not a known field; did you mean .model."):
        load_llm_config(typo)


# ----- exact request bodies --------------------------------------------------------------------


def _expected_tool_params() -> dict:
    return move_tool(IDS).parameters


def test_responses_call_tool_exact_request_body():
    png = _png()
    mock = Mock((200, srv.responses_tool_reply("propose_move_instruction", MOVE)))
    result = _responses(mock).call_tool("You edit apartments.", [Message.user("Move one object.")], png,
                                        move_tool(IDS))
    (request,) = mock.requests
    assert str(request.url) == "https://api.openai.com/v1/responses"
    data_url = "data:image/png;base64," + base64.b64encode(png).decode()
    assert json.loads(request.content) == {
        "model": "gpt-4.1-mini",
        "instructions": "You edit apartments.",
        "input": [{"role": "user", "content": [
            {"type": "input_text", "text": "Move one object."},
            {"type": "input_image", "image_url": data_url, "detail": "auto"}]}],
        "tools": [{"type": "function", "name": "propose_move_instruction",
                   "description": move_tool(IDS).description, "parameters": _expected_tool_params(),
                   "strict": True}],
        "tool_choice": {"type": "function", "name": "propose_move_instruction"},
        "parallel_tool_calls": False,
        "store": False,
        "temperature": 0.0,
    }
    assert result.arguments == MOVE
    assert result.name == "propose_move_instruction"
    assert result.model == "gpt-4.1-mini-2025-04-14"
    assert (result.usage.input_tokens, result.usage.output_tokens, result.usage.total_tokens) == (13, 5, 18)


def test_chat_call_tool_exact_request_body():
    png = _png()
    mock = Mock((200, srv.chat_tool_reply("propose_move_instruction", MOVE)))
    result = _chat(mock, model="qwen2.5vl:7b").call_tool("sys", [Message.user("Move one object.")], png,
                                                          move_tool(IDS))
    (request,) = mock.requests
    assert str(request.url) == "http://127.0.0.1:9/v1/chat/completions"
    data_url = "data:image/png;base64," + base64.b64encode(png).decode()
    assert json.loads(request.content) == {
        "model": "qwen2.5vl:7b",
        "messages": [
            {"role": "system", "content": "sys"},
            {"role": "user", "content": [{"type": "text", "text": "Move one object."},
                                         {"type": "image_url", "image_url": {"url": data_url}}]}],
        "tools": [{"type": "function", "function": {
            "name": "propose_move_instruction", "description": move_tool(IDS).description,
            "parameters": _expected_tool_params(), "strict": True}}],
        "tool_choice": {"type": "function", "function": {"name": "propose_move_instruction"}},
        "parallel_tool_calls": False,
        "temperature": 0.0,
    }
    assert result.arguments == MOVE
    assert result.usage.total_tokens == 18


def test_multi_turn_conversation_maps_to_both_apis():
    first, second = _png((1, 1, 1)), _png((2, 2, 2))
    turns = [Message.user("Move one object.", first), Message.assistant('{"object_id": "Nope"}'),
             Message.user("object_id 'Nope' is unknown; call again.")]
    mock = Mock((200, srv.responses_tool_reply("propose_move_instruction", MOVE)),
                (200, srv.chat_tool_reply("propose_move_instruction", MOVE)))
    _responses(mock).call_tool("", turns, second, move_tool(IDS))
    _chat(mock).call_tool("", turns, second, move_tool(IDS))
    resp_body, chat_body = mock.bodies
    assert "instructions" not in resp_body
    roles = [m["role"] for m in resp_body["input"]]
    assert roles == ["user", "assistant", "user"]
    assert resp_body["input"][1] == {"role": "assistant", "content": '{"object_id": "Nope"}'}
    assert [p["type"] for p in resp_body["input"][2]["content"]] == ["input_text", "input_image"]
    assert [m["role"] for m in chat_body["messages"]] == ["user", "assistant", "user"]
    assert chat_body["messages"][1] == {"role": "assistant", "content": '{"object_id": "Nope"}'}
    assert [p["type"] for p in chat_body["messages"][2]["content"]] == ["text", "image_url"]


def test_image_goes_into_a_new_turn_when_the_last_one_has_an_image():
    mock = Mock((200, srv.chat_tool_reply("propose_move_instruction", MOVE)))
    _chat(mock).call_tool("s", [Message.user("before", _png((1, 1, 1)))], _png((9, 9, 9)), move_tool(IDS))
    msgs = mock.bodies[0]["messages"]
    assert len(msgs) == 3
    assert msgs[2]["content"][0]["type"] == "image_url"


def test_responses_parse_sends_json_schema_and_validates():
    mock = Mock((200, srv.responses_text_reply('{"success": false, "concerns": ["narrow door"]}')))
    result = _responses(mock).parse("Analyze.", [Message.user("trajectory")], _png(), Analysis)
    body = mock.bodies[0]
    fmt = body["text"]["format"]
    assert (fmt["type"], fmt["name"], fmt["strict"]) == ("json_schema", "Analysis", True)
    assert set(fmt["schema"]["properties"]) == {"success", "concerns"}
    assert fmt["schema"]["additionalProperties"] is False
    assert "tools" not in body and body["model"] == "gpt-4.1-mini"
    assert result.value == Analysis(success=False, concerns=["narrow door"])
    assert result.usage.total_tokens == 18


def test_chat_parse_uses_response_format_json_schema():
    mock = Mock((200, srv.chat_text_reply('{"success": true, "concerns": []}')))
    result = _chat(mock).parse("Analyze.", [Message.user("trajectory")], None, Analysis)
    rf = mock.bodies[0]["response_format"]
    assert rf["type"] == "json_schema" and rf["json_schema"]["name"] == "Analysis"
    assert result.value.success is True


def test_chat_parse_falls_back_to_json_mode_when_schema_is_rejected():
    mock = Mock((400, srv.error_body("response_format json_schema is not supported")),
                (200, srv.chat_text_reply('```json\n{"success": true, "concerns": ["x"]}\n```')),
                (200, srv.chat_text_reply('{"success": false, "concerns": []}')))
    backend = _chat(mock)
    first = backend.parse("Analyze.", [Message.user("t1")], None, Analysis)
    second = backend.parse("Analyze.", [Message.user("t2")], None, Analysis)
    assert first.value.concerns == ["x"] and second.value.success is False
    bodies = mock.bodies
    assert len(bodies) == 3
    assert bodies[1]["response_format"] == {"type": "json_object"}
    assert bodies[2]["response_format"] == {"type": "json_object"}, "the fallback is remembered"
    assert '"concerns"' in bodies[1]["messages"][0]["content"], "the schema goes into the system prompt"


def test_chat_parse_without_fallback_raises_on_rejection():
    mock = Mock((400, srv.error_body("response_format json_schema is not supported")))
    with pytest.raises(LLMRequestError, match="HTTP 400"):
        _chat(mock, structured_output="json_schema").parse("s", [Message.user("t")], None, Analysis)


def test_parse_invalid_answer_gives_feedback():
    mock = Mock((200, srv.responses_text_reply('{"success": "maybe"}')))
    with pytest.raises(StructuredOutputError) as info:
        _responses(mock).parse("s", [Message.user("t")], None, Analysis)
    assert "success" in info.value.feedback and "concerns" in info.value.feedback
    assert info.value.raw == '{"success": "maybe"}'


def test_parse_cut_off_answer_is_reported():
    mock = Mock((200, srv.chat_text_reply('{"success": tr', finish_reason="length")))
    with pytest.raises(StructuredOutputError, match="cut off"):
        _chat(mock).parse("s", [Message.user("t")], None, Analysis)


# ----- failures and retries --------------------------------------------------------------------


def test_429_then_success_is_retried_with_backoff():
    sleeps: list[float] = []
    mock = Mock((429, srv.error_body("rate limited", "rate_limit_error")),
                (200, srv.responses_tool_reply("propose_move_instruction", MOVE)))
    result = _responses(mock, sleeps).call_tool("s", [Message.user("go")], None, move_tool(IDS))
    assert result.arguments == MOVE
    assert len(mock.requests) == 2
    assert len(sleeps) == 1 and 1.0 <= sleeps[0] <= 1.25


def test_retry_after_header_is_respected_within_the_cap():
    sleeps: list[float] = []
    mock = Mock((429, srv.error_body("slow down"), {"retry-after": "7"}),
                (429, srv.error_body("slow down"), {"retry-after": "700"}),
                (200, srv.responses_tool_reply("propose_move_instruction", MOVE)))
    _responses(mock, sleeps, backoff_max_s=20).call_tool("s", [Message.user("go")], None, move_tool(IDS))
    assert sleeps == [7.0, 20.0]


def test_500_twice_then_success_backs_off_exponentially():
    sleeps: list[float] = []
    mock = Mock((500, srv.error_body("boom", "server_error")), (503, srv.error_body("busy", "server_error")),
                (200, srv.chat_tool_reply("propose_move_instruction", MOVE)))
    result = _chat(mock, sleeps).call_tool("s", [Message.user("go")], None, move_tool(IDS))
    assert result.arguments == MOVE and len(mock.requests) == 3
    assert len(sleeps) == 2
    assert 1.0 <= sleeps[0] <= 1.25 and 2.0 <= sleeps[1] <= 2.5


def test_backoff_jitter_is_seeded():
    def run(seed: int) -> list[float]:
        sleeps: list[float] = []
        mock = Mock((500, {}), (500, {}), (200, srv.chat_tool_reply("propose_move_instruction", MOVE)))
        _chat(mock, sleeps, seed=seed).call_tool("s", [Message.user("go")], None, move_tool(IDS))
        return sleeps
    assert run(3) == run(3)
    assert run(3) != run(4)


def test_timeouts_are_retried_then_fail_clearly():
    sleeps: list[float] = []
    mock = Mock(httpx2.ReadTimeout, httpx2.ReadTimeout, httpx2.ReadTimeout)
    with pytest.raises(LLMUnavailableError, match="timed out after 5 s") as info:
        _chat(mock, sleeps, max_retries=2, timeout_s=5).call_tool("s", [Message.user("go")], None, move_tool(IDS))
    assert len(mock.requests) == 3 and len(sleeps) == 2
    assert "3 attempt" in str(info.value)


def test_connection_error_then_success():
    sleeps: list[float] = []
    mock = Mock(httpx2.ConnectError, (200, srv.chat_tool_reply("propose_move_instruction", MOVE)))
    assert _chat(mock, sleeps).call_tool("s", [Message.user("go")], None, move_tool(IDS)).arguments == MOVE
    assert len(sleeps) == 1


def test_zero_retries_fails_after_one_attempt():
    mock = Mock((500, {}))
    with pytest.raises(LLMUnavailableError, match="1 attempt"):
        _chat(mock, max_retries=0).call_tool("s", [Message.user("go")], None, move_tool(IDS))
    assert len(mock.requests) == 1


def test_401_fails_fast_without_leaking_the_key():
    leaked = srv.error_body(f"Incorrect API key provided: {KEY}. You can find your API key at ...")
    mock = Mock((401, leaked), (200, srv.responses_tool_reply("propose_move_instruction", MOVE)))
    with pytest.raises(LLMAuthError) as info:
        _responses(mock).call_tool("s", [Message.user("go")], None, move_tool(IDS))
    exc = info.value
    assert len(mock.requests) == 1, "no retry on 401"
    assert "API key was rejected" in str(exc) and "OPENAI_API_KEY" in str(exc)
    assert isinstance(exc, AdaptenvError)
    assert exc.__cause__ is None and exc.__suppress_context__
    assert KEY not in str(exc) and KEY not in repr(exc) and "SECRET" not in str(exc)


def test_other_4xx_fails_fast_with_redacted_server_message():
    mock = Mock((400, srv.error_body(f"Invalid image; key {KEY} and sk-proj-abcdef123 are irrelevant")))
    with pytest.raises(LLMRequestError) as info:
        _responses(mock).call_tool("s", [Message.user("go")], None, move_tool(IDS))
    text = str(info.value)
    assert "HTTP 400" in text and "Invalid image" in text
    assert KEY not in text and "sk-proj-abcdef123" not in text
    assert info.value.status_code == 400 and len(mock.requests) == 1


def test_malformed_tool_arguments_raise_feedback():
    mock = Mock((200, srv.chat_tool_reply("propose_move_instruction", '{"object_id": "Sofa|1", x_units: }')))
    with pytest.raises(ToolCallError) as info:
        _chat(mock).call_tool("s", [Message.user("go")], None, move_tool(IDS))
    assert "not valid JSON" in info.value.feedback and "propose_move_instruction" in info.value.feedback
    assert info.value.raw == '{"object_id": "Sofa|1", x_units: }'


def test_non_object_arguments_raise_feedback():
    mock = Mock((200, srv.responses_tool_reply("propose_move_instruction", "[1, 2]")))
    with pytest.raises(ToolCallError, match="not an object"):
        _responses(mock).call_tool("s", [Message.user("go")], None, move_tool(IDS))


@pytest.mark.parametrize("api", ["responses", "chat"])
def test_answer_without_tool_call_raises_feedback(api):
    reply = srv.responses_text_reply("I would move the sofa.") if api == "responses" else \
        srv.chat_text_reply("I would move the sofa.")
    mock = Mock((200, reply))
    backend = _responses(mock) if api == "responses" else _chat(mock)
    with pytest.raises(ToolCallError, match="without a tool call") as info:
        backend.call_tool("s", [Message.user("go")], None, move_tool(IDS))
    assert "propose_move_instruction" in info.value.feedback
    assert info.value.raw == "I would move the sofa."
    assert backend.usage.calls == 1, "tokens of a bad answer are still counted"


def test_call_of_another_tool_is_rejected():
    mock = Mock((200, srv.chat_tool_reply("delete_everything", {})))
    with pytest.raises(ToolCallError, match="'delete_everything'") as info:
        _chat(mock).call_tool("s", [Message.user("go")], None, move_tool(IDS))
    Message.assistant(info.value.raw)  # the raw answer can always be replayed as a turn


def test_non_json_body_is_a_clear_error():
    def handler(request):
        return httpx2.Response(200, text="<html>proxy login</html>")
    backend = ChatCompletionsBackend(LLMConfig(provider="openai-compatible", base_url="http://127.0.0.1:9/v1"),
                                     http_client=httpx2.Client(transport=httpx2.MockTransport(handler)))
    with pytest.raises(LLMRequestError, match="not a JSON object"):
        backend.call_tool("s", [Message.user("go")], None, move_tool(IDS))


# ----- cache -----------------------------------------------------------------------------------


def test_cache_hit_makes_no_request_and_changed_image_does(tmp_path):
    mock = Mock((200, srv.responses_tool_reply("propose_move_instruction", MOVE)),
                (200, srv.responses_tool_reply("propose_move_instruction", {**MOVE, "x_units": 1})))
    backend = _responses(mock, cache_dir=tmp_path / "cache")
    turns = [Message.user("Move one object.")]
    first = backend.call_tool("s", turns, _png((1, 2, 3)), move_tool(IDS))
    again = backend.call_tool("s", turns, _png((1, 2, 3)), move_tool(IDS))
    assert len(mock.requests) == 1
    assert (first.cached, again.cached) == (False, True)
    assert again.arguments == first.arguments and again.usage == first.usage and again.model == first.model
    other = backend.call_tool("s", turns, _png((3, 2, 1)), move_tool(IDS))
    assert len(mock.requests) == 2 and other.arguments["x_units"] == 1
    # a fresh backend (a re-run) reads the same files
    rerun = _responses(Mock(), cache_dir=tmp_path / "cache")
    assert rerun.call_tool("s", turns, _png((1, 2, 3)), move_tool(IDS)).arguments == MOVE
    assert rerun.usage.snapshot()["calls"] == 0 and rerun.usage.cache_hits == 1
    files = sorted((tmp_path / "cache").rglob("*.json"))
    assert len(files) == 2
    for f in files:
        text = f.read_text()
        assert KEY not in text and "SECRET" not in text
        assert "base64" not in text, "images are keyed by hash, not stored"


def test_cache_key_covers_tool_model_and_temperature(tmp_path):
    replies = [(200, srv.chat_tool_reply("propose_move_instruction", MOVE)) for _ in range(4)]
    mock = Mock(*replies)
    base = dict(cache_dir=tmp_path)
    _chat(mock, **base).call_tool("s", [Message.user("go")], None, move_tool(IDS))
    _chat(mock, **base).call_tool("s", [Message.user("go")], None, move_tool(IDS[:1]))
    _chat(mock, model="other", **base).call_tool("s", [Message.user("go")], None, move_tool(IDS))
    _chat(mock, temperature=0.7, **base).call_tool("s", [Message.user("go")], None, move_tool(IDS))
    assert len(mock.requests) == 4


def test_parse_results_are_cached(tmp_path):
    mock = Mock((200, srv.chat_text_reply('{"success": true, "concerns": ["a"]}')))
    backend = _chat(mock, cache_dir=tmp_path)
    first = backend.parse("s", [Message.user("t")], _png(), Analysis)
    second = backend.parse("s", [Message.user("t")], _png(), Analysis)
    assert len(mock.requests) == 1 and second.cached and second.value == first.value


def test_bad_answers_are_not_cached(tmp_path):
    mock = Mock((200, srv.chat_text_reply("no tool")), (200, srv.chat_tool_reply("propose_move_instruction", MOVE)))
    backend = _chat(mock, cache_dir=tmp_path)
    with pytest.raises(ToolCallError):
        backend.call_tool("s", [Message.user("go")], None, move_tool(IDS))
    assert backend.call_tool("s", [Message.user("go")], None, move_tool(IDS)).arguments == MOVE
    assert len(mock.requests) == 2


def test_corrupt_cache_file_is_a_miss(tmp_path):
    mock = Mock((200, srv.chat_tool_reply("propose_move_instruction", MOVE)),
                (200, srv.chat_tool_reply("propose_move_instruction", MOVE)))
    backend = _chat(mock, cache_dir=tmp_path)
    backend.call_tool("s", [Message.user("go")], None, move_tool(IDS))
    (path,) = tmp_path.rglob("*.json")
    path.write_text("{not json")
    assert backend.call_tool("s", [Message.user("go")], None, move_tool(IDS)).cached is False
    assert len(mock.requests) == 2


# ----- token counting --------------------------------------------------------------------------


def test_token_counter_sums_calls_and_tracks_blocks(tmp_path):
    cached = srv.chat_tool_reply("propose_move_instruction", MOVE, prompt_tokens=200, completion_tokens=20)
    cached["usage"]["prompt_tokens_details"] = {"cached_tokens": 150}
    mock = Mock((200, srv.chat_tool_reply("propose_move_instruction", MOVE, prompt_tokens=100, completion_tokens=10)),
                (429, srv.error_body("slow down", "rate_limit_error")), (200, cached),
                (200, srv.chat_text_reply('{"success": true, "concerns": []}', prompt_tokens=50,
                                          completion_tokens=5)))
    backend = _chat(mock, [], cache_dir=tmp_path)
    backend.call_tool("s", [Message.user("one")], None, move_tool(IDS), role="G")
    with backend.track() as env_usage:
        backend.call_tool("s", [Message.user("two")], None, move_tool(IDS), role="verify")
        backend.parse("s", [Message.user("three")], None, Analysis, role="F")
        backend.call_tool("s", [Message.user("one")], None, move_tool(IDS), role="G")  # cache hit
    assert env_usage.snapshot() == {"input_tokens": 250, "output_tokens": 25, "cached_tokens": 150,
                                    "total_tokens": 275, "calls": 2, "retries": 1, "cache_hits": 1}
    assert backend.usage.snapshot() == {"input_tokens": 350, "output_tokens": 35, "cached_tokens": 150,
                                        "total_tokens": 385, "calls": 3, "retries": 1, "cache_hits": 1}
    roles = env_usage.to_dict()["by_role"]
    assert roles["verify"]["input_tokens"] == 200 and roles["verify"]["retries"] == 1
    assert roles["F"]["calls"] == 1 and roles["G"] == {**roles["G"], "calls": 0, "cache_hits": 1}
    assert [r.role for r in env_usage.records] == ["verify", "F", "G"]
    # cost: 350 input of which 150 cached at 0.10, 200 at 0.40, 35 output at 1.60 (USD per million)
    assert backend.usage.cost(Prices(0.40, 1.60, 0.10)) == pytest.approx((200 * 0.40 + 150 * 0.10 + 35 * 1.60) / 1e6)
    again = Usage.from_dict(env_usage.to_dict())
    assert again.snapshot() == env_usage.snapshot()
    copied = pickle.loads(pickle.dumps(env_usage))  # usage travels back from process/Ray workers
    assert copied.records == env_usage.records
    copied.add(CallRecord("G", Tokens.of(1, 1)))


def test_budget_stops_requests_before_they_are_sent():
    mock = Mock((200, srv.chat_tool_reply("propose_move_instruction", MOVE, prompt_tokens=100, completion_tokens=10)))
    backend = _chat(mock, max_tokens=100)
    backend.call_tool("s", [Message.user("one")], None, move_tool(IDS), role="G")
    with pytest.raises(BudgetExceeded, match="token budget of 100 is used up"):
        backend.call_tool("s", [Message.user("two")], None, move_tool(IDS), role="G")
    assert len(mock.bodies) == 1, "no request once the budget is used up"
    with pytest.raises(ConfigError, match="needs prices"):
        LLMConfig(max_cost=1.0).budget()
    priced = LLMConfig(max_cost=0.0005, price_in=0.4, price_out=1.6).budget()
    usage = Usage()
    usage.add(CallRecord("G", Tokens.of(1000, 10)))
    assert priced.exceeded(usage) is None
    usage.add(CallRecord("G", Tokens.of(1000, 10)))
    assert "cost budget" in priced.exceeded(usage)


def test_missing_usage_counts_as_zero():
    body = srv.chat_tool_reply("propose_move_instruction", MOVE)
    del body["usage"]
    mock = Mock((200, body))
    backend = _chat(mock)
    assert backend.call_tool("s", [Message.user("go")], None, move_tool(IDS)).usage.total_tokens == 0
    assert backend.usage.calls == 1


# ----- end to end against a local OpenAI-shaped server -----------------------------------------


@pytest.fixture
def no_proxy(monkeypatch):
    """Keep requests to 127.0.0.1 off any proxy configured in the environment."""
    for name in ("HTTP_PROXY", "HTTPS_PROXY", "ALL_PROXY", "http_proxy", "https_proxy", "all_proxy"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("NO_PROXY", "127.0.0.1,localhost")


def test_chat_backend_end_to_end_against_local_server(tmp_path, no_proxy):
    replies = {srv.CHAT_PATH: [(200, srv.chat_tool_reply("propose_move_instruction", MOVE)),
                               (200, srv.chat_text_reply('{"success": false, "concerns": ["loop"]}'))]}
    with srv.ScriptedLLMServer(replies, max_requests=5, timeout_s=20) as server:
        config = LLMConfig(provider="openai-compatible", base_url=server.url, model="llava", timeout_s=5,
                           cache_dir=tmp_path)
        backend = make_backend(config)
        assert isinstance(backend, ChatCompletionsBackend)
        with backend:
            move = backend.call_tool("sys", [Message.user("Move one object.")], _png(), move_tool(IDS))
            analysis = backend.parse("sys", [Message.user("Analyze.")], _png(), Analysis)
            cached = backend.call_tool("sys", [Message.user("Move one object.")], _png(), move_tool(IDS))
        assert move.arguments == MOVE and cached.cached
        assert analysis.value.concerns == ["loop"]
        assert [r.path for r in server.requests] == [srv.CHAT_PATH, srv.CHAT_PATH]
        first = server.requests[0]
        assert first.authorization == "Bearer not-needed"
        assert first.body["tool_choice"] == {"type": "function", "function": {"name": "propose_move_instruction"}}
        assert first.body["messages"][1]["content"][1]["image_url"]["url"].startswith("data:image/png;base64,")
        assert backend.usage.calls == 2
    assert server.stopped


def test_local_server_stops_after_max_requests(no_proxy):
    replies = {srv.CHAT_PATH: [(200, srv.chat_tool_reply("propose_move_instruction", MOVE))]}
    server = srv.ScriptedLLMServer(replies, max_requests=1, timeout_s=20).start()
    backend = ChatCompletionsBackend(LLMConfig(provider="openai-compatible", base_url=server.url, timeout_s=2,
                                               max_retries=0))
    backend.call_tool("s", [Message.user("go")], None, move_tool(IDS))
    server._thread.join(timeout=5)
    assert server.stopped
    with pytest.raises(LLMUnavailableError, match="could not connect|timed out"):
        backend.call_tool("s", [Message.user("again")], None, move_tool(IDS))
    backend.close()


def test_openai_key_is_not_sent_to_a_compatible_server(monkeypatch):
    """A compatible server never receives OPENAI_API_KEY unless the user names that variable."""
    monkeypatch.setenv("OPENAI_API_KEY", "sk-real-openai-key")
    monkeypatch.delenv("ADAPTENV_LLM_API_KEY", raising=False)
    cfg = LLMConfig(provider="openai-compatible", base_url="http://127.0.0.1:9/v1")
    assert resolve_api_key(cfg) == "not-needed"
    monkeypatch.setenv("ADAPTENV_LLM_API_KEY", "local-key")
    assert resolve_api_key(cfg) == "local-key"


# ----- waiting out loud: a line per failed attempt, the silent server ------------------------------


def test_each_failed_attempt_says_so_before_the_next(capsys):
    sleeps: list[float] = []
    mock = Mock(httpx2.ReadTimeout, httpx2.ReadTimeout, (200, srv.chat_tool_reply("propose_move_instruction", MOVE)))
    backend = _chat(mock, sleeps, max_retries=2, timeout_s=5)
    assert backend.call_tool("s", [Message.user("go")], None, move_tool(IDS)).arguments == MOVE
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 2 == len(sleeps)
    assert lines[0].startswith("LLM: attempt 1 of 3 at http://127.0.0.1:9/v1 failed (timed out after 5 s); attempt 2 in")
    assert lines[1].startswith("LLM: attempt 2 of 3 at http://127.0.0.1:9/v1 failed (timed out after 5 s); attempt 3 in")


def test_the_default_wait_is_documented_with_its_worst_case():
    from pathlib import Path

    cfg = LLMConfig(api_key=KEY)
    worst = cfg.timeout_s * (cfg.max_retries + 1) + sum(
        min(cfg.backoff_base_s * 2 ** k * 1.25, cfg.backoff_max_s) for k in range(cfg.max_retries))
    doc = (Path(__file__).parents[2] / "docs" / "llm.md").read_text(encoding="utf-8")
    assert f"{cfg.max_retries + 1} attempts of {cfg.timeout_s:g} s" in doc
    assert f"{worst:g} s" in doc


def test_a_server_that_never_answers_is_reported_attempt_by_attempt(no_proxy):
    """The real SDK against a socket on 127.0.0.1 that accepts connections (the kernel's backlog) and never
    answers: each timed-out attempt says so, then one error names the server and the fix."""
    import socket

    said: list[str] = []
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(8)
        url = f"http://127.0.0.1:{silent.getsockname()[1]}/v1"
        config = LLMConfig(provider="openai-compatible", base_url=url, timeout_s=0.2, max_retries=1,
                           backoff_base_s=0.0)
        with ChatCompletionsBackend(config, notify=said.append) as backend, \
                pytest.raises(LLMUnavailableError, match="timed out after 0.2 s") as info:
            backend.call_tool("s", [Message.user("go")], None, move_tool(IDS))
    assert said == [f"LLM: attempt 1 of 2 at {url} failed (timed out after 0.2 s); attempt 2 in 0.0 s"]
    assert url in str(info.value) and "2 attempt" in str(info.value)
