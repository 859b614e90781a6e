"""Train the learned G's scorer on ``adaptenv gdata collect`` rows: one config, one linear script.

:func:`train` splits the collection's houses into training houses and held-in houses (a fixed share of
the training houses, the first by a hash of their names: never held-out houses), fits the MLP of
:mod:`adaptenv.adapt.generators.learned` (a logistic loss on whether the candidate passed every check,
a squared loss on the measured drops in success and SPL of those measured), and keeps the epoch whose
ranking is best on the held-in houses: the mean drop (success + SPL) of the candidate the G would make
there, the best-scored one that passed every check (:func:`chosen_drop`).
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
from adaptenv.adapt.generators.learned import ScorerConfig, build_net, expected_gain, save_scorer
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


@dataclass
class Arrays:
    """The rows as arrays: features, labels, masks and the (house, task) group of each row."""

    x: np.ndarray
    usable: np.ndarray
    """1 when the candidate passed placement, validation, the plausibility rules and the expert check."""
    drops: np.ndarray
    """(N, 2) measured success and SPL drops (0 where not measured)."""
    measured: np.ndarray
    group: np.ndarray
    heldin: np.ndarray


def arrays(rows: list[dict[str, Any]], heldin: int) -> Arrays:
    """The training arrays of collection rows (rows of another feature list are refused)."""
    if not rows:
        raise ConfigError("the collection holds no rows; run `adaptenv gdata collect` first")
    if len(rows[0]["features"]) != len(FEATURE_NAMES):
        raise ConfigError("the collection's features are not the ones this version computes; collect it again")
    keys = sorted({house_key(r["house"]) for r in rows}, key=lambda k: (zlib.crc32(k.encode("utf-8")), k))
    held_keys = set(keys[:max(1, -(-len(keys) // heldin))]) if len(keys) > 1 else set()
    groups: dict[tuple[str, int], int] = {}
    x, usable, drops, measured, group, held = [], [], [], [], [], []
    for r in rows:
        key = house_key(r["house"])
        eff = r.get("effect")
        x.append(r["features"])
        usable.append(float(bool(r["accepted"] and r["plausible"] and r["expert_success"] and eff is not None)))
        measured.append(float(eff is not None))
        drops.append([eff["success_drop"], eff["spl_drop"]] if eff is not None else [0.0, 0.0])
        group.append(groups.setdefault((key, r["task"]), len(groups)))
        held.append(key in held_keys)
    return Arrays(np.asarray(x, np.float32), np.asarray(usable, np.float32), np.asarray(drops, np.float32),
                  np.asarray(measured, np.float32), np.asarray(group), np.asarray(held, bool))


def chosen_drop(score: np.ndarray, a: Arrays, mask: np.ndarray) -> dict[str, float]:
    """Per (house, task) group under ``mask``: the measured drop of the best-scored usable candidate (what the G
    makes), against the mean over usable candidates (a random pick) and the best one; means over the groups. Also
    the rank correlation of score and measured drop over the usable candidates (``spearman``)."""
    chosen, rand, best = [], [], []
    for g in np.unique(a.group[mask]):
        idx = np.flatnonzero(mask & (a.group == g) & (a.usable > 0))
        if len(idx) == 0:
            continue
        total = a.drops[idx].sum(axis=1)
        chosen.append(float(total[int(np.argmax(score[idx]))]))
        rand.append(float(total.mean()))
        best.append(float(total.max()))
    if not chosen:
        return {"groups": 0, "chosen": float("nan"), "random": float("nan"), "best": float("nan"), "spearman": None}
    use = np.flatnonzero(mask & (a.usable > 0))
    with warnings.catch_warnings():  # constant drops (nothing measured moved) give NaN, reported as None
        warnings.simplefilter("ignore")
        rho = spearmanr(score[use], a.drops[use].sum(axis=1)).statistic if len(use) > 2 else float("nan")
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
    a = arrays(rows, cfg.heldin)
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
    scfg = ScorerConfig(hidden=cfg.hidden, layers=cfg.layers)
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
            score = expected_gain(net(xs).numpy().astype(np.float64))
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
        "selection": {"metric": "mean drop (success + SPL) of the chosen edit per held-in task",
                      "epoch": best["epoch"], "heldin": best["heldin"], "train": best["train"]},
        "history": history,
    }
    save_scorer(cfg.out, net, scfg, mean, std, card)
    return card


__all__ = ["Arrays", "TrainConfig", "arrays", "chosen_drop", "train"]
