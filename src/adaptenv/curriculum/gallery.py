"""The loop's gallery: both houses, both episodes of pi_t, renders, analysis and edit log of a few made scenes."""

from __future__ import annotations

import json
from pathlib import Path

from adaptenv.curriculum.jobs import Generated
from adaptenv.curriculum.records import GalleryItem, iteration_dir
from adaptenv.files import atomic_write_text
from adaptenv.render.compare import MOVED_COLOUR, render_before_after
from adaptenv.render.topdown import render_house, save_render
from adaptenv.scene.house import House, save_house
from adaptenv.sim.trajectory import Trajectory


def gallery_item(run_dir: Path, t: int, name: str, parent: House, made: Generated,
                 before: Trajectory | None) -> GalleryItem:
    """Write one made scene's files and renders and return its record (paths relative to ``run_dir``).

    With both of pi_t's episodes (the parent's, and its own in the child) the pair is drawn by
    :func:`~adaptenv.render.compare.render_before_after`, the function ``adaptenv adapt`` and the
    report use; children that were not rolled out (random edits) show the houses without a path.
    """
    d = iteration_dir(run_dir, t) / "gallery" / name
    d.mkdir(parents=True, exist_ok=True)

    def rel(p: Path) -> str:
        return str(p.relative_to(run_dir))

    item = GalleryItem(scene=name, before_png=rel(d / "before.png"), after_png=rel(d / "after.png"),
                       before_house_json=rel(save_house(parent, d / "house_before.json")),
                       after_house_json=rel(save_house(made.house, d / "house_after.json")))
    if before is not None and made.after is not None:
        pair = render_before_after(parent, made.house, before, made.after, made.moved, size=640)
        save_render(pair.before, d / "before.png")
        save_render(pair.after, d / "after.png")
        item.before_trajectory_json = rel(before.save(d / "trajectory_before.json"))
        item.after_trajectory_json = rel(made.after.save(d / "trajectory_after.json"))
    else:
        save_render(render_house(parent, grid=True, size=640, title="before"), d / "before.png")
        save_render(render_house(made.house, grid=True, size=640, highlight={oid: MOVED_COLOUR for oid in made.moved}
                                 or None, title="after (not rolled out)"), d / "after.png")
    if made.analysis is not None:
        atomic_write_text(d / "analysis.json", made.analysis.model_dump_json(indent=1))
        item.analysis_json = rel(d / "analysis.json")
        item.summary = made.analysis.outcome.summary
    atomic_write_text(d / "edits.json", json.dumps(made.edit_log, indent=1, default=str))
    item.edits_json = rel(d / "edits.json")
    return item
