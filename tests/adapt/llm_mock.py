"""Scripted OpenAI-shaped replies through a mocked httpx2 transport (no socket), shared by the LLM G and F tests."""

from __future__ import annotations

import json
from typing import Any, ClassVar

import httpx2

from adaptenv.adapt.llm import ChatCompletionsBackend, LLMConfig
from tests.adapt import llm_server as srv


class Mock:
    """Scripted httpx2 replies in order (a callable reply gets the request body); records every body."""

    defaults: ClassVar[dict[str, Any]] = {}
    """LLMConfig fields every backend of this mock gets (a test's own fields win)."""

    def __init__(self, *replies):
        self.replies = list(replies)
        self.bodies: list[dict] = []

    def __call__(self, request: httpx2.Request) -> httpx2.Response:
        self.bodies.append(json.loads(request.content))
        status, body = self.replies.pop(0)
        return httpx2.Response(status, json=body)

    def backend(self, **cfg) -> ChatCompletionsBackend:
        config = LLMConfig(provider="openai-compatible", base_url="http://127.0.0.1:9/v1", model="vlm",
                           **{**self.defaults, **cfg})
        return ChatCompletionsBackend(config, http_client=httpx2.Client(transport=httpx2.MockTransport(self)),
                                      sleep=lambda s: None)


def move(oid="CoffeeTable|2", xd="right", xu=5.0, yd="up", yu=0.0, rot=0.0) -> tuple[int, dict]:
    """G's proposal: a ``propose_move_instruction`` tool call."""
    return 200, srv.chat_tool_reply("propose_move_instruction", {
        "object_id": oid, "x_direction": xd, "x_units": xu, "y_direction": yd, "y_units": yu, "rotation": rot})


def verify(ok: bool, revised: dict | None = None) -> tuple[int, dict]:
    """G's verification of the rendered edit: a ``verify_move`` tool call."""
    return 200, srv.chat_tool_reply("verify_move", {"matches_intent": ok, "reason": "looks right" if ok else "no",
                                                    "revised_move": revised})


def poses(house) -> dict:
    """Every object's (x, z, yaw), rounded: equal dicts mean the same arrangement."""
    return {o.id: (round(o.position.x, 6), round(o.position.z, 6), round(o.rotation.y, 6)) for o in house.objects}
