"""Train the learned G's scorer on ``adaptenv gdata collect`` rows: one config, one linear script.

:func:`train` splits the collection's houses into training houses and held-in houses (a fixed share of
the training houses, the first by a hash of their names: never held-out houses), fits the MLP of
:mod:`adaptenv.adapt.generators.learned` (a logistic loss on whether the candidate passed every check,
a squared loss on what its target predicts for those measured), and keeps the epoch whose ranking is
best on the held-in houses (:func:`chosen_drop`): the mean of that quantity for the candidate the G
would make there, the best-scored one that passed every check.

Two targets (``TrainConfig.target``): ``agent`` predicts the measured drops in the agent's success and
SPL (sampled rollouts: noisy labels); ``objectives`` predicts the gain of each of the built-in G's
route objectives (measured without rollouts: exact labels), weighted at selection and generation time
as the built-in G weighs F's suggestions.
"""

from __future__ import annotations

import warnings
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import spearmanr

from adaptenv.adapt.gdata import Dataset, house_key, load_rows
from adaptenv.adapt.generators.edit_features import FEATURE_NAMES
from adaptenv.adapt.generators.learned import (
    TARGETS,
    ScorerConfig,
    build_net,
    expected_gain,
    objective_weights,
    save_scorer,
)
from adaptenv.adapt.objectives import OBJECTIVE_KINDS, ObjectiveValues, gain, suggestion_weights
from adaptenv.errors import ConfigError


@dataclass
class TrainConfig:
    """Everything a training run depends on (written into the checkpoint's card)."""

    data: list[str] = field(default_factory=list)
    """Collection folders (``adaptenv gdata collect -o``)."""
    out: str = "learned-g.pt"
    seed: int = 0
    epochs: int = 60
    batch: int = 256
    lr: float = 3e-3
    weight_decay: float = 1e-4
    hidden: int = 64
    layers: int = 2
    heldin: int = 5
    """One house in this many is held in (those first by a hash of their key): selection only, never trained on."""
    target: str = "agent"
    """What the scorer predicts beside acceptance: ``agent`` (success and SPL drops) or ``objectives``."""


@dataclass
class Arrays:
    """The rows as arrays: features, labels, masks and the (house, task) group of each row."""

    x: np.ndarray
    usable: np.ndarray
    """1 when the candidate passed placement, validation, the plausibility rules and the expert check."""
    drops: np.ndarray
    """(N, K) the measured labels of the target: success and SPL drops, or the gain per route objective (0 where
    not measured)."""
    measured: np.ndarray
    weights: np.ndarray
    """(N, K) the weight of each label in the score (1 for the agent's drops; per F's suggestions for objectives)."""
    group: np.ndarray
    heldin: np.ndarray


#: Objective gains are clipped to this magnitude as labels (a route that doubles is a gain of 1).
GAIN_CLIP = 2.0


def objective_labels(row: dict[str, Any]) -> tuple[list[float], list[float]] | None:
    """A row's gain per route objective (clipped) and the weights F's analysis gives them at the first step; None
    when the row holds no objectives."""
    obj = row.get("objectives")
    if not obj or any(v is None for part in (obj["before"], obj["after"]) for v in part.values()):
        return None
    before, after = ObjectiveValues(**obj["before"]), ObjectiveValues(**obj["after"])
    gains = [float(np.clip(gain(k, before, after), -GAIN_CLIP, GAIN_CLIP)) for k in OBJECTIVE_KINDS]
    sug = row["analysis"].get("suggestions") or {}
    first = max(sug, key=lambda k: (sug[k], k)) if sug else None
    w = objective_weights(suggestion_weights(first, sug)) if first else np.zeros(len(OBJECTIVE_KINDS))
    return gains, [float(x) for x in w]


def arrays(rows: list[dict[str, Any]], heldin: int, target: str = "agent") -> Arrays:
    """The training arrays of collection rows for ``target`` (rows of another feature list are refused)."""
    if not rows:
        raise ConfigError("the collection holds no rows; run `adaptenv gdata collect` first")
    if len(rows[0]["features"]) != len(FEATURE_NAMES):
        raise ConfigError("the collection's features are not the ones this version computes; collect it again")
    if target not in TARGETS:
        raise ConfigError(f"target {target!r}: use one of {', '.join(TARGETS)}")
    width = len(TARGETS[target]) - 1
    keys = sorted({house_key(r["house"]) for r in rows}, key=lambda k: (zlib.crc32(k.encode("utf-8")), k))
    held_keys = set(keys[:max(1, -(-len(keys) // heldin))]) if len(keys) > 1 else set()
    groups: dict[tuple[str, int], int] = {}
    x, usable, drops, measured, weights, group, held = [], [], [], [], [], [], []
    for r in rows:
        key = house_key(r["house"])
        eff = r.get("effect")
        if target == "agent":
            label = ([eff["success_drop"], eff["spl_drop"]], [1.0, 1.0]) if eff is not None else None
        else:
            label = objective_labels(r)
        x.append(r["features"])
        usable.append(float(bool(r["accepted"] and r["plausible"] and r["expert_success"] and label is not None)))
        measured.append(float(label is not None))
        drops.append(label[0] if label is not None else [0.0] * width)
        weights.append(label[1] if label is not None else [0.0] * width)
        group.append(groups.setdefault((key, r["task"]), len(groups)))
        held.append(key in held_keys)
    if not any(measured):
        fix = ("collect with --episodes 1 or more" if target == "agent" else
               "collect it again with this version, which records the route objectives")
        raise ConfigError(f"the collection holds no row measured for the target {target!r}; {fix}")
    return Arrays(np.asarray(x, np.float32), np.asarray(usable, np.float32), np.asarray(drops, np.float32),
                  np.asarray(measured, np.float32), np.asarray(weights, np.float32), np.asarray(group),
                  np.asarray(held, bool))


def chosen_drop(score: np.ndarray, a: Arrays, mask: np.ndarray) -> dict[str, float]:
    """Per (house, task) group under ``mask``: the measured label (weighted sum) of the best-scored usable candidate
    (what the G makes), against the mean over usable candidates (a random pick) and the best one; means over the
    groups. Also the rank correlation of score and label over the usable candidates (``spearman``)."""
    chosen, rand, best = [], [], []
    value = (a.drops * a.weights).sum(axis=1)
    for g in np.unique(a.group[mask]):
        idx = np.flatnonzero(mask & (a.group == g) & (a.usable > 0))
        if len(idx) == 0:
            continue
        total = value[idx]
        chosen.append(float(total[int(np.argmax(score[idx]))]))
        rand.append(float(total.mean()))
        best.append(float(total.max()))
    if not chosen:
        return {"groups": 0, "chosen": float("nan"), "random": float("nan"), "best": float("nan"), "spearman": None}
    use = np.flatnonzero(mask & (a.usable > 0))
    with warnings.catch_warnings():  # constant drops (nothing measured moved) give NaN, reported as None
        warnings.simplefilter("ignore")
        rho = spearmanr(score[use], value[use]).statistic if len(use) > 2 else float("nan")
    return {"groups": len(chosen), "chosen": float(np.mean(chosen)), "random": float(np.mean(rand)),
            "best": float(np.mean(best)), "spearman": float(rho) if np.isfinite(rho) else None}


def _collection(folder: Path) -> dict[str, Any]:
    """What the card says of one collection: its settings and command (from ``meta.json``)."""
    meta = Dataset(folder).meta() or {}
    return {"folder": str(folder), "command": meta.get("command", ""), "policy": meta.get("policy"),
            "collect": meta.get("collect")}


def train(cfg: TrainConfig, *, progress=None, command: str = "") -> dict[str, Any]:
    """Fit the scorer, keep the best held-in epoch, write it to ``cfg.out``; returns the card written beside it."""
    import torch

    rows = [r for folder in cfg.data for r in load_rows(Path(folder))]
    a = arrays(rows, cfg.heldin, cfg.target)
    tr, hi = ~a.heldin, a.heldin
    if not tr.any() or not hi.any():
        raise ConfigError(f"{len(set(a.group.tolist()))} tasks are too few to hold some houses in; collect more houses")
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    mean = a.x[tr].mean(axis=0)
    std = a.x[tr].std(axis=0)
    std = np.where(std > 1e-6, std, 1.0).astype(np.float32)
    xs = torch.as_tensor((a.x - mean) / std)
    usable, drops, measured = map(torch.as_tensor, (a.usable, a.drops, a.measured))
    scfg = ScorerConfig(hidden=cfg.hidden, layers=cfg.layers, target=cfg.target)
    net = build_net(scfg)
    opt = torch.optim.AdamW(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    train_idx = np.flatnonzero(tr)
    best: dict[str, Any] | None = None
    history = []
    for epoch in range(1, cfg.epochs + 1):
        net.train()
        for b in np.array_split(rng.permutation(train_idx), max(1, len(train_idx) // cfg.batch)):
            out = net(xs[b])
            loss = torch.nn.functional.binary_cross_entropy_with_logits(out[:, 0], usable[b])
            m = measured[b]
            loss = loss + ((out[:, 1:] - drops[b]) ** 2 * m[:, None]).sum() / m.sum().clamp(min=1.0)
            opt.zero_grad()
            loss.backward()
            opt.step()
        net.eval()
        with torch.no_grad():
            score = expected_gain(net(xs).numpy().astype(np.float64), a.weights)  # each row with its step's weights
        held = chosen_drop(score, a, hi)
        history.append({"epoch": epoch, "heldin_chosen": round(held["chosen"], 5)})
        if best is None or held["chosen"] > best["heldin"]["chosen"] + 1e-9:
            best = {"epoch": epoch, "heldin": held, "train": chosen_drop(score, a, tr),
                    "state": {k: v.detach().clone() for k, v in net.state_dict().items()}}
        if progress is not None:
            progress(epoch)
    net.load_state_dict(best["state"])
    card = {
        "format": "adaptenv-learned-g card/1", "command": command, "config": asdict(cfg),
        "collections": [_collection(Path(d)) for d in cfg.data],
        "data": {"rows": len(rows), "houses": len({house_key(r["house"]) for r in rows}),
                 "house_keys": sorted({house_key(r["house"]) for r in rows}),
                 "heldin_houses": sorted({house_key(r["house"]) for r, h in zip(rows, a.heldin, strict=True) if h}),
                 "specs": sorted({r["house"]["spec"] for r in rows}), "policy": sorted({r["policy"] for r in rows}),
                 "usable": int(a.usable.sum()), "measured": int(a.measured.sum()),
                 "tasks": len(set(a.group.tolist()))},
        "selection": {"metric": ("mean drop (success + SPL) of the chosen edit per held-in task" if cfg.target == "agent"
                                 else "mean weighted route-objective gain of the chosen edit per held-in task"),
                      "epoch": best["epoch"], "heldin": best["heldin"], "train": best["train"]},
        "history": history,
    }
    save_scorer(cfg.out, net, scfg, mean, std, card)
    return card


__all__ = ["Arrays", "TrainConfig", "arrays", "chosen_drop", "train"]
