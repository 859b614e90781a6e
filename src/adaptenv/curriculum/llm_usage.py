"""The LLM usage ledger of a closed-loop run: ``RUN_DIR/llm_usage.json``, per iteration and in total.

The loop calls :func:`record_iteration` once an iteration's scenes are made (replacing an earlier,
interrupted attempt at the same iteration) and :func:`budget_left` before starting the next
iteration, so a run stops cleanly at its token or cost budget (``llm.max_tokens``,
``llm.max_cost``) and continues with ``--resume`` after the budget is raised. Each backend also
stops its own requests at the full budget, so one iteration can overshoot the run's budget by at
most the scenes it makes in parallel.

Example:
    >>> record_iteration(run_dir, t, scenes_usage(made), cfg.llm)  # doctest: +SKIP
    >>> why = budget_left(run_dir, cfg.llm)  # None while there is budget left  # doctest: +SKIP
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import BaseModel, Field

from adaptenv.adapt.llm.accounting import llm_config_of
from adaptenv.adapt.llm.config import LLMConfig
from adaptenv.adapt.llm.usage import Usage
from adaptenv.curriculum.records import atomic_write_text

#: File of a run folder holding the LLM usage per iteration.
LEDGER = "llm_usage.json"


class UsageLedger(BaseModel):
    """What ``llm_usage.json`` holds: the LLM used, and the usage of each finished iteration and in total."""

    llm: dict[str, Any] = Field(default_factory=dict)
    """Provider, API, model, base URL, prompt set, temperature, prices (never the key)."""
    iterations: dict[str, dict[str, Any]] = Field(default_factory=dict)
    """Iteration number (as text) -> ``Usage.to_dict`` (totals, per role, with cost when priced)."""
    total: dict[str, Any] = Field(default_factory=dict)
    """The run total (totals and per role)."""

    @classmethod
    def read(cls, run_dir: str | Path) -> UsageLedger:
        """The ledger of a run folder (empty when there is none yet)."""
        p = Path(run_dir) / LEDGER
        return cls.model_validate_json(p.read_text(encoding="utf-8")) if p.is_file() else cls()

    def usage(self) -> Usage:
        """The run total as a :class:`Usage` (every stored call record)."""
        out = Usage()
        for t in sorted(self.iterations, key=int):
            out.merge(Usage.from_dict(self.iterations[t]))
        return out


def record_iteration(run_dir: str | Path, t: int, usage: Usage, llm: dict[str, Any] | LLMConfig | None
                     ) -> UsageLedger:
    """Store iteration ``t``'s usage (replacing an earlier attempt at ``t``) and the new total; atomic write."""
    cfg = llm_config_of(llm)
    prices = cfg.prices() if cfg is not None else None
    ledger = UsageLedger.read(run_dir)
    ledger.iterations = {k: v for k, v in ledger.iterations.items() if int(k) < t}
    ledger.iterations[str(t)] = usage.to_dict(prices)
    ledger.total = ledger.usage().to_dict(prices, calls=False)
    if cfg is not None:
        ledger.llm = cfg.describe()
    atomic_write_text(Path(run_dir) / LEDGER, ledger.model_dump_json(indent=1))
    return ledger


def budget_left(run_dir: str | Path, llm: dict[str, Any] | LLMConfig | None) -> str | None:
    """Why the run's token/cost budget is used up (None while there is budget left, or without a budget)."""
    cfg = llm_config_of(llm)
    if cfg is None:
        return None
    budget = cfg.budget()
    if not budget.active:
        return None
    return budget.exceeded(UsageLedger.read(run_dir).usage())


def usage_line(run_dir: str | Path, llm: dict[str, Any] | LLMConfig | None) -> str:
    """One progress line with the run's running LLM totals (tokens, calls, retries, cache hits, cost)."""
    cfg = llm_config_of(llm)
    return "LLM so far: " + UsageLedger.read(run_dir).usage().line(cfg.prices() if cfg is not None else None)



def iteration_lines(t: int, names: list[str], made: list[Any], run_dir: str | Path,
                    llm: dict[str, Any] | LLMConfig | None) -> list[str]:
    """Progress lines after an iteration's generation: one per scene (edits, tokens, cost, why G stopped
    early), then the run's running totals."""
    cfg = llm_config_of(llm)
    prices = cfg.prices() if cfg is not None else None
    lines = []
    for name, g in zip(names, made, strict=True):
        usage = g.usage if g.usage is not None else Usage()
        stop = f"; G stopped early: {g.stopped}" if getattr(g, "stopped", "") else ""
        lines.append(f"t={t} {name}: {g.edits} edit(s) applied; {usage.line(prices)}{stop}")
    lines.append(f"t={t}: {usage_line(run_dir, llm)}")
    return lines
