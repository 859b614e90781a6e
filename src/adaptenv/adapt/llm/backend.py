"""LLM backends for F and G: one forced tool call or one structured answer per request.

Two implementations share the :class:`LLMBackend` protocol and everything around the HTTP call
(bounded retries with seeded jitter, the response cache, token counting, error mapping):

* :class:`OpenAIResponsesBackend` speaks the OpenAI Responses API (``api="responses"``, the default
  of ``provider="openai"``);
* :class:`ChatCompletionsBackend` speaks Chat Completions, which vLLM, Ollama and llama.cpp serve
  (``api="chat"``, the default of ``provider="openai-compatible"``).

Both drive the real ``openai`` SDK (imported lazily) with its own retries off, and read the JSON
body of every answer themselves, so a server that returns a slightly unusual shape still yields a
clear :class:`ModelAnswerError` whose ``feedback`` the caller can send back to the model.
"""

from __future__ import annotations

import json
import logging
import math
import re
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any, Generic, Protocol, TypeVar

import numpy as np
from pydantic import BaseModel, ValidationError

from adaptenv.adapt.llm.cache import ResponseCache, request_key
from adaptenv.adapt.llm.config import PLACEHOLDER_KEY, LLMConfig, resolve_api_key
from adaptenv.adapt.llm.errors import (
    LLMAuthError,
    LLMError,
    LLMRequestError,
    LLMUnavailableError,
    StructuredOutputError,
    ToolCallError,
)
from adaptenv.adapt.llm.messages import (
    Message,
    ToolSpec,
    to_chat_messages,
    to_responses_input,
    with_image,
)
from adaptenv.adapt.llm.usage import COUNTERS, CallRecord, Role, Tokens, Usage

if TYPE_CHECKING:
    import httpx2

log = logging.getLogger(__name__)

T = TypeVar("T", bound=BaseModel)

#: Fraction of the backoff delay added as random jitter (drawn from the backend's seeded generator).
JITTER_FRACTION = 0.25
#: HTTP statuses after which Chat ``parse`` (json_schema) falls back to JSON mode in ``auto`` mode.
SCHEMA_UNSUPPORTED_STATUSES = (400, 404, 415, 422)


@dataclass(frozen=True)
class ToolCallResult:
    """The forced tool call: its name, decoded arguments, the raw argument text and the cost."""

    name: str
    arguments: dict[str, Any]
    raw_arguments: str
    text: str
    usage: Tokens
    model: str
    cached: bool = False


@dataclass(frozen=True)
class ParseResult(Generic[T]):
    """A structured answer validated into ``value``, with the raw JSON text and the cost."""

    value: T
    raw_text: str
    usage: Tokens
    model: str
    cached: bool = False


class LLMBackend(Protocol):
    """What F and G need from a language model; the offline built-ins need none of it."""

    config: LLMConfig
    usage: Usage

    def call_tool(self, system: str, messages: list[Message], image_png: bytes | None,
                  tool: ToolSpec | Sequence[ToolSpec], *, role: Role = "other") -> ToolCallResult:
        """Force one call of ``tool`` (of one of several tools: the result's ``name`` says which); ``image_png`` is
        attached to the last user turn; ``role`` tags the count."""
        ...

    def parse(self, system: str, messages: list[Message], image_png: bytes | None,
              schema: type[T], *, role: Role = "other") -> ParseResult[T]:
        """Ask for one answer that validates into the pydantic model ``schema``."""
        ...

    def track(self) -> AbstractContextManager[Usage]:
        """Count the tokens of the calls made inside a ``with`` block (e.g. one generated environment)."""
        ...


@dataclass
class _Answer:
    """What a backend extracted from one response body, before validation."""

    text: str
    calls: list[tuple[str, str]]
    usage: Tokens
    model: str
    refusal: str | None = None
    incomplete: str | None = None
    retries: int = 0


def import_openai() -> Any:
    """Import the openai SDK on first use; a missing package is a one-line user error."""
    try:
        import openai
    except ImportError:
        raise LLMError("the LLM backends need the openai package, which is not installed: "
                       "pip install openai") from None
    return openai


def redact(text: str, secret: str | None) -> str:
    """Remove the API key (and anything shaped like an OpenAI key) from a server message."""
    if secret and secret != PLACEHOLDER_KEY and len(secret) >= 4:
        text = text.replace(secret, "***")
    return re.sub(r"sk-[A-Za-z0-9_\-*.]{2,}", "sk-***", text)


def _validation_problems(exc: ValidationError, limit: int = 8) -> str:
    """A compact 'field: message; ...' list of pydantic errors, without echoing the input."""
    parts = []
    for err in exc.errors(include_url=False, include_input=False)[:limit]:
        loc = ".".join(str(p) for p in err["loc"]) or "(answer)"
        parts.append(f"{loc}: {err['msg']}")
    more = exc.error_count() - limit
    return "; ".join(parts) + (f"; and {more} more" if more > 0 else "")


def _strip_fences(text: str) -> str:
    """Drop a ```json ... ``` fence that local models like to wrap JSON in."""
    match = re.fullmatch(r"\s*```(?:json|JSON)?\s*(.*?)\s*```\s*", text, flags=re.DOTALL)
    return match.group(1) if match else text.strip()


def _to_stderr(line: str) -> None:
    """Say ``line`` on stderr (where a command's progress goes; its output stays clean)."""
    print(line, file=sys.stderr, flush=True)


def _retry_after_s(headers: Any) -> float | None:
    """Seconds from a numeric ``retry-after-ms`` / ``retry-after`` header, if any."""
    for name, scale in (("retry-after-ms", 1000.0), ("retry-after", 1.0)):
        value = headers.get(name) if headers is not None else None
        if value is None:
            continue
        try:
            seconds = float(value) / scale
        except ValueError:
            continue
        if math.isfinite(seconds) and seconds >= 0:
            return seconds
    return None


class _OpenAIBackendBase:
    """Shared machinery: client construction, retries, cache, token counting, answer checks."""

    #: Which wire API the subclass speaks ("responses" or "chat"); part of the cache key.
    api = ""

    def __init__(self, config: LLMConfig, *, http_client: httpx2.Client | None = None,
                 sleep: Callable[[float], None] = time.sleep, rng: np.random.Generator | None = None,
                 notify: Callable[[str], None] | None = None):
        """Build the SDK client (openai imported here); ``http_client``/``sleep``/``rng`` are for tests, ``notify``
        takes the line said when an attempt failed and another begins (default: printed on stderr)."""
        self.config = config
        self._notify = notify or _to_stderr
        self.base_url = config.resolved_base_url()
        self._api_key = resolve_api_key(config)
        self._openai = import_openai()
        self._client = self._openai.OpenAI(api_key=self._api_key, base_url=self.base_url,
                                           timeout=config.timeout_s, max_retries=0, http_client=http_client)
        self._sleep = sleep
        self._rng = rng if rng is not None else np.random.default_rng(config.seed)
        self._cache = ResponseCache(config.cache_dir) if config.cache_dir is not None else None
        self.usage = Usage()
        self._trackers: list[Usage] = []
        self.budget = config.budget()
        #: Usage spent before this backend was built (e.g. earlier iterations of a loop), counted by the budget.
        self.prior = Usage()

    def __repr__(self) -> str:
        return f"{type(self).__name__}(model={self.config.model!r}, base_url={self.base_url!r})"

    def describe(self) -> dict[str, object]:
        """Provider, API, model, base URL, prompt set and temperature (never the key), for run records."""
        return {**self.config.describe(), "api": self.api, "base_url": self.base_url}

    def close(self) -> None:
        """Close the underlying HTTP client."""
        self._client.close()

    def __enter__(self) -> _OpenAIBackendBase:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ----- token accounting -------------------------------------------------------------------

    @contextmanager
    def track(self) -> Iterator[Usage]:
        """Yield a fresh :class:`Usage` that sees every call made inside the block (nesting is fine)."""
        counter = Usage()
        self._trackers.append(counter)
        try:
            yield counter
        finally:
            self._trackers.remove(counter)

    def _record(self, record: CallRecord) -> None:
        """Add one answer to the backend total and to every active tracker."""
        for counter in (self.usage, *self._trackers):
            counter.add(record)

    def _check_budget(self) -> None:
        """Raise BudgetExceeded before a request once this backend plus ``prior`` reached the budget."""
        if not self.budget.active:
            return
        spent = Usage(**{k: getattr(self.usage, k) + getattr(self.prior, k) for k in COUNTERS})
        self.budget.check(spent)

    # ----- retries and error mapping ----------------------------------------------------------

    def _send(self, request: Callable[[], Any]) -> tuple[dict[str, Any], int]:
        """Run ``request`` (an SDK ``with_raw_response`` call) with bounded retries; (JSON body, retries)."""
        self._check_budget()
        attempts = self.config.max_retries + 1
        last = ""
        for attempt in range(attempts):
            try:
                raw = request()
            except Exception as exc:  # noqa: BLE001 - classified below, unknown errors re-raised
                verdict = self._classify(exc)
                if verdict is None:
                    raise
                last, retry_after = verdict
                if attempt + 1 < attempts:
                    delay = self._backoff(attempt, retry_after)
                    self._notify(f"LLM: attempt {attempt + 1} of {attempts} at {self.base_url} failed ({last}); "
                                 f"attempt {attempt + 2} in {delay:.1f} s")
                    self._sleep(delay)
                continue
            return self._json_body(raw), attempt
        raise LLMUnavailableError(
            f"the LLM server at {self.base_url} gave no usable answer after {attempts} attempt(s) "
            f"(last: {last}); check that it is running and reachable, or raise max_retries or "
            f"timeout_s in the LLM config")

    def _json_body(self, raw: Any) -> dict[str, Any]:
        """The decoded JSON object of a raw SDK response."""
        try:
            body = json.loads(raw.text)
        except (json.JSONDecodeError, UnicodeDecodeError):
            body = None
        if not isinstance(body, dict):
            raise LLMRequestError(f"the LLM server at {self.base_url} answered HTTP {raw.status_code} "
                                  f"with a body that is not a JSON object; check base_url", raw.status_code)
        return body

    def _classify(self, exc: Exception) -> tuple[str, float | None] | None:
        """(reason, retry-after) for retryable errors; raises fatal ones; None for unknown ones."""
        o = self._openai
        if isinstance(exc, o.APITimeoutError):
            return f"timed out after {self.config.timeout_s:g} s", None
        if isinstance(exc, o.APIConnectionError):
            return f"could not connect to {self.base_url}", None
        if isinstance(exc, o.APIStatusError):
            status = exc.status_code
            if status == 429 or status >= 500:
                return f"HTTP {status}", _retry_after_s(exc.response.headers)
            raise self._fatal(status, exc.body, str(getattr(exc, "message", ""))) from None
        return None

    def _fatal(self, status: int, body: object, message: str) -> LLMError:
        """A clear, key-free error for a 4xx answer that retrying cannot fix."""
        cfg = self.config
        if status == 401:
            return LLMAuthError(f"the API key was rejected by {self.base_url} (HTTP 401): check the key in "
                                f"the environment variable {cfg.key_env()}")
        if status == 403:
            return LLMAuthError(f"{self.base_url} denied access to model {cfg.model!r} (HTTP 403): check that "
                                f"the key's project may use this model")
        detail = body.get("message") if isinstance(body, dict) else None
        detail = redact(str(detail or message or "no details"), self._api_key)[:300]
        if status == 404:
            return LLMRequestError(f"{self.base_url} answered HTTP 404 for model {cfg.model!r} ({detail}): "
                                   f"check the model name and that base_url ends in /v1", status)
        return LLMRequestError(f"{self.base_url} rejected the request for model {cfg.model!r} "
                               f"(HTTP {status}: {detail}); fix the LLM config or the request", status)

    def _backoff(self, attempt: int, retry_after: float | None) -> float:
        """Exponential delay with seeded jitter, at least the server's retry-after, at most backoff_max_s."""
        cfg = self.config
        delay = cfg.backoff_base_s * (2.0 ** attempt) * (1.0 + JITTER_FRACTION * float(self._rng.random()))
        if retry_after is not None:
            delay = max(delay, retry_after)
        return min(delay, cfg.backoff_max_s)

    # ----- cache ------------------------------------------------------------------------------

    def _key(self, kind: str, system: str, msgs: list[Message], what: dict[str, Any]) -> str:
        """Hash of everything that shapes the answer (no key, images by hash)."""
        cfg = self.config
        return request_key({
            "api": self.api, "provider": cfg.provider, "base_url": self.base_url, "model": cfg.model,
            "temperature": cfg.temperature, "max_output_tokens": cfg.max_output_tokens,
            "image_detail": cfg.image_detail, "kind": kind, "system": system,
            "messages": [m.fingerprint() for m in msgs], **what,
        })

    def _cache_get(self, key: str) -> dict[str, Any] | None:
        return self._cache.get(key) if self._cache is not None else None

    def _cache_put(self, key: str, record: dict[str, Any]) -> None:
        if self._cache is not None:
            self._cache.put(key, record, secret=self._api_key)

    # ----- the two calls ----------------------------------------------------------------------

    def call_tool(self, system: str, messages: list[Message], image_png: bytes | None,
                  tool: ToolSpec | Sequence[ToolSpec], *, role: Role = "other") -> ToolCallResult:
        """Force one call of ``tool`` (or of one of several tools) and return its name and decoded arguments.

        Raises:
            ToolCallError: no call of ``tool`` in the answer, or arguments that are not a JSON
                object; ``exc.feedback`` is the message to send back before asking again.
            LLMError: transport failures (after retries), rejected key, rejected request.
        """
        msgs = with_image(messages, image_png)
        tools = [tool] if isinstance(tool, ToolSpec) else list(tool)
        what = {"tool": tools[0].as_dict()} if len(tools) == 1 else {"tools": [t.as_dict() for t in tools]}
        key = self._key("tool", system, msgs, what)
        record = self._cache_get(key)
        if record is not None and record.get("kind") == "tool":
            usage = Tokens(**record["usage"])
            self._record(CallRecord(role, usage, cache_hit=True, model=record["model"]))
            res = record["result"]
            return ToolCallResult(res["name"], res["arguments"], res["raw_arguments"], res["text"], usage,
                                  record["model"], cached=True)
        answer = self._tool_request(system, msgs, tools)
        self._record(CallRecord(role, answer.usage, retries=answer.retries, model=answer.model))
        name, raw, arguments = _decode_tool_call(answer, [t.name for t in tools])
        result = ToolCallResult(name, arguments, raw, answer.text, answer.usage, answer.model)
        self._cache_put(key, {"kind": "tool", "model": answer.model, "usage": asdict(answer.usage),
                              "result": {"name": name, "arguments": arguments, "raw_arguments": raw,
                                         "text": answer.text}})
        return result

    def parse(self, system: str, messages: list[Message], image_png: bytes | None,
              schema: type[T], *, role: Role = "other") -> ParseResult[T]:
        """Ask for one JSON answer and validate it into ``schema``.

        Raises:
            StructuredOutputError: refused, cut off, or not valid for ``schema``; send
                ``exc.feedback`` back and ask again.
            LLMError: transport failures (after retries), rejected key, rejected request.
        """
        msgs = with_image(messages, image_png)
        key = self._key("parse", system, msgs, {"schema_name": schema.__name__,
                                                "schema": schema.model_json_schema()})
        record = self._cache_get(key)
        if record is not None and record.get("kind") == "parse":
            try:
                value = schema.model_validate(record["result"]["value"])
            except ValidationError:
                log.warning("ignoring a cached answer that no longer fits %s", schema.__name__)
            else:
                usage = Tokens(**record["usage"])
                self._record(CallRecord(role, usage, cache_hit=True, model=record["model"]))
                return ParseResult(value, record["result"]["raw_text"], usage, record["model"], cached=True)
        answer = self._parse_request(system, msgs, schema)
        self._record(CallRecord(role, answer.usage, retries=answer.retries, model=answer.model))
        value = _validate_answer(answer, schema)
        self._cache_put(key, {"kind": "parse", "model": answer.model, "usage": asdict(answer.usage),
                              "result": {"value": value.model_dump(mode="json"), "raw_text": answer.text}})
        return ParseResult(value, answer.text, answer.usage, answer.model)

    def _sampling(self) -> dict[str, Any]:
        """Optional sampling arguments common to both APIs."""
        return {} if self.config.temperature is None else {"temperature": self.config.temperature}

    def _tool_request(self, system: str, msgs: list[Message], tools: list[ToolSpec]) -> _Answer:
        raise NotImplementedError

    def _parse_request(self, system: str, msgs: list[Message], schema: type[BaseModel]) -> _Answer:
        raise NotImplementedError


def _decode_tool_call(answer: _Answer, names: list[str]) -> tuple[str, str, dict[str, Any]]:
    """The name, raw and decoded arguments of the first call of one of ``names``; ToolCallError otherwise."""
    calls = [(called, args) for called, args in answer.calls if called in names]
    name = names[0] if len(names) == 1 else " or ".join(names)
    if not calls:
        got = f"called {answer.calls[0][0]!r}" if answer.calls else "answered without a tool call"
        raise ToolCallError(f"the model {got} instead of calling {name}",
                            feedback=f"You must answer by calling the function {name} exactly once, "
                                     f"not with plain text. Call {name} now.",
                            raw=answer.text or f"(no call of {name})")
    name, raw = calls[0]
    try:
        arguments = json.loads(raw)
    except json.JSONDecodeError as exc:
        raise ToolCallError(f"the arguments of {name} are not valid JSON ({exc.msg} at character {exc.pos})",
                            feedback=f"The arguments of your {name} call were not valid JSON ({exc.msg} at "
                                     f"character {exc.pos}). Call {name} again with one JSON object "
                                     f"that matches its parameters.",
                            raw=raw) from None
    if not isinstance(arguments, dict):
        raise ToolCallError(f"the arguments of {name} are a JSON {type(arguments).__name__}, not an object",
                            feedback=f"The arguments of your {name} call must be one JSON object with the "
                                     f"function's parameters as keys. Call {name} again.",
                            raw=raw)
    return name, raw, arguments


def _validate_answer(answer: _Answer, schema: type[T]) -> T:
    """Validate a structured answer, turning every failure into StructuredOutputError with feedback."""
    name = schema.__name__
    if answer.refusal:
        raise StructuredOutputError(f"the model refused to answer: {answer.refusal[:200]}",
                                    feedback=f"Please answer the request with one JSON object of the "
                                             f"{name} schema.", raw=answer.refusal)
    if answer.incomplete:
        raise StructuredOutputError(f"the answer was cut off ({answer.incomplete}); raise max_output_tokens",
                                    feedback=f"Your answer was cut off ({answer.incomplete}). Answer again, "
                                             f"more briefly, with one JSON object of the {name} schema.",
                                    raw=answer.text)
    try:
        return schema.model_validate_json(_strip_fences(answer.text))
    except ValidationError as exc:
        problems = _validation_problems(exc)
        raise StructuredOutputError(f"the answer does not fit {name}: {problems}",
                                    feedback=f"Your answer did not match the {name} JSON schema ({problems}). "
                                             f"Answer again with one JSON object that matches the schema.",
                                    raw=answer.text) from None


def _usage_from(raw: object, i_key: str, o_key: str, details_key: str) -> Tokens:
    """Tokens from a body's ``usage`` object (missing fields count as zero; cached from ``details_key``)."""
    u = raw if isinstance(raw, dict) else {}
    details = u.get(details_key) if isinstance(u.get(details_key), dict) else {}
    return Tokens.of(u.get(i_key), u.get(o_key), u.get("total_tokens"), details.get("cached_tokens"))


def _arguments_text(args: object) -> str:
    """Tool arguments as text (some servers send an object instead of a JSON string)."""
    return args if isinstance(args, str) else json.dumps(args)


class OpenAIResponsesBackend(_OpenAIBackendBase):
    """The OpenAI Responses API (``client.responses``), as the paper used with gpt-4.1-mini."""

    api = "responses"

    def _common(self, system: str, msgs: list[Message]) -> dict[str, Any]:
        kwargs: dict[str, Any] = {"model": self.config.model,
                                  "input": to_responses_input(msgs, detail=self.config.image_detail),
                                  "store": False, **self._sampling()}
        if system:
            kwargs["instructions"] = system
        if self.config.max_output_tokens is not None:
            kwargs["max_output_tokens"] = self.config.max_output_tokens
        return kwargs

    def _tool_request(self, system: str, msgs: list[Message], tools: list[ToolSpec]) -> _Answer:
        kwargs = self._common(system, msgs)
        choice = {"type": "function", "name": tools[0].name} if len(tools) == 1 else "required"
        body, retries = self._send(lambda: self._client.responses.with_raw_response.create(
            **kwargs, tools=[t.responses_param() for t in tools], tool_choice=choice, parallel_tool_calls=False))
        return self._answer(body, retries)

    def _parse_request(self, system: str, msgs: list[Message], schema: type[BaseModel]) -> _Answer:
        kwargs = self._common(system, msgs)
        body, retries = self._send(lambda: self._client.responses.with_raw_response.parse(**kwargs,
                                                                                          text_format=schema))
        return self._answer(body, retries)

    def _answer(self, body: dict[str, Any], retries: int = 0) -> _Answer:
        """Text, function calls, refusal and usage of a Responses API body."""
        texts: list[str] = []
        calls: list[tuple[str, str]] = []
        refusal = None
        for item in body.get("output") or []:
            if not isinstance(item, dict):
                continue
            if item.get("type") == "function_call":
                calls.append((str(item.get("name")), _arguments_text(item.get("arguments", ""))))
            elif item.get("type") == "message":
                for part in item.get("content") or []:
                    if isinstance(part, dict) and part.get("type") == "output_text":
                        texts.append(str(part.get("text", "")))
                    elif isinstance(part, dict) and part.get("type") == "refusal":
                        refusal = str(part.get("refusal", "")) or "refused"
        incomplete = None
        if body.get("status") == "incomplete":
            details = body.get("incomplete_details") or {}
            incomplete = str(details.get("reason", "incomplete")) if isinstance(details, dict) else "incomplete"
        return _Answer("".join(texts), calls,
                       _usage_from(body.get("usage"), "input_tokens", "output_tokens", "input_tokens_details"),
                       str(body.get("model") or self.config.model), refusal, incomplete, retries)


class ChatCompletionsBackend(_OpenAIBackendBase):
    """Chat Completions (``client.chat.completions``) against any OpenAI-compatible ``base_url``."""

    api = "chat"

    def __init__(self, config: LLMConfig, **kwargs: Any):
        super().__init__(config, **kwargs)
        self._structured = "json_object" if config.structured_output == "json_object" else "json_schema"

    def _common(self, messages: list[dict[str, Any]]) -> dict[str, Any]:
        kwargs: dict[str, Any] = {"model": self.config.model, "messages": messages, **self._sampling()}
        if self.config.max_output_tokens is not None:
            kwargs["max_tokens"] = self.config.max_output_tokens
        return kwargs

    def _tool_request(self, system: str, msgs: list[Message], tools: list[ToolSpec]) -> _Answer:
        kwargs = self._common(to_chat_messages(system, msgs))
        choice = {"type": "function", "function": {"name": tools[0].name}} if len(tools) == 1 else "required"
        body, retries = self._send(lambda: self._client.chat.completions.with_raw_response.create(
            **kwargs, tools=[t.chat_param() for t in tools], tool_choice=choice, parallel_tool_calls=False))
        return self._answer(body, retries)

    def _parse_request(self, system: str, msgs: list[Message], schema: type[BaseModel]) -> _Answer:
        if self._structured == "json_schema":
            kwargs = self._common(to_chat_messages(system, msgs))
            try:
                body, retries = self._send(lambda: self._client.chat.completions.with_raw_response.parse(
                    **kwargs, response_format=schema))
                return self._answer(body, retries)
            except LLMRequestError as exc:
                if self.config.structured_output != "auto" or exc.status_code not in SCHEMA_UNSUPPORTED_STATUSES:
                    raise
                log.warning("%s rejected json_schema output (HTTP %s); using JSON mode from now on",
                            self.base_url, exc.status_code)
                self._structured = "json_object"
        schema_text = json.dumps(schema.model_json_schema(), sort_keys=True)
        system = (f"{system}\n\n" if system else "") + (
            f"Answer with one JSON object only, no other text, that matches this JSON schema:\n{schema_text}")
        kwargs = self._common(to_chat_messages(system, msgs))
        body, retries = self._send(lambda: self._client.chat.completions.with_raw_response.create(
            **kwargs, response_format={"type": "json_object"}))
        return self._answer(body, retries)

    def _answer(self, body: dict[str, Any], retries: int = 0) -> _Answer:
        """Text, tool calls, refusal and usage of a Chat Completions body."""
        choices = body.get("choices") or [{}]
        choice = choices[0] if isinstance(choices[0], dict) else {}
        msg = choice.get("message") if isinstance(choice.get("message"), dict) else {}
        content = msg.get("content")
        if isinstance(content, list):  # a few servers return content parts
            content = "".join(str(p.get("text", "")) for p in content if isinstance(p, dict))
        calls = []
        for call in msg.get("tool_calls") or []:
            fn = call.get("function") if isinstance(call, dict) else None
            if isinstance(fn, dict):
                calls.append((str(fn.get("name")), _arguments_text(fn.get("arguments", ""))))
        incomplete = "max_output_tokens" if choice.get("finish_reason") == "length" and not calls else None
        return _Answer(str(content or ""), calls,
                       _usage_from(body.get("usage"), "prompt_tokens", "completion_tokens", "prompt_tokens_details"),
                       str(body.get("model") or self.config.model), msg.get("refusal") or None, incomplete, retries)


def make_backend(config: LLMConfig, **kwargs: Any) -> OpenAIResponsesBackend | ChatCompletionsBackend:
    """The backend of ``config.resolved_api()``: Responses (default for 'openai') or Chat Completions."""
    cls = OpenAIResponsesBackend if config.resolved_api() == "responses" else ChatCompletionsBackend
    return cls(config, **kwargs)
