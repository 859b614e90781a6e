"""Run and experiment folders in the records.py layout, as the report reads them, for the report tests.

Fake-but-schema-valid runs (:func:`write_fake_run`, :func:`write_fake_experiment`) and the run of one
real adaptation (:func:`write_adapted_run`); the fixtures in conftest.py call them.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

from adaptenv.adapt.analysis import (
    Analysis,
    Concern,
    GridPoint,
    Outcome,
    Suggestion,
    analyze_trajectory,
)
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
from adaptenv.render.compare import render_before_after
from adaptenv.scene.house import save_house
from adaptenv.sim.world import compile_world

if TYPE_CHECKING:
    from tests.report.gallery_check import AdaptedScene

SETS = ("rearranged", "unseen")
"""Held-out sets of the fake runs."""


def start_run(run_dir: Path, info: RunInfo) -> Path:
    """Create ``run_dir`` with its run.json."""
    run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(run_dir / RUN_INFO, info.model_dump_json())
    return run_dir


def gallery_dir(run_dir: Path, t: int, scene: str) -> Path:
    """Create the folder of one gallery item of iteration ``t``; returns it relative to ``run_dir``."""
    rel = Path(iteration_dir(run_dir, t).name) / "gallery" / scene
    (run_dir / rel).mkdir(parents=True, exist_ok=True)
    return rel


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
    start_run(run_dir, RunInfo(method=method, seed=seed, config={"iterations": iterations, "note": f"cfg{text}"},
                               command=f"adaptenv loop --method {method} --seed {seed}"))
    records = []
    for t in range(1, iterations + 1):
        gallery = []
        for k in range(scenes):
            scene = f"train-{k}{text.replace('/', '')}"  # a level is a plain name (no folder part), hostile all the same
            rel = gallery_dir(run_dir, t, f"scene{k}")
            folder = run_dir / rel
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


def write_adapted_run(run_dir: Path, scene: AdaptedScene) -> Path:
    """A one-iteration run folder whose gallery item records both houses and both trajectories."""
    start_run(run_dir, RunInfo(method="ours", seed=0))
    rel = gallery_dir(run_dir, 1, "house_04~t01a00")
    folder = run_dir / rel
    save_house(scene.original, folder / "house_before.json")
    save_house(scene.edited, folder / "house_after.json")
    scene.before.save(folder / "trajectory_before.json")
    scene.after.save(folder / "trajectory_after.json")
    world = compile_world(scene.original, "e_t")
    (folder / "analysis.json").write_text(analyze_trajectory(scene.before, world).model_dump_json(), encoding="utf-8")
    pair = render_before_after(scene.original, scene.edited, scene.before, scene.after, [scene.moved], size=448)
    pair.before.save(folder / "before.png")
    pair.after.save(folder / "after.png")
    item = GalleryItem(scene="house_04~t01a00", before_png=str(rel / "before.png"), after_png=str(rel / "after.png"),
                       analysis_json=str(rel / "analysis.json"), before_house_json=str(rel / "house_before.json"),
                       after_house_json=str(rel / "house_after.json"),
                       before_trajectory_json=str(rel / "trajectory_before.json"),
                       after_trajectory_json=str(rel / "trajectory_after.json"), summary="1 edit")
    metrics = SetMetrics(success=0.5, spl=0.4, collisions=1.0, episodes=10)
    write_iterations(run_dir, [IterationRecord(iteration=1, env_steps=1000, grad_updates=10, edits=1, train=metrics,
                                               heldout={"unseen": metrics}, gallery=[item], wall_time_s=5.0)])
    return run_dir
