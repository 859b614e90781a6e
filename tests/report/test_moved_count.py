"""The after render's title counts distinct moved objects, not edits."""

from __future__ import annotations

from adaptenv.render.compare import render_before_after


def test_an_object_edited_twice_counts_once(adapted):
    twice = render_before_after(adapted.original, adapted.edited, adapted.before, adapted.after,
                                [adapted.moved, adapted.moved], size=320)
    once = render_before_after(adapted.original, adapted.edited, adapted.before, adapted.after, [adapted.moved],
                               size=320)
    assert twice.moved == [adapted.moved]
    assert twice.after.tobytes() == once.after.tobytes(), "the title says 1 moved object"
