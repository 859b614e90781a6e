"""The gallery's before/after pair: drawn by render_before_after from the recorded episodes, never the old path."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from adaptenv.errors import AdaptenvError
from adaptenv.render.compare import MOVED_COLOUR, moved_objects, render_before_after
from adaptenv.render.topdown import render_map
from adaptenv.report import build_report
from adaptenv.report.html import GALLERY_SIZE
from tests.report.gallery_check import path_pixels_in
from tests.report.run_folders import write_adapted_run


def after_images(index: Path) -> list[Path]:
    """Files of the gallery's "after" images, from the page's <img alt="..., after">."""
    text = index.read_text(encoding="utf-8")
    return [index.parent / src for src, alt in re.findall(r'<img src="([^"]+)" alt="([^"]+)"', text)
            if alt.endswith(", after")]


def test_the_fixture_moves_an_object_onto_the_old_path(adapted):
    assert moved_objects(adapted.original, adapted.edited) == [adapted.moved]
    old = render_map(adapted.edited, trajectory=adapted.before, grid=True, size=GALLERY_SIZE,
                     highlight={adapted.moved: MOVED_COLOUR})
    assert path_pixels_in(old.image, old.layout, adapted.edited, [adapted.moved], adapted.before) > 50, \
        "the check must see the old path drawn through the moved object (the bug it guards against)"


def test_report_after_render_is_pi_t_in_the_edited_scene(tmp_path, adapted):
    index = build_report(write_adapted_run(tmp_path / "run", adapted))
    [after] = after_images(index)
    pair = render_before_after(adapted.original, adapted.edited, adapted.before, adapted.after, size=GALLERY_SIZE)
    shown = Image.open(after).convert("RGB")
    assert shown.tobytes() == pair.after.tobytes(), "the report draws with render_before_after"
    assert path_pixels_in(shown, pair.after_layout, adapted.edited, [adapted.moved], adapted.after) == 0
    text = index.read_text(encoding="utf-8")
    assert "What changed for pi_t" in text and "own episode in the edited scene" in text
    spl = f"{adapted.before.metrics.spl:.2f}", f"{adapted.after.metrics.spl:.2f}"
    assert re.search(rf"<td class=l>SPL</td><td>{spl[0]}</td><td[^>]*>{spl[1]}</td>", text)


def test_a_run_without_episodes_keeps_its_renders_and_says_so(tmp_path, make_run):
    text = build_report(make_run(tmp_path / "run", iterations=1, scenes=1)).read_text(encoding="utf-8")
    assert "did not record pi_t&#x27;s episode there" in text and "What changed" not in text


def test_before_after_needs_the_same_start(adapted):
    moved_start = adapted.after.model_copy(deep=True)
    moved_start.start.x += 0.5
    with pytest.raises(AdaptenvError, match="same start"):
        render_before_after(adapted.original, adapted.edited, adapted.before, moved_start)


def test_side_by_side_and_legend(adapted):
    pair = render_before_after(adapted.original, adapted.edited, adapted.before, adapted.after, size=448)
    both = pair.side_by_side()
    assert both.width > pair.before.width + pair.after.width and both.height > pair.after.height
    assert "SPL" in pair.summary() and "collisions" in pair.summary()
    # the legend names the highlight colour: the after render has the cyan swatch, the before render none
    def cyan_pixels(image: Image.Image, top: int) -> int:
        return int((np.asarray(image)[top:] == (0, 170, 210)).all(axis=-1).sum())

    assert cyan_pixels(pair.after, int(pair.after_layout.legend_top)) > 20 and cyan_pixels(pair.before, 0) == 0
