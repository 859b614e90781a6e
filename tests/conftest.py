"""Shared fixtures: the real ProcTHOR house and small generated houses."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

DATA = Path(__file__).parent / "data"
REAL_HOUSE = DATA / "procthor-10k-train-1.json"

FUZZ_SLOW = [HealthCheck.too_slow, HealthCheck.data_too_large]
settings.register_profile("ci", max_examples=100, deadline=None, derandomize=True, database=None,
                          suppress_health_check=FUZZ_SLOW)
settings.register_profile("long", max_examples=10_000, deadline=None, derandomize=False, database=None,
                          suppress_health_check=FUZZ_SLOW)
settings.load_profile(os.environ.get("ADAPTENV_FUZZ_PROFILE", "ci"))
"""Hypothesis examples per property: ``ci`` (the default) runs 100, deterministically;
``ADAPTENV_FUZZ_PROFILE=long`` runs 10,000 random ones (docs/scene.md, "Fuzzing the readers")."""


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
