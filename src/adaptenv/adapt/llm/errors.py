"""Errors of the LLM layer: transport failures (fatal) and bad model answers (send back and retry)."""

from __future__ import annotations

from adaptenv.errors import AdaptenvError


class LLMError(AdaptenvError):
    """Base class of every error raised by the LLM backends."""


class LLMAuthError(LLMError):
    """The server rejected the credentials (HTTP 401/403); retrying cannot help."""


class LLMRequestError(LLMError):
    """The server refused the request (a 4xx other than 401/403/429); retrying cannot help."""

    def __init__(self, message: str, status_code: int | None = None):
        super().__init__(message)
        self.status_code = status_code


class LLMUnavailableError(LLMError):
    """The server did not answer usefully within the retry budget (429, 5xx, timeouts, connection errors)."""


class ModelAnswerError(LLMError):
    """The model answered, but not in the required shape; ``feedback`` is the message to send back.

    Callers (F and G) append the model's answer and ``Message.user(exc.feedback)`` to the
    conversation and ask again, a bounded number of times.
    """

    def __init__(self, message: str, *, feedback: str, raw: str = ""):
        super().__init__(message)
        self.feedback = feedback
        self.raw = raw


class ToolCallError(ModelAnswerError):
    """The answer had no call of the forced tool, or its arguments were not a JSON object."""


class StructuredOutputError(ModelAnswerError):
    """A structured (pydantic) answer was missing, refused, cut off or did not validate."""


class BudgetExceeded(LLMError):
    """The run reached its token or cost budget; no further request is sent and the run ends cleanly."""
