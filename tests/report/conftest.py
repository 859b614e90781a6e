"""Fixtures of the report tests: renders, run and experiment folders (written by run_folders.py), evil text."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.report.run_folders import write_fake_experiment, write_fake_run

EVIL = '<script>alert("x")</script><img src=x onerror=alert(1)> & "quotes"'


@pytest.fixture(scope="session")
def renders(tmp_path_factory) -> tuple[Path, Path]:
    """A real before/after pair: a generated house and the same house with one object moved."""
    from adaptenv.render.topdown import render_house, save_render
    from adaptenv.scene.house import move_object
    from adaptenv.scene.procedural import generate_house

    out = tmp_path_factory.mktemp("renders")
    house = generate_house(3)
    before = save_render(render_house(house, grid=True, size=448, title="before"), out / "before.png")
    moved = house.model_copy(deep=True)
    obj = moved.objects[0]
    move_object(obj, 0.4, -0.3, 90.0)
    after = save_render(render_house(moved, grid=True, size=448, title="after", highlight={obj.id: "gold"}),
                        out / "after.png")
    return before, after


@pytest.fixture
def fake_run(tmp_path, renders) -> Path:
    return write_fake_run(tmp_path / "run", renders)


@pytest.fixture
def fake_experiment(tmp_path, renders) -> Path:
    return write_fake_experiment(tmp_path / "exp", renders)


@pytest.fixture
def make_run(renders):
    """Factory: ``make_run(run_dir, **kw)`` writes a fake run with real renders (see :func:`write_fake_run`)."""
    return lambda run_dir, **kw: write_fake_run(run_dir, renders, **kw)


@pytest.fixture
def make_experiment(renders):
    """Factory: ``make_experiment(exp_dir, **kw)`` (see :func:`write_fake_experiment`)."""
    return lambda exp_dir, **kw: write_fake_experiment(exp_dir, renders, **kw)


@pytest.fixture
def evil() -> str:
    """Text with markup in it, as an LLM's analysis might contain."""
    return EVIL


@pytest.fixture(scope="session")
def adapted():
    """A real adaptation: the expert in e_t, an object moved onto its path, the expert again in e_{t+1}."""
    from tests.report.gallery_check import adapted_scene

    return adapted_scene()
