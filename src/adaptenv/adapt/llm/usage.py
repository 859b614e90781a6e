"""Token accounting: tokens of one answer, a record per call tagged F/G/verify, running totals, cost, budgets.

* :class:`Tokens`: what the server reported for one answer (input, output, cached input, total).
* :class:`CallRecord`: one answer as counted: its role (``F`` analysis, ``G`` move proposal,
  ``verify`` verification), tokens, whether it came from the response cache and how many
  transport retries it took.
* :class:`Usage`: running totals over calls (and the calls themselves), mergeable across scenes,
  iterations and runs; :meth:`Usage.cost` prices it with :class:`Prices`.
* :class:`Budget`: a token and/or cost ceiling; :meth:`Budget.check` raises :class:`BudgetExceeded`.

Example:
    >>> u = Usage()
    >>> u.add(CallRecord("G", Tokens.of(1000, 50)))
    >>> round(u.cost(Prices(0.40, 1.60)), 6)
    0.00048
"""

from __future__ import annotations

import threading
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

from adaptenv.adapt.llm.errors import BudgetExceeded
from adaptenv.errors import ConfigError

Role = Literal["F", "G", "verify", "other"]
ROLES: tuple[str, ...] = ("F", "G", "verify", "other")


@dataclass(frozen=True)
class Tokens:
    """Tokens of one answer as reported by the server (zeros when the server reports none).

    ``cached_tokens`` is the part of ``input_tokens`` the server read from its prompt cache.
    """

    input_tokens: int = 0
    output_tokens: int = 0
    total_tokens: int = 0
    cached_tokens: int = 0

    @classmethod
    def of(cls, input_tokens: int | None, output_tokens: int | None, total_tokens: int | None = None,
           cached_tokens: int | None = None) -> Tokens:
        """Build from possibly-missing server fields; total defaults to input + output."""
        i, o = int(input_tokens or 0), int(output_tokens or 0)
        return cls(i, o, int(total_tokens) if total_tokens is not None else i + o, int(cached_tokens or 0))


@dataclass(frozen=True)
class CallRecord:
    """One counted answer: which step asked (F, G, verify), its tokens, cache hit, transport retries."""

    role: str
    tokens: Tokens
    cache_hit: bool = False
    retries: int = 0
    model: str = ""

    def to_dict(self) -> dict[str, Any]:
        """Flat JSON-able form."""
        return {"role": self.role, **asdict(self.tokens), "cache_hit": self.cache_hit, "retries": self.retries,
                "model": self.model}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CallRecord:
        """Inverse of :meth:`to_dict`."""
        tokens = Tokens(**{k: int(d.get(k, 0)) for k in ("input_tokens", "output_tokens", "total_tokens",
                                                         "cached_tokens")})
        return cls(str(d.get("role", "other")), tokens, bool(d.get("cache_hit", False)), int(d.get("retries", 0)),
                   str(d.get("model", "")))


@dataclass(frozen=True)
class Prices:
    """USD per million tokens; cached input defaults to the input price when not given."""

    input_per_million: float
    output_per_million: float
    cached_input_per_million: float | None = None

    def cost(self, input_tokens: int, output_tokens: int, cached_tokens: int = 0) -> float:
        """USD for these tokens (cached tokens are part of ``input_tokens``, billed at the cached price)."""
        cached = min(max(cached_tokens, 0), input_tokens)
        p_cached = self.input_per_million if self.cached_input_per_million is None else self.cached_input_per_million
        return ((input_tokens - cached) * self.input_per_million + cached * p_cached
                + output_tokens * self.output_per_million) / 1e6


COUNTERS = ("input_tokens", "output_tokens", "cached_tokens", "total_tokens", "calls", "retries", "cache_hits")


@dataclass
class Usage:
    """Running totals over answers: server calls (their tokens) and cache hits (no tokens, no cost).

    Keeps every :class:`CallRecord` so totals can be split by role (F, G, verify) afterwards.
    """

    input_tokens: int = 0
    output_tokens: int = 0
    cached_tokens: int = 0
    total_tokens: int = 0
    calls: int = 0
    retries: int = 0
    cache_hits: int = 0
    records: list[CallRecord] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._lock = threading.Lock()

    def __getstate__(self) -> dict[str, Any]:
        """Pickle without the lock (usage travels back from executor workers)."""
        state = dict(self.__dict__)
        state.pop("_lock", None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()

    def add(self, record: CallRecord) -> None:
        """Count one answer: a server call adds its tokens; a cache hit only counts as a hit."""
        with self._lock:
            self.records.append(record)
            self.retries += record.retries
            if record.cache_hit:
                self.cache_hits += 1
                return
            self.calls += 1
            t = record.tokens
            self.input_tokens += t.input_tokens
            self.output_tokens += t.output_tokens
            self.cached_tokens += t.cached_tokens
            self.total_tokens += t.total_tokens

    def merge(self, other: Usage) -> Usage:
        """Add every record of ``other`` to this total; returns self."""
        for r in list(other.records):
            self.add(r)
        if not other.records:  # totals without records (e.g. read back from a summary)
            with self._lock:
                for k in COUNTERS:
                    setattr(self, k, getattr(self, k) + getattr(other, k))
        return self

    def cost(self, prices: Prices | None) -> float | None:
        """Estimated USD of the server calls (None without prices)."""
        if prices is None:
            return None
        return prices.cost(self.input_tokens, self.output_tokens, self.cached_tokens)

    def by_role(self) -> dict[str, Usage]:
        """Totals per role (F, G, verify, ...), only roles that were used."""
        out: dict[str, Usage] = {}
        for r in list(self.records):
            out.setdefault(r.role, Usage()).add(r)
        return out

    def totals(self, prices: Prices | None = None) -> dict[str, Any]:
        """The counters as a dict, plus ``cost_usd`` when prices are given."""
        d: dict[str, Any] = {k: getattr(self, k) for k in COUNTERS}
        if prices is not None:
            d["cost_usd"] = round(self.cost(prices) or 0.0, 8)
        return d

    def to_dict(self, prices: Prices | None = None, *, calls: bool = True) -> dict[str, Any]:
        """Totals, totals per role and (with ``calls``) every call record: what runs write to disk."""
        d = self.totals(prices)
        d["by_role"] = {role: u.totals(prices) for role, u in self.by_role().items()}
        if calls:
            d["records"] = [r.to_dict() for r in list(self.records)]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> Usage:
        """Read back :meth:`to_dict` (records when present, else the totals)."""
        u = cls()
        if not d:
            return u
        if d.get("records"):
            for r in d["records"]:
                u.add(CallRecord.from_dict(r))
            return u
        for k in COUNTERS:
            setattr(u, k, int(d.get(k, 0)))
        return u

    def snapshot(self) -> dict[str, int]:
        """The counters as a plain dict (for logs)."""
        with self._lock:
            return {k: getattr(self, k) for k in COUNTERS}

    def line(self, prices: Prices | None = None) -> str:
        """One human line: tokens in/out (cached), calls, retries, cache hits, cost."""
        cost = self.cost(prices)
        money = f", ${cost:.4f}" if cost is not None else ""
        return (f"{self.input_tokens:,} in ({self.cached_tokens:,} cached) / {self.output_tokens:,} out tokens, "
                f"{self.calls} calls, {self.retries} retries, {self.cache_hits} cache hits{money}")


@dataclass(frozen=True)
class Budget:
    """A ceiling on tokens (input + output) and/or estimated cost; None means no limit."""

    max_tokens: int | None = None
    max_cost: float | None = None
    prices: Prices | None = None

    def __post_init__(self) -> None:
        if self.max_cost is not None and self.prices is None:
            raise ConfigError("a cost budget (--max-cost, max_cost) needs prices: pass --price-in and --price-out "
                              "(USD per million tokens) or set price_in/price_out in the LLM config")

    @property
    def active(self) -> bool:
        return self.max_tokens is not None or self.max_cost is not None

    def exceeded(self, usage: Usage) -> str | None:
        """Why ``usage`` has reached the budget, or None while it has not."""
        if self.max_tokens is not None and usage.total_tokens >= self.max_tokens:
            return f"the token budget of {self.max_tokens:,} is used up ({usage.total_tokens:,} tokens)"
        cost = usage.cost(self.prices)
        if self.max_cost is not None and cost is not None and cost >= self.max_cost:
            return f"the cost budget of ${self.max_cost:.4f} is used up (${cost:.4f})"
        return None

    def check(self, usage: Usage) -> None:
        """Raise :class:`BudgetExceeded` when ``usage`` has reached the budget."""
        why = self.exceeded(usage)
        if why:
            raise BudgetExceeded(f"{why}; the run stops here: raise --max-tokens/--max-cost (or max_tokens/"
                                 "max_cost in the LLM config) and resume")
