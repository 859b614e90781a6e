"""The LLM generator and the LLM analyzer through the real openai SDK with a mocked HTTP transport."""

from __future__ import annotations

import json

import numpy as np

from adaptenv.adapt.analysis import LLMAnalyzer
from adaptenv.adapt.generators import GenerationContext
from adaptenv.adapt.generators.llm import SYSTEM_PROMPT, LLMGenerator
from adaptenv.adapt.llm import move_tool
from tests.adapt import llm_server as srv
from tests.adapt.llm_mock import Mock, move, poses, verify

IDS = ["GarbageCan|0", "Desk|1", "CoffeeTable|2"]
#: What G may move: the episode's target (a GarbageCan) is excluded by default.
MOVABLE = ["Desk|1", "CoffeeTable|2"]


def _run(llm_scene, mock: Mock, steps: int = 1, **kw):
    house, world, ep, traj, analysis = llm_scene
    ctx = GenerationContext(episode=ep, trajectory=traj, render_size=320)
    return LLMGenerator(mock.backend(), **kw).generate(house, analysis, steps=steps, context=ctx,
                                                       rng=np.random.default_rng(0))


def test_step_request_body_and_verification(llm_scene):
    house, world, ep, traj, analysis = llm_scene
    mock = Mock(move(), verify(True))
    res = _run(llm_scene, mock)
    first, second = mock.bodies
    assert first["messages"][0] == {"role": "system", "content": SYSTEM_PROMPT}
    user = first["messages"][1]
    assert [p["type"] for p in user["content"]] == ["text", "image_url"]
    assert user["content"][1]["image_url"]["url"].startswith("data:image/png;base64,")
    text = user["content"][0]["text"]
    assert analysis.to_text() in text and "rotation is the object's NEW absolute heading" in text
    assert "- CoffeeTable|2: CoffeeTable at x=" in text and "Desk|1" in text
    assert first["tools"] == [{"type": "function", "function": {
        "name": "propose_move_instruction", "description": move_tool(MOVABLE).description,
        "parameters": move_tool(MOVABLE).parameters, "strict": True}}]
    assert first["tools"][0]["function"]["parameters"]["properties"]["object_id"]["enum"] == MOVABLE
    assert "- GarbageCan|0:" not in text, "the episode's target is not offered to G"
    assert first["tool_choice"] == {"type": "function", "function": {"name": "propose_move_instruction"}}
    assert first["parallel_tool_calls"] is False
    assert second["tool_choice"] == {"type": "function", "function": {"name": "verify_move"}}
    last = second["messages"][-1]
    assert [p["type"] for p in last["content"]] == ["text", "image_url"]
    assert "Placement achieved: moved +" in last["content"][0]["text"]
    (step,) = res.steps
    assert step.status == "applied" and step.verified is True and step.revisions == 0 and step.attempts == 1
    assert step.edit.object_id == "CoffeeTable|2" and step.edit.achieved_dx_units > 0
    assert res.usage.calls == 2 and res.usage.total_tokens == 36
    assert [r.role for r in res.usage.records] == ["G", "verify"]
    assert len(res.renders) == 1 and poses(house) != poses(res.house)


def test_unknown_id_is_sent_back_and_the_retry_succeeds(llm_scene):
    mock = Mock(move(oid="Sofa|9"), move(), verify(True))
    res = _run(llm_scene, mock)
    retry = mock.bodies[1]["messages"]
    assert retry[-2]["role"] == "assistant" and "Sofa|9" in retry[-2]["content"]
    assert retry[-1]["role"] == "user" and "object_id 'Sofa|9' is not allowed" in retry[-1]["content"]
    assert res.steps[0].status == "applied" and res.steps[0].attempts == 2


def test_three_bad_answers_skip_the_step_and_the_loop_goes_on(llm_scene):
    house = llm_scene[0]
    mock = Mock(move(oid="Nope"), move(xu="far"), (200, srv.chat_text_reply("I would move the sofa.")),
                move(), verify(True))
    res = _run(llm_scene, mock, steps=2)
    skipped, applied = res.steps
    assert skipped.status == "skipped" and skipped.attempts == 3 and skipped.edit is None
    assert "no valid move after 3 answers" in skipped.reason
    assert applied.status == "applied" and len(res.edit_log) == 1
    assert poses(res.house) != poses(house)


def test_revise_replaces_the_move_from_the_scene_before_it(llm_scene):
    house = llm_scene[0]
    revised = {"object_id": "Desk|1", "x_direction": "right", "x_units": 4.0, "y_direction": "up", "y_units": 0.0,
               "rotation": 90.0}
    mock = Mock(move(), verify(False, revised), verify(True))
    res = _run(llm_scene, mock)
    (step,) = res.steps
    assert step.status == "applied" and step.revisions == 1 and step.verified is True
    assert [e.object_id for e in res.edit_log] == ["CoffeeTable|2", "Desk|1"]
    before, after = poses(house), poses(res.house)
    assert after["CoffeeTable|2"] == before["CoffeeTable|2"], "the first attempt must be undone"
    assert after["Desk|1"] != before["Desk|1"]


def test_revise_without_a_revised_move_asks_for_a_new_one(llm_scene):
    mock = Mock(move(), verify(False), move(oid="Desk|1", xu=3.0, rot=90.0), verify(True))
    res = _run(llm_scene, mock)
    assert mock.bodies[2]["tool_choice"]["function"]["name"] == "propose_move_instruction"
    assert "replaces the previous one" in mock.bodies[2]["messages"][-1]["content"]
    assert res.steps[0].revisions == 1 and res.steps[0].edit.object_id == "Desk|1"


def test_revisions_are_bounded(llm_scene):
    mock = Mock(move(), verify(False), move(xu=2.0), verify(False), move(xu=1.0), verify(False))
    res = _run(llm_scene, mock, max_revisions=2)
    step = res.steps[0]
    assert step.revisions == 2 and step.verified is False and step.status == "applied"
    assert not mock.replies


def test_malformed_json_never_raises(llm_scene):
    bad = (200, srv.chat_tool_reply("propose_move_instruction", '{"object_id": "Desk|1", '))
    mock = Mock(bad, bad, bad)
    res = _run(llm_scene, mock)
    assert res.steps[0].status == "skipped" and "not valid JSON" in res.steps[0].reason
    assert "were not valid JSON" in mock.bodies[1]["messages"][-1]["content"]


def test_server_down_ends_the_run_with_a_reason(llm_scene):
    mock = Mock((500, srv.error_body("boom", "server_error")))
    house, world, ep, traj, analysis = llm_scene
    gen = LLMGenerator(mock.backend(max_retries=0))
    res = gen.generate(house, analysis, steps=3, context=GenerationContext(episode=ep, trajectory=traj, render_size=320),
                       rng=np.random.default_rng(0))
    assert len(res.steps) == 1 and res.steps[0].reason.startswith("LLM unavailable")


# ----------------------------------------------------------------------------- the LLM analyzer

ANSWER = {"outcome": {"success": False, "failure_mode": "timeout", "summary": "kept circling the corridor"},
          "concerns": [{"kind": "collision", "severity": 0.7, "description": "bumped the desk", "grid_x": 20.0,
                        "grid_y": 30.0, "objects": ["Desk|1", "Ghost|7"]},
                       {"kind": "detour", "severity": 1.4, "description": "long loop", "grid_x": None,
                        "grid_y": None, "objects": []}],
          "suggestions": [{"kind": "add_clutter", "description": "more obstacles near the corridor",
                           "addresses": [2], "priority": 0.4},
                          {"kind": "narrow_passage", "description": "tighter passage by the desk",
                           "addresses": [1, 5], "priority": 0.9}]}


def test_llm_analyzer_sends_the_render_and_converts_the_answer(llm_scene):
    house, world, ep, traj, _ = llm_scene
    mock = Mock((200, srv.chat_text_reply("not json")), (200, srv.chat_text_reply(json.dumps(ANSWER))))
    a = LLMAnalyzer(mock.backend(), image_size=320).analyze(traj, world)
    body = mock.bodies[0]
    assert body["response_format"]["type"] == "json_schema"
    parts = body["messages"][1]["content"]
    assert [p["type"] for p in parts] == ["text", "image_url"] and "find a GarbageCan" in parts[0]["text"]
    assert "did not match" in mock.bodies[1]["messages"][-1]["content"]
    assert a.source == "llm" and a.outcome.failure_mode == "timeout" and not a.outcome.success
    assert [c.id for c in a.concerns] == ["c1", "c2"]
    assert a.concerns[0].objects == ["Desk|1"] and a.concerns[0].where.x == 20.0
    assert a.concerns[1].severity == 1.0 and a.concerns[1].where is None
    assert [s.kind for s in a.suggestions] == ["narrow_passage", "add_clutter"]
    assert a.suggestions[0].addresses == ["c1"] and a.suggestions[1].addresses == ["c2"]


def test_llm_analyzer_falls_back_to_builtin(llm_scene):
    house, world, ep, traj, analysis = llm_scene
    bad = (200, srv.chat_text_reply("{}"))
    a = LLMAnalyzer(Mock(bad, bad, bad).backend(), image_size=320).analyze(traj, world)
    assert a.source == "builtin-fallback" and a.concerns == analysis.concerns


def test_invalid_verification_answers_leave_the_edit_unverified(llm_scene):
    bad = (200, srv.chat_tool_reply("verify_move", {"matches_intent": "yes"}))
    res = _run(llm_scene, Mock(move(), bad, bad, bad))
    step = res.steps[0]
    assert step.status == "applied" and step.verified is None and "verification skipped" in step.reason


def test_g_with_door_edits_offers_both_tools_and_opens_a_shut_door():
    from adaptenv.adapt.analysis import analyze_trajectory
    from adaptenv.adapt.edits import replay
    from adaptenv.agents.policy import ExpertPolicy
    from adaptenv.agents.rollout import draw_episode, rollout
    from adaptenv.scene.procedural import GenerationConfig, generate_house
    from adaptenv.scene.procedural.checks import closed_interior_doors
    from adaptenv.sim.world import compile_world

    house = generate_house(0, GenerationConfig(n_rooms=6, closed_door_prob=0.4))
    world = compile_world(house, "h")
    ep = draw_episode(world, np.random.default_rng([1, 1]))
    traj = rollout(world, ep, ExpertPolicy())
    shut = closed_interior_doors(house)
    mock = Mock((200, srv.chat_tool_reply("set_door_openness", {"door_id": "door|2|5", "open": True})), verify(True))
    ctx = GenerationContext(episode=ep, trajectory=traj, render_size=320)
    res = LLMGenerator(mock.backend(), door_edits=True).generate(house, analyze_trajectory(traj, world), steps=1,
                                                                 context=ctx, rng=np.random.default_rng(0))
    first, second = mock.bodies
    assert [t["function"]["name"] for t in first["tools"]] == ["propose_move_instruction", "set_door_openness"]
    assert first["tool_choice"] == "required"
    assert "door|2|5" in shut and "- door|2|5: between room|2 and room|5, shut" in first["messages"][1]["content"][0]["text"]
    assert "door door|2|5 is now open (it was shut)" in second["messages"][-1]["content"][0]["text"]
    (step,) = res.steps
    assert step.status == "applied" and step.verified is True and step.edit.is_door and step.edit.openness == 1.0
    assert set(closed_interior_doors(res.house)) == set(shut) - {"door|2|5"}
    assert replay(house, res.edit_log).model_dump() == res.house.model_dump()
    plain = Mock(move(oid="Sofa|9"))
    LLMGenerator(plain.backend(), max_attempts=1).generate(house, analyze_trajectory(traj, world), steps=1,
                                                          context=ctx, rng=np.random.default_rng(0))
    assert len(plain.bodies[0]["tools"]) == 1, "without door_edits G has the paper's move tool only"
