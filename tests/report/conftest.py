"""Fixtures writing fake-but-schema-valid run and experiment folders (records.py layout) for report tests."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from adaptenv.adapt.analysis import Analysis, Concern, GridPoint, Outcome, Suggestion
from adaptenv.adapt.edits import Edit, EditLog
from adaptenv.curriculum.records import (
    RUN_INFO,
    GalleryItem,
    IterationRecord,
    RunInfo,
    SetMetrics,
    atomic_write_text,
    iteration_dir,
    write_iterations,
)

EVIL = '<script>alert("x")</script><img src=x onerror=alert(1)> & "quotes"'
SETS = ("rearranged", "unseen")


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


def fake_analysis(k: int, text: str = "") -> Analysis:
    """A plausible analysis; ``text`` is put into every free-text field (to test escaping)."""
    return Analysis(
        task=f"Find a Television (ObjectNav) in house train-{k}.{text}",
        outcome=Outcome(success=k % 2 == 0, failure_mode=None if k % 2 == 0 else "looping",
                        summary=f"episode {k} summary{text}", steps=120 + k, spl=0.4 if k % 2 == 0 else 0.0),
        concerns=[Concern(id="c1", kind="collision", severity=0.6, description=f"3 blocked moves against Sofa|3|0{text}",
                          steps=[10, 14], where=GridPoint(x=42.0, y=55.0), objects=["Sofa|3|0"]),
                  Concern(id="c2", kind="late_sight", severity=0.8, description="the target was first seen late",
                          steps=[90])],
        suggestions=[Suggestion(id="s1", kind="narrow_passage", description=f"narrow the passage by the sofa{text}",
                                addresses=["c1"], priority=0.9),
                     Suggestion(id="s2", kind="occlude_target", description="hide the television", addresses=["c2"],
                                priority=0.6)],
    )


def fake_edits(text: str = "") -> EditLog:
    return EditLog(edits=[
        Edit(object_id="Sofa|3|0", dx_units=10.0, dy_units=-5.0, rotation=90.0, achieved_dx=0.4, achieved_dz=-0.3,
             achieved_dx_units=6.5, achieved_dy_units=-5.0, yaw_before=0.0, yaw_after=90.0,
             stop_reason="blocked_by_object", blocked_by="DiningTable|3|2", steps=13, source="llm",
             intent=f"narrow the corridor{text}"),
        Edit(object_id="Stool|2|6", dx_units=0.0, dy_units=20.0, accepted=False, stop_reason="invalid",
             problems=["the target is no longer reachable"], source="llm"),
    ])


def fake_generation_log(text: str = "") -> dict:
    """An edits.json in the generator's format (steps with verification), as adapt/pipeline.py writes it."""
    log = fake_edits(text)
    return {"generator": "builtin", "usage": {}, "objective_trace": [],
            "edit_log": [e.model_dump(mode="json") for e in log.edits],
            "steps": [{"step": 1, "status": "applied", "suggestion_id": "s1", "suggestion_kind": "narrow_passage",
                       "edit": log.edits[0].model_dump(mode="json"), "reason": "clearance fell 0.2 m",
                       "verified": True, "verification": "objective"},
                      {"step": 2, "status": "skipped", "reason": f"no candidate improved the objective{text}"}]}


def write_fake_run(run_dir: Path, renders: tuple[Path, Path] | None, *, method: str = "ours", seed: int = 0,
                   iterations: int = 3, scenes: int = 2, text: str = "", offset: float = 0.0) -> Path:
    """A run folder with ``iterations`` records, each with ``scenes`` gallery items (renders, analysis, edits)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(run_dir / RUN_INFO, RunInfo(method=method, seed=seed, config={"iterations": iterations,
                      "note": f"cfg{text}"}, command=f"adaptenv loop --method {method} --seed {seed}").model_dump_json())
    records = []
    for t in range(1, iterations + 1):
        gallery = []
        for k in range(scenes):
            scene = f"train-{k}{text}" if text else f"train-{k}"
            rel = Path(iteration_dir(run_dir, t).name) / "gallery" / f"scene{k}"
            folder = run_dir / rel
            folder.mkdir(parents=True, exist_ok=True)
            if renders is not None:
                shutil.copyfile(renders[0], folder / "before.png")
                shutil.copyfile(renders[1], folder / "after.png")
            (folder / "analysis.json").write_text(fake_analysis(k, text).model_dump_json(indent=1), encoding="utf-8")
            edits = fake_generation_log(text) if k % 2 else fake_edits(text).model_dump(mode="json")
            (folder / "edits.json").write_text(json.dumps(edits), encoding="utf-8")
            gallery.append(GalleryItem(scene=scene, before_png=str(rel / "before.png"), after_png=str(rel / "after.png"),
                                       analysis_json=str(rel / "analysis.json"), edits_json=str(rel / "edits.json"),
                                       summary=f"2 edits{text}"))
        base = min(0.95, 0.2 + 0.15 * t + offset)
        heldout = {s: SetMetrics(success=base - 0.05 * i, spl=(base - 0.05 * i) * 0.7, collisions=2.0, episodes=50,
                                 success_se=0.05, spl_se=0.04) for i, s in enumerate(SETS)}
        records.append(IterationRecord(iteration=t, env_steps=20_000 * t + seed * 100, grad_updates=50 * t,
                                       edits=10 * t, train=SetMetrics(success=base + 0.1, spl=base * 0.8,
                                                                      collisions=1.0, episodes=32),
                                       heldout=heldout, gallery=gallery, wall_time_s=61.0 * t))
    if iterations:
        write_iterations(run_dir, records)
    return run_dir


@pytest.fixture
def fake_run(tmp_path, renders) -> Path:
    return write_fake_run(tmp_path / "run", renders)


def write_fake_experiment(exp: Path, renders: tuple[Path, Path] | None, *, methods=("ours", "accel", "dr"),
                          seeds=(0, 1, 2), iterations: int = 3, summary: bool = True) -> Path:
    """EXP_DIR/<method>/seed_<s>/ run folders (1 scene per iteration) plus summary.json with p-values and a CSV."""
    for j, m in enumerate(methods):
        for s in seeds:
            write_fake_run(exp / m / f"seed_{s}", renders, method=m, seed=s, iterations=iterations, scenes=1,
                           offset=0.1 * (len(methods) - j) + 0.02 * s)
    if summary:  # the layout of adaptenv.curriculum.experiment.summarize: ours compared with each method
        reference = methods[0]
        doc = {"methods": {m: {f"{k}:{st}": {"mean": 0.5, "se": 0.01, "n": len(seeds)} for k in ("success", "spl")
                               for st in SETS} for m in methods},
               "tests": {m: {f"{k}:{st}": (0.003 if j == 1 else 0.2) if k == "success" else None
                             for k in ("success", "spl") for st in SETS}
                         for j, m in enumerate(methods) if m != reference},
               "reference": reference, "seeds": list(seeds)}
        (exp / "summary.json").write_text(json.dumps(doc), encoding="utf-8")
        (exp / "summary.md").write_text("| method |\n", encoding="utf-8")
        for m in methods:
            (exp / m / "per_seed.csv").write_text("metric:set,seed_0\nsuccess:unseen,0.5\n", encoding="utf-8")
    return exp


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
