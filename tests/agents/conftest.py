"""Fixtures of the agent tests: the tiny preset compiled once per session."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def tiny_set():
    """The ``tiny`` preset (three small houses) as a compiled HouseSet."""
    from adaptenv.agents.houses import load_house_set

    return load_house_set("preset:tiny")


@pytest.fixture(autouse=True)
def one_torch_thread():
    """Small batches run faster (and the same) on one thread; restore the setting afterwards."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
