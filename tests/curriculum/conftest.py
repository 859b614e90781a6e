"""Fixtures of the curriculum tests."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def tiny_policy(tmp_path_factory) -> Path:
    """A small untrained network saved as a checkpoint (the loop only needs something to fine-tune)."""
    import torch

    from adaptenv.agents.checkpoint import save_checkpoint
    from adaptenv.agents.network import NavNet, NetConfig

    torch.manual_seed(0)
    path = tmp_path_factory.mktemp("ckpt") / "tiny.pt"
    save_checkpoint(path, NavNet(NetConfig(hidden=32, feature_dim=32)), {"note": "untrained test network"})
    return path


@pytest.fixture(scope="session")
def loop_run(tmp_path_factory) -> Callable:
    """``loop_run(cfg)``: the records and folder of an in-process run with these settings, run once per session.

    A run is a deterministic function of its settings (test_loop.py's same-seed test checks it), so tests that
    only read a run share it; a test that writes into a run folder or needs a fresh process runs its own.
    """
    from adaptenv.curriculum.loop import run_loop

    runs: dict[str, tuple[list, Path]] = {}

    def run(cfg) -> tuple[list, Path]:
        key = json.dumps(asdict(cfg), sort_keys=True)
        if key not in runs:
            out = tmp_path_factory.mktemp(f"loop-{cfg.method}") / "run"
            runs[key] = (run_loop(cfg, out), out)
        return runs[key]

    return run
