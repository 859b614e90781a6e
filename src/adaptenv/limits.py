"""The ranges of the numbers a user types: seeds, counts, rates and network widths, each checked in one place.

Every check raises one :class:`~adaptenv.errors.ConfigError` sentence naming the flag (or field), the value
and the range, before any work. Seeds are whole numbers from 0 to :data:`SEED_MAX`: numpy's ``SeedSequence``
takes non-negative numbers only, and 32 bits leave room for the derived seeds (``seed * 100_003 + i``) in
64-bit arithmetic. Counts stop at :data:`COUNT_MAX` (a C ``int``), network widths at :data:`WIDTH_MAX`.
"""

from __future__ import annotations

import math
import os
from typing import Any

from adaptenv.errors import ConfigError

SEED_MAX = 2**32 - 1
"""The largest seed a command takes (seeds are 0 .. 2**32 - 1)."""
COUNT_MAX = 2**31 - 1
"""The largest count (frames, episodes, steps) a command takes."""
WIDTH_MAX = 4096
"""The widest network layer (hidden, feature_dim, ...): a 4096-wide GRU already holds 200 M parameters."""
THREADS_MAX = 1024
"""The most torch threads a command takes."""
EPISODE_BYTES = 64 * 1024
"""Memory one evaluated episode may take at most (its result and a 600-step recording): the bound of
:func:`check_episodes`."""

# -- the files a user hands over: the largest of each kind adaptenv reads (README, "Limits") ------------------

MiB = 2**20
HOUSE_BYTES = 32 * MiB
"""The largest house JSON file (ProcTHOR-10K's largest house is under 1 MiB)."""
DATASET_LINE_BYTES = 32 * MiB
"""The longest line of a house dataset (one house), after decompression."""
CONFIG_BYTES = 1 * MiB
"""The largest experiment or LLM config file."""
STATE_BYTES = 64 * MiB
"""The largest run state a command resumes from (a loop's ``state.json``)."""
ASSET_TABLE_BYTES = 64 * MiB
"""The largest ``--assets`` table."""
TRAJECTORY_BYTES = 64 * MiB
"""The largest trajectory JSON file (a 600-step episode takes about 150 KiB)."""
AI2THOR_LOG_BYTES = 256 * MiB
"""The largest AI2-THOR episode log, after decompression."""
ANNOTATIONS_BYTES = 1024 * MiB
"""The largest objathor annotation file, after decompression."""
JSON_DEPTH_MAX = 64
"""The deepest nesting of arrays and objects a JSON file may have (a house nests 6 deep)."""


def check_int(value: Any, flag: str, lo: int = 0, hi: int = COUNT_MAX) -> int:
    """``value`` if it is a whole number in ``lo .. hi``, else a ConfigError naming ``flag``."""
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ConfigError(f"{flag} {value}: must be a whole number from {lo:,} to {hi:,}; pass a value in that range")
    return value


def check_seed(value: Any, flag: str = "--seed") -> int:
    """``value`` if it is a seed (a whole number from 0 to 2**32 - 1), else a ConfigError naming ``flag``."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= SEED_MAX:
        raise ConfigError(f"{flag} {value}: a seed is a whole number from 0 to {SEED_MAX} (2**32 - 1); pass one "
                          "in that range")
    return value


def check_float(value: Any, flag: str, lo: float = 0.0, hi: float = math.inf, *, lo_open: bool = False) -> float:
    """``value`` if it is a finite number in ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``), else a ConfigError."""
    ok = (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
          and (value > lo if lo_open else value >= lo) and value <= hi)
    if not ok:
        bounds = [f"more than {lo:g}" if lo_open else f"at least {lo:g}"] if math.isfinite(lo) else []
        bounds += [f"at most {hi:g}"] if math.isfinite(hi) else []
        range_ = f" {' and '.join(bounds)}" if bounds else ""
        raise ConfigError(f"{flag} {value}: must be a finite number{range_}; pass a value in that range")
    return float(value)


def memory_bytes() -> int:
    """This machine's physical memory in bytes (16 GiB where the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 16 << 30


def check_episodes(value: Any, flag: str = "--episodes") -> int:
    """``value`` if that many episodes fit in memory (:data:`EPISODE_BYTES` each), else a ConfigError naming
    ``flag`` and the limit."""
    most = min(COUNT_MAX, memory_bytes() // EPISODE_BYTES)
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= most:
        raise ConfigError(f"{flag} {value}: must be a whole number from 1 to {most:,} (the episodes that fit in "
                          f"this machine's {memory_bytes() / 2**30:.0f} GiB of memory); pass a number in that range")
    return value


# -- the numbers of a training config, by field name ---------------------------------------------------------

SEEDS = ("seed",)
POSITIVE_COUNTS = ("frames", "num_envs", "rollout_steps", "chunk_len", "batch_chunks", "updates_per_iter",
                   "buffer_frames", "max_episode_steps", "eval_episodes", "save_every", "num_minibatches",
                   "update_epochs")
COUNTS = ("eval_every", "final_eval_episodes", "calibrate_episodes", "value_warmup_iters", "snapshots")
WIDTHS = ("hidden", "feature_dim", "conv_channels", "map_dim")
PROBABILITIES = ("beta_start", "beta_end", "beta_decay_fraction", "beta", "end_threshold", "teacher_mix", "gamma",
                 "gae_lambda")
LEARNING_RATES = ("learning_rate",)
POSITIVE_RATES = ("max_grad_norm", "end_weight")
RATES = ("min_start_distance", "clip_coef", "ent_coef", "vf_coef", "target_kl", "bc_coef", "kl_coef",
         "explore_bonus")


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def check_numbers(cfg: object, flag=_flag) -> None:
    """Check every number field of a run config (TrainConfig, PPOConfig, FinetuneConfig) by its name: seeds, counts,
    widths, probabilities and finite rates; ``flag(name)`` names the field in the message (default ``--name``)."""
    def has(name: str) -> bool:
        return hasattr(cfg, name)

    for name in filter(has, SEEDS):
        check_seed(getattr(cfg, name), flag(name))
    for name in filter(has, POSITIVE_COUNTS):
        check_int(getattr(cfg, name), flag(name), 1)
    for name in filter(has, COUNTS):
        check_int(getattr(cfg, name), flag(name), 0)
    for name in filter(has, WIDTHS):
        check_int(getattr(cfg, name), flag(name), 1, WIDTH_MAX)
    if has("threads"):
        check_int(cfg.threads, flag("threads"), 0, THREADS_MAX)  # type: ignore[attr-defined]
    for name in filter(has, PROBABILITIES):
        check_float(getattr(cfg, name), flag(name), 0.0, 1.0)
    for name in filter(has, LEARNING_RATES):
        check_float(getattr(cfg, name), flag(name), 0.0, 1.0, lo_open=True)
    for name in filter(has, POSITIVE_RATES):
        check_float(getattr(cfg, name), flag(name), lo_open=True)
    for name in filter(has, RATES):
        check_float(getattr(cfg, name), flag(name))
