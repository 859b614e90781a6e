"""ours-llm in the loop and the experiment against a loopback server: usage recorded, budgets, no key ever written."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from adaptenv.curriculum.experiment import ExperimentConfig, run_experiment
from adaptenv.curriculum.llm_usage import LEDGER, UsageLedger
from adaptenv.curriculum.loop import LoopConfig, run_loop
from adaptenv.curriculum.records import read_iterations
from adaptenv.errors import ConfigError
from adaptenv.report.html import build_report
from tests.adapt import llm_server as srv

KEY = "sk-loop-SECRET-9876543210fedcba"
F_ANSWER = {"outcome": {"success": True, "failure_mode": None, "summary": "reached it"}, "concerns": [],
            "suggestions": [{"kind": "narrow_passage", "description": "tighter", "addresses": [], "priority": 0.9}]}


def answer(body: dict) -> tuple[int, dict]:
    """Any request of F or G: F's analysis, the first allowed object moved right, or 'matches'."""
    tools = body.get("tools") or []
    if not tools:
        return 200, srv.chat_text_reply(json.dumps(F_ANSWER), prompt_tokens=1000, completion_tokens=100)
    fn = tools[0]["function"]
    if fn["name"] == "propose_move_instruction":
        oid = fn["parameters"]["properties"]["object_id"]["enum"][0]
        return 200, srv.chat_tool_reply(fn["name"], {"object_id": oid, "x_direction": "right", "x_units": 3,
                                                     "y_direction": "up", "y_units": 2, "rotation": 90},
                                        prompt_tokens=800, completion_tokens=40)
    return 200, srv.chat_tool_reply("verify_move", {"matches_intent": True, "reason": "ok", "revised_move": None},
                                    prompt_tokens=900, completion_tokens=30)


@pytest.fixture
def server(monkeypatch):
    for name in ("HTTP_PROXY", "HTTPS_PROXY", "ALL_PROXY", "http_proxy", "https_proxy", "all_proxy"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("NO_PROXY", "127.0.0.1,localhost")
    monkeypatch.setenv("MY_LLM_KEY", KEY)
    with srv.ScriptedLLMServer({srv.CHAT_PATH: [answer] * 400}, max_requests=400, timeout_s=600) as s:
        yield s


def llm_loop(policy: Path, server, **llm) -> dict:
    return dict(method="ours-llm", policy=str(policy), houses="preset:tiny", heldout={"tiny": "preset:tiny"},
                finetune_algo="dagger", finetune_max_steps=300, finetune_min_start=0.0,
                iterations=2, scenes_per_iteration=2, edit_steps=1, finetune_frames=256, finetune_envs=8,
                heldout_episodes=1, gallery=1, diagnose_episodes=1,
                llm={"provider": "openai-compatible", "base_url": server.url if server else "", "model": "vlm",
                     "api_key_env": "MY_LLM_KEY", "price_in": 0.4, "price_out": 1.6, **llm})


def files_holding(folder: Path, secret: str) -> list[str]:
    return [str(p) for p in folder.rglob("*") if p.is_file() and secret.encode() in p.read_bytes()]


def test_a_key_in_a_run_config_is_refused_before_anything_is_saved(tmp_path, tiny_policy):
    cfg = LoopConfig(method="ours-llm", policy=str(tiny_policy), llm={"base_url": "http://127.0.0.1:9/v1",
                                                                      "api_key": KEY})
    with pytest.raises(ConfigError, match="loop config: llm: field api_key holds an API key") as info:
        run_loop(cfg, tmp_path / "run")
    assert KEY not in str(info.value) and not (tmp_path / "run").exists()
    path = tmp_path / "exp.json"
    path.write_text(json.dumps({"methods": ["ours-llm"], "seeds": [0], "loop": {"llm": {"api_key": KEY}}}))
    with pytest.raises(ConfigError, match="exp.json: loop.llm: field api_key") as info:
        ExperimentConfig.load(path)
    assert KEY not in str(info.value)
    with pytest.raises(ConfigError, match="experiment config: loop.llm"):
        run_experiment(ExperimentConfig(methods=["ours-llm"], seeds=[0], loop={"llm": {"api_key": KEY}}),
                       tmp_path / "exp")
    assert not (tmp_path / "exp").exists()


@pytest.mark.slow
def test_llm_experiment_records_usage_never_writes_the_key_and_takes_one_heldout_episode(tmp_path, tiny_policy,
                                                                                         server):
    loop = llm_loop(tiny_policy, server)
    loop.pop("method")
    cfg = ExperimentConfig(methods=["ours-llm"], seeds=[0], reference="ours-llm", loop=loop)
    summary = run_experiment(cfg, tmp_path)
    run = tmp_path / "ours-llm" / "seed_0"
    assert files_holding(tmp_path, KEY) == [], "the key is in no file the experiment wrote"
    for name in ("experiment.json", "ours-llm/seed_0/run.json", "ours-llm/seed_0/state.json"):
        assert "MY_LLM_KEY" in (tmp_path / name).read_text(), f"{name} names the key's variable"
    assert all(r.authorization == f"Bearer {KEY}" for r in server.requests), "the key is sent, only to the server"
    # every request counted once, per iteration and in the ledger, by role
    recs = read_iterations(run)
    ledger = UsageLedger.read(run)
    assert sum(r.llm_usage["calls"] for r in recs[1:]) == ledger.total["calls"] == len(server.requests)
    assert ledger.total["input_tokens"] == sum(1000 if not r.body.get("tools") else
                                               800 if r.body["tools"][0]["function"]["name"] != "verify_move"
                                               else 900 for r in server.requests)
    assert set(ledger.total["by_role"]) == {"F", "G", "verify"} and ledger.total["cost_usd"] > 0
    assert ledger.llm["model"] == "vlm" and ledger.llm["base_url"] == server.url
    # one held-out episode: no standard error, shown as n/a, and the run does not crash
    assert recs[-1].heldout["tiny"].episodes == 1 and recs[-1].heldout["tiny"].success_se is None
    assert "n/a" in (tmp_path / "summary.md").read_text() and summary["methods"]["ours-llm"]


@pytest.mark.slow
def test_loop_stops_at_its_token_budget_and_resumes_with_a_larger_one(tmp_path, tiny_policy, server):
    cfg = LoopConfig(**llm_loop(tiny_policy, server, max_tokens=1000))
    lines: list[str] = []
    records = run_loop(cfg, tmp_path, progress=lines.append)
    assert [r.iteration for r in records] == [0, 1], "stopped cleanly after the iteration that used the budget"
    assert any("stopping before t=2: the token budget of 1,000 is used up" in x for x in lines)
    assert any(x.startswith("t=1: LLM so far:") for x in lines)
    assert any("G stopped early: budget used up: the token budget" in x for x in lines), "one line per scene says why"
    made = len(server.requests)
    bigger = LoopConfig(**llm_loop(tiny_policy, server, max_tokens=10**7))
    records = run_loop(bigger, tmp_path, resume=True)
    assert [r.iteration for r in records] == [0, 1, 2] and len(server.requests) > made
    assert json.loads((tmp_path / LEDGER).read_text())["iterations"].keys() == {"1", "2"}
    html = build_report(tmp_path, tmp_path / "report").read_text()
    assert "LLM usage per iteration" in html and "<td>F</td>" in html and "<td>G</td>" in html and "$0.00" in html


@pytest.mark.slow
def test_a_second_identical_loop_replays_from_the_cache_without_requests(tmp_path, tiny_policy, server):
    cache = str(tmp_path / "cache")
    first = run_loop(LoopConfig(**llm_loop(tiny_policy, server, cache_dir=cache)), tmp_path / "a")
    made = len(server.requests)
    assert made > 0
    server.stop()  # the replay must come from the cache alone
    again = run_loop(LoopConfig(**llm_loop(tiny_policy, server, cache_dir=cache)), tmp_path / "b")
    assert len(server.requests) == made
    scenes = sorted(p.name for p in (tmp_path / "a" / "scenes").iterdir())
    assert scenes == sorted(p.name for p in (tmp_path / "b" / "scenes").iterdir())
    assert all((tmp_path / "a" / "scenes" / n).read_text() == (tmp_path / "b" / "scenes" / n).read_text()
               for n in scenes)
    replay = UsageLedger.read(tmp_path / "b").total
    assert replay["calls"] == 0 and replay["cache_hits"] == made
    assert [r.edits for r in again] == [r.edits for r in first]


@pytest.mark.slow
def test_an_unreachable_llm_stops_the_run_with_one_clear_error(tmp_path, tiny_policy, monkeypatch):
    import socket

    from adaptenv.adapt.llm import LLMUnavailableError

    monkeypatch.setenv("MY_LLM_KEY", KEY)
    with socket.socket() as s:  # a loopback port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cfg = LoopConfig(**{**llm_loop(tiny_policy, None), "llm": {
        "provider": "openai-compatible", "base_url": f"http://127.0.0.1:{port}/v1", "model": "vlm",
        "api_key_env": "MY_LLM_KEY", "max_retries": 0, "timeout_s": 5}})
    with pytest.raises(LLMUnavailableError) as info:
        run_loop(cfg, tmp_path)
    assert "\n" not in str(info.value) and f"127.0.0.1:{port}" in str(info.value)
    assert [r.iteration for r in read_iterations(tmp_path)] == [0], "no iteration is recorded as if the LLM had run"
