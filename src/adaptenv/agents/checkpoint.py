"""Policy checkpoints: the network's architecture and weights plus a small metadata card.

A checkpoint is a ``torch.save`` dictionary ``{"format", "net_config", "state_dict", "classes",
"observation_version", "meta"}``. It is written atomically (temporary file, then rename) so an
interrupted run never leaves a truncated checkpoint behind. Loading checks that the observation
layout and the semantic class list match this version of the simulator.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch

from adaptenv.agents.network import END_THRESHOLD, NavNet, NetConfig, NeuralPolicy
from adaptenv.errors import ConfigError
from adaptenv.sim.spec import OBSERVATION_VERSION, object_classes

FORMAT = "adaptenv-policy/1"


@dataclass
class Checkpoint:
    """A loaded checkpoint: the network (eval mode) and its metadata."""

    net: NavNet
    meta: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None

    def policy(self, *, greedy: bool = False, seed: int = 0) -> NeuralPolicy:
        """The network wrapped as a batched policy."""
        name = self.path.name if self.path is not None else "neural"
        threshold = float(self.meta.get("end_threshold", END_THRESHOLD))
        return NeuralPolicy(self.net, greedy=greedy, seed=seed, name=name, end_threshold=threshold)


def atomic_torch_save(obj: Any, path: str | Path) -> Path:
    """``torch.save`` to a temporary file in the same folder, then rename over ``path``."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    os.close(fd)
    try:
        torch.save(obj, tmp)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; checkpoints are ordinary readable files
        os.replace(tmp, p)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return p


def save_checkpoint(path: str | Path, net: NavNet, meta: dict[str, Any] | None = None) -> Path:
    """Write ``net`` (architecture + weights, float32 on CPU) and ``meta`` to ``path`` atomically."""
    state = {k: v.detach().to("cpu", torch.float32).clone() for k, v in net.state_dict().items()}
    return atomic_torch_save({
        "format": FORMAT,
        "net_config": asdict(net.config),
        "state_dict": state,
        "classes": list(object_classes()),
        "observation_version": OBSERVATION_VERSION,
        "meta": dict(meta or {}),
    }, path)


def load_checkpoint(path: str | Path) -> Checkpoint:
    """Read a checkpoint written by :func:`save_checkpoint`; problems raise one clear ConfigError."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: no such checkpoint; train one with `adaptenv train ... -o {p}`")
    try:
        doc = torch.load(p, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for corrupt files
        raise ConfigError(f"{p}: not a readable torch checkpoint ({type(exc).__name__}); "
                          "re-create it with `adaptenv train`") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ConfigError(f"{p}: not an adaptenv policy checkpoint (expected format {FORMAT!r}); "
                          "write it with `adaptenv train`")
    if doc.get("observation_version") != OBSERVATION_VERSION or doc.get("classes") != list(object_classes()):
        raise ConfigError(f"{p}: trained for another observation layout or class list "
                          f"(observation_version {doc.get('observation_version')}, this simulator has "
                          f"{OBSERVATION_VERSION}); retrain it with `adaptenv train`")
    net = NavNet(NetConfig(**doc["net_config"]))
    net.load_state_dict(doc["state_dict"])
    net.eval()
    return Checkpoint(net, dict(doc.get("meta", {})), p)
