"""The loop's gallery: before/after renders, analysis and edit log of a few made scenes per iteration."""

from __future__ import annotations

import json
from pathlib import Path

from adaptenv.curriculum.jobs import Generated
from adaptenv.curriculum.records import GalleryItem, iteration_dir
from adaptenv.render.topdown import render_house
from adaptenv.scene.house import House
from adaptenv.sim.trajectory import Trajectory

#: Fill colour of the objects a child's edits moved.
MOVED_COLOUR = "#e6194b"


def gallery_item(run_dir: Path, t: int, name: str, parent: House, made: Generated,
                 before: Trajectory | None) -> GalleryItem:
    """Write one made scene's renders (pi_t's own episode in each house), analysis and edits; return its record."""
    d = iteration_dir(run_dir, t) / "gallery" / name
    d.mkdir(parents=True, exist_ok=True)
    moved = {oid: MOVED_COLOUR for oid in made.moved}
    render_house(parent, trajectory=before, grid=True, size=640).save(d / "before.png")
    render_house(made.house, trajectory=made.after, grid=True, size=640, highlight=moved or None).save(d / "after.png")
    item = GalleryItem(scene=name, before_png=str((d / "before.png").relative_to(run_dir)),
                       after_png=str((d / "after.png").relative_to(run_dir)))
    if made.analysis is not None:
        (d / "analysis.json").write_text(made.analysis.model_dump_json(indent=1), encoding="utf-8")
        item.analysis_json = str((d / "analysis.json").relative_to(run_dir))
        item.summary = made.analysis.outcome.summary
    (d / "edits.json").write_text(json.dumps(made.edit_log, indent=1, default=str), encoding="utf-8")
    item.edits_json = str((d / "edits.json").relative_to(run_dir))
    return item
