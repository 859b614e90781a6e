"""Policy checkpoints: the network's architecture and weights plus a small metadata card.

A checkpoint is a ``torch.save`` dictionary ``{"format", "net_config", "state_dict", "classes",
"observation_version", "meta"}``. It is written atomically (temporary file, then rename) so an
interrupted run never leaves a truncated checkpoint behind. Loading checks that the observation
layout and the semantic class list match this version of the simulator.
"""

from __future__ import annotations

import os
import tempfile
import warnings
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import torch

from adaptenv.agents.network import END_THRESHOLD, NavNet, NetConfig, NeuralPolicy
from adaptenv.configfile import printable
from adaptenv.errors import ConfigError, TrainingDiverged
from adaptenv.limits import WIDTH_MAX
from adaptenv.sim.egomap import CROP, MAP_CHANNELS
from adaptenv.sim.perception import N_SHAPE
from adaptenv.sim.spec import N_ACTIONS, N_RAYS, OBSERVATION_VERSION, n_classes, object_classes

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


def non_finite_weight(net: torch.nn.Module) -> str | None:
    """The name of the first weight of ``net`` holding NaN or infinity, or None when all are finite."""
    return next((k for k, v in net.state_dict().items()
                 if v.is_floating_point() and not bool(torch.isfinite(v).all())), None)


def save_checkpoint(path: str | Path, net: NavNet, meta: dict[str, Any] | None = None) -> Path:
    """Write ``net`` (architecture + weights, float32 on CPU) and ``meta`` to ``path`` atomically; weights that are
    not finite raise :class:`TrainingDiverged` and write nothing (an earlier checkpoint at ``path`` stays)."""
    if (bad := non_finite_weight(net)) is not None:
        raise TrainingDiverged(f"{path}: not written, the weight {bad} holds NaN or infinite values (training "
                               "diverged); lower --learning-rate or --max-grad-norm and train again")
    state = {k: v.detach().to("cpu", torch.float32).clone() for k, v in net.state_dict().items()}
    return atomic_torch_save({
        "format": FORMAT,
        "net_config": asdict(net.config),
        "state_dict": state,
        "classes": list(object_classes()),
        "observation_version": OBSERVATION_VERSION,
        "meta": dict(meta or {}),
    }, path)


def load_tensors(path: str | Path) -> Any:
    """``torch.load`` of tensors and plain data only (``weights_only``: never code), on the CPU, without torch's
    warning about a foreign pickle protocol (a damaged file then fails in one line, not under a warning)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Detected pickle protocol", category=UserWarning)
        return torch.load(path, map_location="cpu", weights_only=True)


def load_checkpoint(path: str | Path) -> Checkpoint:
    """Read a checkpoint written by :func:`save_checkpoint`; problems raise one clear ConfigError."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: no such checkpoint; train one with `adaptenv train ... -o {p}`")
    try:
        doc = load_tensors(p)
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
    config = checked_net_config(doc.get("net_config"), p)
    state = checked_state_dict(doc.get("state_dict"), config, p)
    meta = doc.get("meta", {})
    threshold = meta.get("end_threshold", END_THRESHOLD) if isinstance(meta, dict) else None
    if not isinstance(threshold, (int, float)) or isinstance(threshold, bool) or not 0.0 <= threshold <= 1.0:
        raise ConfigError(f"{p}: meta.end_threshold {threshold!r} is not a probability (the meta must be a dict "
                          "with end_threshold in [0, 1]); re-create the checkpoint with `adaptenv train`")
    net = NavNet(config)
    net.load_state_dict(state)
    net.eval()
    return Checkpoint(net, dict(meta), p)


NET_FIXED = {"n_rays": N_RAYS, "n_actions": N_ACTIONS}
"""NetConfig fields the observation fixes: a checkpoint must hold exactly these values."""


def checked_net_config(raw: Any, path: Path) -> NetConfig:
    """The checkpoint's network config, or one ConfigError (before anything is allocated) when a field is unknown,
    not a whole number, does not fit this simulator's observation, or is wider than WIDTH_MAX."""
    fix = "re-create the checkpoint with `adaptenv train`"
    names = [f.name for f in fields(NetConfig)]
    if not isinstance(raw, dict) or set(raw) - set(names):
        got = (", ".join(printable(str(k)) for k in sorted(map(str, set(raw) - set(names))))
               if isinstance(raw, dict) else type(raw).__name__)
        raise ConfigError(f"{path}: net_config holds {got}, not only the fields {', '.join(names)}; {fix}")
    raw = {**asdict(NetConfig()), **raw}  # checkpoints from before a field existed have its default
    expected = {**NET_FIXED, "n_classes": n_classes(), "map_crop": CROP}
    for name in names:
        value = raw[name]
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{path}: net_config.{name} {value!r} is not a whole number; {fix}")
        if name in expected and value != expected[name] and not (name == "n_classes" and value == 0):
            raise ConfigError(f"{path}: net_config.{name} is {value}, this simulator's observation needs "
                              f"{expected[name]}; {fix}")
        if name == "map_channels" and value not in (0, MAP_CHANNELS):
            raise ConfigError(f"{path}: net_config.map_channels is {value}, expected 0 or {MAP_CHANNELS}; {fix}")
        if name == "shape_features" and value not in (0, N_SHAPE):
            raise ConfigError(f"{path}: net_config.shape_features is {value}, expected 0 or {N_SHAPE}; {fix}")
        if name not in expected and name not in ("map_channels", "shape_features") and not 1 <= value <= WIDTH_MAX:
            raise ConfigError(f"{path}: net_config.{name} is {value}, outside 1 .. {WIDTH_MAX}; {fix}")
    return NetConfig(**raw)


def checked_state_dict(state: Any, config: NetConfig, path: Path) -> dict[str, torch.Tensor]:
    """The checkpoint's weights, or one ConfigError when a tensor is missing, unknown, of another shape than
    ``config``'s network (built on the meta device: nothing allocated) or not finite."""
    fix = "re-create the checkpoint with `adaptenv train`"
    with torch.device("meta"):
        shapes = {k: tuple(v.shape) for k, v in NavNet(config).state_dict().items()}
    if not isinstance(state, dict) or set(state) != set(shapes):
        keys = set(state) if isinstance(state, dict) else set()
        wrong = sorted(set(shapes) ^ keys)[:3] if keys else ["(not a dict of tensors)"]
        raise ConfigError(f"{path}: the weights do not fit the network of its net_config ({', '.join(printable(str(w)) for w in wrong)} "
                          f"missing or unknown); {fix}")
    for name, shape in shapes.items():
        t = state[name]
        if not isinstance(t, torch.Tensor) or tuple(t.shape) != shape:
            got = tuple(t.shape) if isinstance(t, torch.Tensor) else type(t).__name__
            raise ConfigError(f"{path}: weight {name} has shape {got}, its net_config's network needs {shape}; {fix}")
        if not t.is_floating_point():
            raise ConfigError(f"{path}: weight {name} is of type {t.dtype}, not floating point; {fix}")
        if not bool(torch.isfinite(t).all()):
            raise ConfigError(f"{path}: weight {name} holds NaN or infinite values (training diverged); retrain with a "
                              "lower --learning-rate")
    return state
