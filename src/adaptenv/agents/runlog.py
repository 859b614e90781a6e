"""What DAgger (:mod:`adaptenv.agents.train`) and PPO (:mod:`adaptenv.agents.ppo`) training share.

The precision check, the metrics logger and the result record; ``train`` re-exports them.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from adaptenv.agents.checkpoint import non_finite_weight
from adaptenv.agents.config import PRECISIONS, PPOConfig, TrainConfig
from adaptenv.agents.network import END_THRESHOLD, NavNet, NeuralPolicy
from adaptenv.errors import ConfigError, TrainingDiverged
from adaptenv.files import atomic_write_text, open_append


def check_precision(precision: str, where: str) -> None:
    """Raise a ConfigError unless ``precision`` names an arithmetic of the gradient steps (auto, fp32 or bf16)."""
    if precision not in PRECISIONS:
        raise ConfigError(f"{where} must be one of {', '.join(PRECISIONS)}, got {precision!r}")


def check_finite(net: NavNet, cfg: TrainConfig, frames: int, saved_at: int) -> None:
    """Stop with one TrainingDiverged line when a gradient step made a weight NaN or infinite (nothing more is
    saved, so the last checkpoint written, ``saved_at`` updates, stays the last finite one)."""
    if (bad := non_finite_weight(net)) is None:
        return
    kept = (f"the last finite checkpoint, {cfg.output} ({saved_at} updates), is kept" if cfg.output and saved_at
            else "no checkpoint was written")
    raise TrainingDiverged(f"training diverged after {frames:,} frames: the weight {bad} holds NaN or infinite "
                           f"values; {kept}; lower --learning-rate (now {cfg.learning_rate:g}) or --max-grad-norm "
                           f"(now {cfg.max_grad_norm:g})")


def card_config(cfg: TrainConfig | PPOConfig, net: NavNet) -> dict[str, Any]:
    """The run's settings for its card, the network sizes as trained (an ``init`` checkpoint's, not the flags')."""
    c = net.config
    return {**asdict(cfg), "hidden": c.hidden, "feature_dim": c.feature_dim, "conv_channels": c.conv_channels,
            "map_dim": c.map_dim, **({"map": bool(c.map_channels)} if hasattr(cfg, "map") else {})}


LOG_KEYS = ("iteration", "frames", "updates", "wall_time", "charts/beta", "charts/learning_rate",
            "charts/collect_fps", "charts/train_fps", "charts/episodes", "charts/episode_success",
            "charts/episode_length", "charts/buffer_frames", "losses/loss", "losses/accuracy",
            "eval/success", "eval/spl")


class RunLogger:
    """Metrics to ``metrics.csv`` always and to TensorBoard when it is importable."""

    def __init__(self, run_dir: Path | None, tensorboard: bool, keys: Sequence[str] = LOG_KEYS, fresh: bool = True):
        self.keys = tuple(keys)
        self.fresh = fresh
        """A new run: its first row replaces any metrics.csv there (a resumed run appends to its own)."""
        self.rows: list[dict[str, Any]] = []
        self.csv_path = run_dir / "metrics.csv" if run_dir else None
        self.writer = None
        if run_dir and tensorboard:
            try:
                # tensorboard: optional, and slow to import; only when a run asks for it
                from torch.utils.tensorboard import SummaryWriter

                self.writer = SummaryWriter(str(run_dir / "tb"))
            except ImportError:
                self.writer = None

    def log(self, row: dict[str, Any]) -> None:
        self.rows.append(row)
        if self.csv_path is not None:
            values = {k: row.get(k, "") for k in self.keys}
            if self.fresh:  # the first row of a new run: a file of its own, never another's extended
                text = io.StringIO(newline="")
                w = csv.DictWriter(text, fieldnames=list(self.keys), extrasaction="ignore")
                w.writeheader()
                w.writerow(values)
                atomic_write_text(self.csv_path, text.getvalue())
                self.fresh = False
            else:
                new = not self.csv_path.exists()
                with open_append(self.csv_path) as f:
                    w = csv.DictWriter(f, fieldnames=list(self.keys), extrasaction="ignore")
                    if new:
                        w.writeheader()
                    w.writerow(values)
        if self.writer is not None:
            for k, v in row.items():
                if "/" in k and v is not None and v != "":
                    self.writer.add_scalar(k, float(v), int(row["frames"]))

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


@dataclass
class TrainResult:
    """What a run returns: the trained policy network, its card and the logged rows."""

    net: NavNet
    card: dict[str, Any]
    rows: list[dict[str, Any]] = field(default_factory=list)
    learner: dict[str, Any] | None = None
    """PPO's value head and optimizer state (``train_ppo(learner=...)`` continues from them); None for DAgger."""

    def policy(self, *, name: str = "finetuned") -> NeuralPolicy:
        return NeuralPolicy(self.net, name=name, end_threshold=self.card.get("end_threshold", END_THRESHOLD))
