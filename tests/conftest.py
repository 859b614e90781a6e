"""Shared fixtures: the real ProcTHOR house and small generated houses."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

os.environ["OMP_NUM_THREADS"] = "1"
"""Every torch block of a test, and of the processes it starts, runs on one thread: ``pytest -n 2`` runs two
workers on two cores, and training's default of every available core (``available_cores``, which reads this
variable as an executor's worker does) made two workers' four spinning threads slow each small torch op tens of
times over. Tests of the thread rule set the variable themselves."""

DATA = Path(__file__).parent / "data"
REAL_HOUSE = DATA / "procthor-10k-train-1.json"

CHILD_IDS = ("0f6b3c1e9a8d4e2f8b7c6d5e4f3a2b1c", "7e1d2c3b4a5f46e7a8b9c0d1e2f3a4b5")
FLOOR_ID = "3c4d5e6f7a8b49c0b1d2e3f4a5b6c7d8"
"""Made-up Objaverse-style asset ids (32 hex digits) of :func:`objaverse_house_doc`."""


def objaverse_house_doc(*, floor: bool) -> dict:
    """The real house with two children (on the counter and on the sofa) of made-up Objaverse ids, and
    with ``floor`` also its fridge."""
    doc = json.loads(REAL_HOUSE.read_text(encoding="utf-8"))
    by_id = {o["id"]: o for o in doc["objects"]}
    by_id["CounterTop|2|0"]["children"][0]["assetId"] = CHILD_IDS[0]  # Book|surface|2|0
    by_id["Sofa|3|3"]["children"][1]["assetId"] = CHILD_IDS[1]  # RemoteControl|surface|3|18
    by_id["CounterTop|2|0"]["children"][1]["assetId"] = CHILD_IDS[1]  # Ladle|surface|2|1: same asset again
    if floor:
        by_id["Fridge|2|1"]["assetId"] = FLOOR_ID
    return doc


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
