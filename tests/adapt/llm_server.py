"""A tiny OpenAI-shaped HTTP server on 127.0.0.1 for offline end-to-end tests of the LLM layer.

It answers POST /v1/chat/completions and /v1/responses with scripted replies (in order, per
path), records every request body, and stops itself after ``max_requests`` requests or
``timeout_s`` seconds, whichever comes first. The reply builders below are shared with the
mocked-transport tests.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

#: A scripted reply: (HTTP status, JSON body) or a function of the request body returning one.
Reply = tuple[int, dict[str, Any]] | Callable[[dict[str, Any]], tuple[int, dict[str, Any]]]

CHAT_PATH = "/v1/chat/completions"
RESPONSES_PATH = "/v1/responses"


@dataclass(frozen=True)
class Recorded:
    """One request the server saw: path, whether it carried an Authorization header, JSON body."""

    path: str
    authorization: str | None
    body: dict[str, Any]


class ScriptedLLMServer:
    """Serve scripted OpenAI-shaped replies on 127.0.0.1:<free port>; use as a context manager."""

    def __init__(self, replies: dict[str, list[Reply]], *, max_requests: int = 20, timeout_s: float = 20.0):
        self._replies = {path: list(rs) for path, rs in replies.items()}
        self.max_requests = max_requests
        self.requests: list[Recorded] = []
        self._lock = threading.Lock()
        self._server = ThreadingHTTPServer(("127.0.0.1", 0), self._handler_class())
        self._server.daemon_threads = True
        self._thread = threading.Thread(target=self._server.serve_forever, kwargs={"poll_interval": 0.05},
                                        daemon=True)
        self._timer = threading.Timer(timeout_s, self.stop)
        self._timer.daemon = True
        self._stopped = threading.Event()

    @property
    def url(self) -> str:
        """Base URL to give the backend (ends in /v1)."""
        return f"http://127.0.0.1:{self._server.server_address[1]}/v1"

    @property
    def stopped(self) -> bool:
        """True once the server has shut down."""
        return self._stopped.is_set()

    def start(self) -> ScriptedLLMServer:
        """Start serving in a daemon thread and arm the timeout."""
        self._thread.start()
        self._timer.start()
        return self

    def stop(self) -> None:
        """Shut down (idempotent; safe from any thread except the serving one)."""
        with self._lock:
            if self._stopped.is_set():
                return
            self._stopped.set()
        self._timer.cancel()
        self._server.shutdown()
        self._server.server_close()

    def __enter__(self) -> ScriptedLLMServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _next_reply(self, path: str, body: dict[str, Any]) -> tuple[int, dict[str, Any], bool]:
        """(status, body, stop_after) for one request."""
        with self._lock:
            count = len(self.requests)
            queue = self._replies.get(path)
            reply: Reply | None = queue.pop(0) if queue else None
        stop_after = count >= self.max_requests
        if count > self.max_requests:
            return 503, error_body("request limit of the test server reached", "server_error"), True
        if reply is None:
            return 404, error_body(f"no scripted reply left for {path}", "invalid_request_error"), stop_after
        status, payload = reply(body) if callable(reply) else reply
        return status, payload, stop_after

    def _handler_class(self) -> type[BaseHTTPRequestHandler]:
        owner = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802 - http.server naming
                length = int(self.headers.get("content-length") or 0)
                try:
                    body = json.loads(self.rfile.read(length) or b"{}")
                except json.JSONDecodeError:
                    body = {"_unparseable": True}
                with owner._lock:
                    owner.requests.append(Recorded(self.path, self.headers.get("authorization"), body))
                status, payload, stop_after = owner._next_reply(self.path, body)
                data = json.dumps(payload).encode("utf-8")
                self.send_response(status)
                self.send_header("content-type", "application/json")
                self.send_header("content-length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)
                if stop_after:
                    threading.Thread(target=owner.stop, daemon=True).start()

            def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - silence stderr
                return

        return Handler


def error_body(message: str, kind: str = "invalid_request_error") -> dict[str, Any]:
    """An OpenAI-style error body."""
    return {"error": {"message": message, "type": kind, "param": None, "code": None}}


def chat_tool_reply(name: str, arguments: dict[str, Any] | str, *, prompt_tokens: int = 11,
                    completion_tokens: int = 7, model: str = "test-model") -> dict[str, Any]:
    """A Chat Completions body whose message calls ``name`` with ``arguments``."""
    args = arguments if isinstance(arguments, str) else json.dumps(arguments)
    return {"id": "chatcmpl-1", "object": "chat.completion", "created": 0, "model": model,
            "choices": [{"index": 0, "finish_reason": "tool_calls",
                         "message": {"role": "assistant", "content": None,
                                     "tool_calls": [{"id": "call_1", "type": "function",
                                                     "function": {"name": name, "arguments": args}}]}}],
            "usage": {"prompt_tokens": prompt_tokens, "completion_tokens": completion_tokens,
                      "total_tokens": prompt_tokens + completion_tokens}}


def chat_text_reply(text: str, *, prompt_tokens: int = 11, completion_tokens: int = 7,
                    model: str = "test-model", finish_reason: str = "stop") -> dict[str, Any]:
    """A Chat Completions body with plain assistant text."""
    return {"id": "chatcmpl-2", "object": "chat.completion", "created": 0, "model": model,
            "choices": [{"index": 0, "finish_reason": finish_reason,
                         "message": {"role": "assistant", "content": text}}],
            "usage": {"prompt_tokens": prompt_tokens, "completion_tokens": completion_tokens,
                      "total_tokens": prompt_tokens + completion_tokens}}


def responses_tool_reply(name: str, arguments: dict[str, Any] | str, *, input_tokens: int = 13,
                         output_tokens: int = 5, model: str = "gpt-4.1-mini-2025-04-14") -> dict[str, Any]:
    """A Responses API body with one function_call output item."""
    args = arguments if isinstance(arguments, str) else json.dumps(arguments)
    return {"id": "resp_1", "object": "response", "created_at": 0, "model": model, "status": "completed",
            "output": [{"type": "function_call", "id": "fc_1", "call_id": "call_1", "name": name,
                        "arguments": args, "status": "completed"}],
            "usage": {"input_tokens": input_tokens, "output_tokens": output_tokens,
                      "total_tokens": input_tokens + output_tokens}}


def responses_text_reply(text: str, *, input_tokens: int = 13, output_tokens: int = 5,
                         model: str = "gpt-4.1-mini-2025-04-14") -> dict[str, Any]:
    """A Responses API body with one assistant message of output_text."""
    return {"id": "resp_2", "object": "response", "created_at": 0, "model": model, "status": "completed",
            "output": [{"type": "message", "id": "msg_1", "role": "assistant", "status": "completed",
                        "content": [{"type": "output_text", "text": text, "annotations": []}]}],
            "usage": {"input_tokens": input_tokens, "output_tokens": output_tokens,
                      "total_tokens": input_tokens + output_tokens}}
