"""Fixtures of the curriculum tests."""

from __future__ import annotations

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
