"""Shared fixtures: the real ProcTHOR house and small generated houses."""

from __future__ import annotations

from pathlib import Path

import pytest

DATA = Path(__file__).parent / "data"
REAL_HOUSE = DATA / "procthor-10k-train-1.json"


@pytest.fixture(autouse=True, scope="session")
def _one_torch_thread():
    """Tests run two workers on two cores: one torch thread each, as the CLI and the loop's workers use."""
    import torch

    torch.set_num_threads(1)


@pytest.fixture
def real_house_path() -> Path:
    """A real ProcTHOR-10K house (10 rooms, 68 top-level objects)."""
    return REAL_HOUSE


@pytest.fixture
def real_house():
    from adaptenv.scene.house import load_house

    return load_house(REAL_HOUSE, validate=False)
