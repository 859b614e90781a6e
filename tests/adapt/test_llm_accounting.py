"""Honest accounting of the LLM G: the house holds exactly the edits the log marks applied, whatever the server does.

Also: no-op moves, recorded clamps, the episode's targets, the paper's prompts, and F's token counts.
"""

from __future__ import annotations

import json
import threading

import numpy as np
import pytest

from adaptenv.adapt.analysis import LLMAnalyzer
from adaptenv.adapt.edits import replay
from adaptenv.adapt.generators import GenerationContext
from adaptenv.adapt.generators.llm import LLMGenerator
from adaptenv.adapt.llm import ChatCompletionsBackend, LLMConfig
from adaptenv.adapt.llm.prompts import PAPER_F_PROMPT, PAPER_G_PROMPT
from tests.adapt import llm_mock
from tests.adapt import llm_server as srv
from tests.adapt.llm_mock import move, poses, verify

FAIL = (500, srv.error_body("the server fell over", "server_error"))


class Mock(llm_mock.Mock):
    """No retries: a scripted failure is final."""

    defaults = {"max_retries": 0}


REVISED = {"object_id": "Desk|1", "x_direction": "right", "x_units": 4.0, "y_direction": "up", "y_units": 0.0,
           "rotation": 90.0}


def _generate(llm_scene, backend, steps=1, **kw):
    house, world, ep, traj, analysis = llm_scene
    ctx = GenerationContext(episode=ep, trajectory=traj, render_size=256)
    return LLMGenerator(backend, **kw).generate(house, analysis, steps=steps, context=ctx, rng=np.random.default_rng(0))


def assert_house_matches_log(house, res) -> None:
    """The house holds exactly the edits whose steps say applied, and replaying the edit log gives it too."""
    applied = [s.edit for s in res.steps if s.status == "applied"]
    assert poses(res.house) == poses(replay(house, applied))
    assert poses(res.house) == poses(replay(house, res.edit_log))
    assert all(s.verified is None for s in res.steps if s.status != "applied")


# Each script fails (HTTP 500, no retries) at another point of one step.
FAILURE_POINTS = {
    "first move request": [FAIL],
    "verification": [move(), FAIL],
    "move after a rejected verification": [move(), verify(False), FAIL],
    "verification of a revised move": [move(), verify(False, REVISED), FAIL],
    "second step's verification": [move(), verify(True), move(oid="Desk|1", xd="left", xu=6.0), FAIL],  # to its wall
}


@pytest.mark.parametrize("point", list(FAILURE_POINTS))
def test_a_server_failure_at_any_point_leaves_house_and_log_in_agreement(llm_scene, point):
    house = llm_scene[0]
    res = _generate(llm_scene, Mock(*FAILURE_POINTS[point]).backend(), steps=3)
    assert_house_matches_log(house, res)
    assert res.stopped.startswith("LLM unavailable") and res.steps[-1].status == "skipped"
    if point == "second step's verification":
        assert [s.status for s in res.steps] == ["applied", "skipped"]
        assert poses(res.house)["CoffeeTable|2"] != poses(house)["CoffeeTable|2"]
    else:
        assert poses(res.house) == poses(house), "the unfinished step's edit must be undone"
    if point != "first move request":
        assert "this step's edit was undone" in res.steps[-1].reason
        assert res.edit_log.edits[-1].undone or not res.edit_log.edits[-1].changed


def test_killing_the_server_mid_verification(llm_scene):
    """The real SDK against a loopback server that shuts itself down when asked to verify."""
    house = llm_scene[0]
    holder: dict = {}

    def die(body):
        threading.Thread(target=holder["server"].stop, daemon=True).start()
        return FAIL

    with srv.ScriptedLLMServer({srv.CHAT_PATH: [move(), die]}, max_requests=10, timeout_s=60) as server:
        holder["server"] = server
        cfg = LLMConfig(provider="openai-compatible", base_url=server.url, model="vlm", max_retries=2,
                        backoff_base_s=0.01, timeout_s=5)
        res = _generate(llm_scene, ChatCompletionsBackend(cfg), steps=2)
    assert_house_matches_log(house, res)
    assert poses(res.house) == poses(house) and [s.status for s in res.steps] == ["skipped"]
    assert server.url.removesuffix("/v1") in res.stopped, "the error names the server actually used"
    assert res.usage.calls == 1 and res.usage.records[0].role == "G"


def test_zero_move_with_unchanged_heading_is_a_noop_asked_once_more(llm_scene):
    house = llm_scene[0]
    yaw = next(o.rotation.y for o in house.objects if o.id == "CoffeeTable|2") % 360
    mock = Mock(move(xu=0.0, rot=yaw), move(xu=0.0, rot=yaw))
    res = _generate(llm_scene, mock.backend())
    (step,) = res.steps
    assert step.status == "no-op" and step.verified is None and not res.applied
    assert "changed nothing" in mock.bodies[1]["messages"][-1]["content"]
    assert not mock.replies and len(mock.bodies) == 2, "re-asked exactly once, never verified"
    assert_house_matches_log(house, res)


def test_clamped_answers_are_recorded_in_the_edit_log(llm_scene):
    res = _generate(llm_scene, Mock(move(xu=150.0, rot=-90.0), verify(True)).backend())
    intent = res.steps[0].edit.intent
    assert "clamped: x_units 150 -> 100, rotation -90 -> 270" in intent
    assert res.edit_log.edits[0].dx_units == 100.0


def test_targets_only_with_allow_target_moves(llm_scene):
    mock = Mock(move(oid="GarbageCan|0"), move(), verify(True))
    res = _generate(llm_scene, mock.backend())
    assert "GarbageCan|0" not in mock.bodies[0]["tools"][0]["function"]["parameters"]["properties"]["object_id"]["enum"]
    assert res.steps[0].attempts == 2 and res.steps[0].edit.object_id == "CoffeeTable|2"
    allowed = Mock(move(oid="GarbageCan|0"), verify(True))
    res = _generate(llm_scene, allowed.backend(allow_target_moves=True))
    assert res.steps[0].edit.object_id == "GarbageCan|0" and res.steps[0].attempts == 1


def test_paper_prompts_are_sent_verbatim(llm_scene):
    house, world, ep, traj, analysis = llm_scene
    mock = Mock(move(), verify(True))
    _generate(llm_scene, mock.backend(prompts="paper"))
    first = mock.bodies[0]["messages"]
    assert first[0]["role"] == "user", "the paper's G has no system message"
    assert first[0]["content"][0]["text"] == PAPER_G_PROMPT.format(analysis=analysis.to_text())
    answer = {"outcome": {"success": True, "failure_mode": None, "summary": "reached it"}, "concerns": [],
              "suggestions": [{"kind": "narrow_passage", "description": "tighter", "addresses": [],
                               "priority": 0.5}]}
    f_mock = Mock((200, srv.chat_text_reply(json.dumps(answer), prompt_tokens=900, completion_tokens=80)))
    a = LLMAnalyzer(f_mock.backend(prompts="paper"), image_size=256).analyze(traj, world)
    msgs = f_mock.bodies[0]["messages"]
    assert msgs[0]["role"] == "user" and msgs[0]["content"][0]["text"] == PAPER_F_PROMPT
    schema = f_mock.bodies[0]["response_format"]["json_schema"]["schema"]
    assert {"outcome", "concerns", "suggestions"} <= set(schema["properties"])
    assert a.outcome.success and a.usage["calls"] == 1 and a.usage["by_role"]["F"]["input_tokens"] == 900
