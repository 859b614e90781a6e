"""Token accounting: per-call Usage and a TokenCounter that F/G read per generated environment."""

from __future__ import annotations

import threading
from dataclasses import dataclass


@dataclass(frozen=True)
class Usage:
    """Tokens of one answer as reported by the server (zeros when the server reports none)."""

    input_tokens: int = 0
    output_tokens: int = 0
    total_tokens: int = 0

    @classmethod
    def of(cls, input_tokens: int | None, output_tokens: int | None, total_tokens: int | None = None) -> Usage:
        """Build from possibly-missing server fields; total defaults to input + output."""
        i, o = int(input_tokens or 0), int(output_tokens or 0)
        return cls(i, o, int(total_tokens) if total_tokens is not None else i + o)


@dataclass
class TokenCounter:
    """Running sums over calls; cache hits are counted separately and cost no tokens."""

    input_tokens: int = 0
    output_tokens: int = 0
    total_tokens: int = 0
    calls: int = 0
    cache_hits: int = 0

    def __post_init__(self) -> None:
        self._lock = threading.Lock()

    def add(self, usage: Usage, *, cached: bool = False) -> None:
        """Add one answer: a server call (its tokens) or a cache hit (no tokens)."""
        with self._lock:
            if cached:
                self.cache_hits += 1
                return
            self.calls += 1
            self.input_tokens += usage.input_tokens
            self.output_tokens += usage.output_tokens
            self.total_tokens += usage.total_tokens

    def snapshot(self) -> dict[str, int]:
        """The current sums as a plain dict (for logs and run summaries)."""
        with self._lock:
            return {"input_tokens": self.input_tokens, "output_tokens": self.output_tokens,
                    "total_tokens": self.total_tokens, "calls": self.calls, "cache_hits": self.cache_hits}

    def reset(self) -> dict[str, int]:
        """Zero the sums and return what they were."""
        before = self.snapshot()
        with self._lock:
            self.input_tokens = self.output_tokens = self.total_tokens = self.calls = self.cache_hits = 0
        return before
