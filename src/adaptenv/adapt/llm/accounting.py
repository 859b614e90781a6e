"""LLM usage of runs: one scene's F + G tokens, a batch's, and the checks a run config's ``llm`` section gets.

For one adapted scene, :func:`scene_usage` adds F's calls (``Analysis.usage``) to G's
(``GenerationResult.usage``); :func:`scenes_usage` sums a batch. :func:`check_llm_section` refuses an
API key in a run config (before anything is saved) and validates the fields; :func:`run_changes` names
what a resumed run changed (it may raise its budget). The closed loop's per-iteration ledger is
:mod:`adaptenv.curriculum.llm_usage`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from adaptenv.adapt.llm.config import LLM_FIX, LLMConfig, refuse_secrets
from adaptenv.adapt.llm.usage import Usage
from adaptenv.configfile import parse_config

if TYPE_CHECKING:
    from adaptenv.adapt.analysis import Analysis
    from adaptenv.adapt.generators import GenerationResult

def scene_usage(analysis: Analysis | None, generation: GenerationResult | None) -> Usage:
    """F's and G's calls for one adapted scene, as one :class:`Usage` (empty for the built-ins)."""
    out = Usage.from_dict(analysis.usage if analysis is not None else None)
    if generation is not None:
        out.merge(generation.usage)
    return out


def llm_config_of(llm: dict[str, Any] | LLMConfig | None) -> LLMConfig | None:
    """An LLMConfig from a run config's ``llm`` section (None when the section is empty)."""
    if llm is None or isinstance(llm, LLMConfig):
        return llm
    return LLMConfig(**llm) if llm else None


def check_llm_section(llm: dict[str, Any], source: str, prefix: str = "llm") -> None:
    """Refuse an API key in a run config's ``llm`` section and check its fields' types and values (one
    ConfigError ``source: prefix.field ...``)."""
    refuse_secrets(llm, f"{source}: {prefix}")
    if llm:
        parse_config(LLMConfig, llm, source, prefix=prefix, fix=LLM_FIX).budget()


#: LLM fields a resumed run may change: budgets can be raised to continue a run that used them up.
RESUMABLE_LLM_FIELDS = ("max_tokens", "max_cost")


def run_changes(saved: dict[str, Any], current: dict[str, Any]) -> list[str]:
    """``name (was A, now B)`` for each setting in which two run configs differ (``llm.NAME`` inside the llm
    section); the budgets a resumed run may raise are left out."""
    from adaptenv.agents.config import changed_settings

    def spread(cfg: dict[str, Any]) -> dict[str, Any]:
        if not isinstance(cfg, dict):  # a tampered state: every setting differs
            return {"config": cfg}
        section = cfg.get("llm") if isinstance(cfg.get("llm"), dict) else {}  # a tampered state: compared as it is
        llm = {f"llm.{k}": v for k, v in section.items() if k not in RESUMABLE_LLM_FIELDS}
        return {**{k: v for k, v in cfg.items() if k != "llm"}, **llm}

    return changed_settings(spread(saved), spread(current))


def scenes_usage(made: list[Any]) -> Usage:
    """The LLM usage of a batch of generated scenes (objects with a ``usage`` attribute; None is skipped)."""
    out = Usage()
    for g in made:
        if getattr(g, "usage", None) is not None:
            out.merge(g.usage)
    return out
