"""Provider-neutral conversation pieces (Message, ToolSpec) and their mapping to both OpenAI APIs.

F and G build conversations from :class:`Message` only; this module turns them into Responses API
``input`` items or Chat Completions ``messages``, so a prompt is written once for every server.
"""

from __future__ import annotations

import base64
import hashlib
from dataclasses import dataclass, field
from typing import Any, Literal

Role = Literal["user", "assistant"]

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@dataclass(frozen=True)
class Message:
    """One conversation turn: a role, its text and optionally one PNG image (user turns only).

    Example: ``[Message.user("Move one object.", png), Message.assistant(raw), Message.user(fix)]``.
    """

    role: Role
    text: str = ""
    image_png: bytes | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.role not in ("user", "assistant"):
            raise ValueError(f"Message role must be 'user' or 'assistant', got {self.role!r}")
        if self.image_png is not None:
            if self.role != "user":
                raise ValueError("only user messages can carry an image")
            check_png(self.image_png)
        if not self.text and self.image_png is None:
            raise ValueError("a Message needs text or an image")

    @classmethod
    def user(cls, text: str = "", image_png: bytes | None = None) -> Message:
        """A user turn (prompt, error feedback, or a newly rendered view)."""
        return cls("user", text, image_png)

    @classmethod
    def assistant(cls, text: str) -> Message:
        """An earlier model answer, replayed as text (e.g. the rejected tool arguments)."""
        return cls("assistant", text)

    def fingerprint(self) -> dict[str, Any]:
        """JSON-able identity of this turn for cache keys (image by SHA-256, not by bytes)."""
        image = hashlib.sha256(self.image_png).hexdigest() if self.image_png is not None else None
        return {"role": self.role, "text": self.text, "image_sha256": image}


@dataclass(frozen=True)
class ToolSpec:
    """A function tool: name, description and JSON-schema parameters (``strict`` = Structured Outputs)."""

    name: str
    description: str
    parameters: dict[str, Any]
    strict: bool = True

    def as_dict(self) -> dict[str, Any]:
        """Plain-dict form (the paper's flat layout), used for cache keys and documentation."""
        return {"type": "function", "name": self.name, "description": self.description,
                "parameters": self.parameters, "strict": self.strict}

    def responses_param(self) -> dict[str, Any]:
        """Responses API tool: flat ``{"type": "function", "name", ...}``."""
        return self.as_dict()

    def chat_param(self) -> dict[str, Any]:
        """Chat Completions tool: the function nested under ``"function"``."""
        return {"type": "function", "function": {"name": self.name, "description": self.description,
                                                 "parameters": self.parameters, "strict": self.strict}}


def check_png(data: bytes) -> None:
    """Raise ValueError unless ``data`` starts with the PNG signature (catches paths and JPEGs early)."""
    if not isinstance(data, (bytes, bytearray)) or not bytes(data[:8]) == PNG_SIGNATURE:
        raise ValueError("image_png must be the bytes of a PNG file (render with format='png')")


def png_data_url(data: bytes) -> str:
    """A ``data:image/png;base64,...`` URL, the form both APIs accept for inline images."""
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def with_image(messages: list[Message], image_png: bytes | None) -> list[Message]:
    """Attach ``image_png`` to the last user turn, or append it as a new user turn if that has one."""
    msgs = list(messages)
    if not msgs:
        raise ValueError("a conversation needs at least one message")
    if image_png is None:
        return msgs
    last = msgs[-1]
    if last.role == "user" and last.image_png is None:
        msgs[-1] = Message.user(last.text, image_png)
    else:
        msgs.append(Message.user("", image_png))
    return msgs


def to_responses_input(messages: list[Message], *, detail: str = "auto") -> list[dict[str, Any]]:
    """Responses API ``input``: user parts are input_text/input_image, assistant turns plain text."""
    items: list[dict[str, Any]] = []
    for msg in messages:
        if msg.role == "assistant":
            items.append({"role": "assistant", "content": msg.text})
            continue
        parts: list[dict[str, Any]] = []
        if msg.text:
            parts.append({"type": "input_text", "text": msg.text})
        if msg.image_png is not None:
            parts.append({"type": "input_image", "image_url": png_data_url(msg.image_png), "detail": detail})
        items.append({"role": "user", "content": parts})
    return items


def to_chat_messages(system: str, messages: list[Message]) -> list[dict[str, Any]]:
    """Chat Completions ``messages``: system first; a user turn with an image becomes text + image_url parts."""
    out: list[dict[str, Any]] = [{"role": "system", "content": system}] if system else []
    for msg in messages:
        if msg.image_png is None:
            out.append({"role": msg.role, "content": msg.text})
            continue
        parts: list[dict[str, Any]] = []
        if msg.text:
            parts.append({"type": "text", "text": msg.text})
        parts.append({"type": "image_url", "image_url": {"url": png_data_url(msg.image_png)}})
        out.append({"role": "user", "content": parts})
    return out
