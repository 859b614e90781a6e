"""LLM layer of F and G: configuration, the two backends, the response cache and the move tools.

Importing this package does not import ``openai``; the SDK loads when a backend is constructed.
The built-in offline analyzer and generator need none of this.

Example:
    >>> from adaptenv.adapt.llm import LLMConfig, Message, make_backend, move_tool
    >>> backend = make_backend(LLMConfig(provider="openai-compatible",
    ...                                  base_url="http://localhost:11434/v1", model="qwen2.5vl"))
    >>> result = backend.call_tool("You edit apartments.", [Message.user("Move one object.")],
    ...                            png_bytes, move_tool(["Sofa|1", "Chair|2"]))  # doctest: +SKIP
"""

from adaptenv.adapt.llm.backend import (
    ChatCompletionsBackend,
    LLMBackend,
    OpenAIResponsesBackend,
    ParseResult,
    ToolCallResult,
    make_backend,
)
from adaptenv.adapt.llm.cache import ResponseCache, request_key
from adaptenv.adapt.llm.config import LLMConfig, load_llm_config, refuse_secrets, resolve_api_key
from adaptenv.adapt.llm.errors import (
    BudgetExceeded,
    LLMAuthError,
    LLMError,
    LLMRequestError,
    LLMUnavailableError,
    ModelAnswerError,
    StructuredOutputError,
    ToolCallError,
)
from adaptenv.adapt.llm.messages import Message, ToolSpec
from adaptenv.adapt.llm.tools import (
    MoveInstruction,
    MoveInstructionError,
    Verification,
    move_tool,
    parse_move_instruction,
    parse_verification,
    verify_tool,
)
from adaptenv.adapt.llm.usage import Budget, CallRecord, Prices, Tokens, Usage

__all__ = [
    "Budget", "BudgetExceeded", "CallRecord", "ChatCompletionsBackend", "LLMAuthError", "LLMBackend", "LLMConfig",
    "LLMError", "LLMRequestError", "LLMUnavailableError", "Message", "ModelAnswerError", "MoveInstruction",
    "MoveInstructionError", "OpenAIResponsesBackend", "ParseResult", "Prices", "ResponseCache",
    "StructuredOutputError", "Tokens", "ToolCallError", "ToolCallResult", "ToolSpec", "Usage", "Verification",
    "load_llm_config", "make_backend", "move_tool", "parse_move_instruction", "parse_verification",
    "refuse_secrets", "request_key", "resolve_api_key", "verify_tool",
]
