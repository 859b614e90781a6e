"""What DAgger (:mod:`adaptenv.agents.train`) and PPO (:mod:`adaptenv.agents.ppo`) training share.

The precision check, the metrics logger and the result record; ``train`` re-exports them.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from adaptenv.agents.config import PRECISIONS
from adaptenv.agents.network import END_THRESHOLD, NavNet, NeuralPolicy
from adaptenv.errors import ConfigError


def check_precision(precision: str, where: str) -> None:
    """Raise a ConfigError unless ``precision`` names an arithmetic of the gradient steps (fp32 or bf16)."""
    if precision not in PRECISIONS:
        raise ConfigError(f"{where} must be one of {', '.join(PRECISIONS)}, got {precision!r}")


LOG_KEYS = ("iteration", "frames", "updates", "wall_time", "charts/beta", "charts/learning_rate",
            "charts/collect_fps", "charts/train_fps", "charts/episodes", "charts/episode_success",
            "charts/episode_length", "charts/buffer_frames", "losses/loss", "losses/accuracy",
            "eval/success", "eval/spl")


class RunLogger:
    """Metrics to ``metrics.csv`` always and to TensorBoard when it is importable."""

    def __init__(self, run_dir: Path | None, tensorboard: bool, keys: Sequence[str] = LOG_KEYS):
        self.keys = tuple(keys)
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
            new = not self.csv_path.exists()
            with self.csv_path.open("a", newline="", encoding="utf-8") as f:
                w = csv.DictWriter(f, fieldnames=list(self.keys), extrasaction="ignore")
                if new:
                    w.writeheader()
                w.writerow({k: row.get(k, "") for k in self.keys})
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
