"""Before and after an adaptation: pi_t's episode in e_t beside pi_t's own episode in e_{t+1}.

:func:`render_before_after` is the one function that draws an adaptation, for ``adaptenv adapt``,
the closed loop's gallery and the report alike. Each side shows the episode that really happened
in the scene drawn under it (same start and target on both sides), with that episode's own figures
in the header; the objects the edit moved are filled with :data:`MOVED_COLOUR`, which the legend
names ("moved object"). :meth:`BeforeAfter.side_by_side` puts the two next to each other above a
line saying what changed (success, SPL, path length, collisions, steps).

Example:
    >>> pair = render_before_after(house, edited, before, after, moved_objects(house, edited))  # doctest: +SKIP
    >>> pair.side_by_side().save("before_after.png")  # doctest: +SKIP
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from PIL import Image

from adaptenv.errors import AdaptenvError
from adaptenv.render.topdown import (
    BACKGROUND,
    CAPTION_TEXT,
    FAILURE_TEXT,
    SUCCESS_TEXT,
    MapLayout,
    draw_text,
    render_map,
    text_size,
)
from adaptenv.scene.house import House
from adaptenv.sim.trajectory import Trajectory

MOVED_COLOUR = "#00aad2"
"""Cyan: apart from the path (yellow -> orange), the markers (green, purple), collisions (red) and the target (orange)."""
SAME_START = 1e-6
"""Before and after episodes must start within this distance (m) and heading (degrees) of each other."""
SAME_PLACE = 1e-3
"""An object counts as moved when its position changed by more than this (m) or its yaw by more (degrees)."""


@dataclass(frozen=True)
class Change:
    """One figure before and after, as text, and whether it got better, worse or stayed."""

    name: str
    before: str
    after: str
    trend: int
    """+1 better for the agent, -1 worse, 0 unchanged (success, SPL higher is better; the rest lower)."""


@dataclass
class BeforeAfter:
    """The two renders, their layouts (pixel transforms) and what changed between the episodes."""

    before: Image.Image
    after: Image.Image
    before_layout: MapLayout
    after_layout: MapLayout
    changes: list[Change] = field(default_factory=list)
    moved: list[str] = field(default_factory=list)

    def summary(self) -> str:
        """'success yes -> no, SPL 0.81 -> 0.55, ...' (one line, plain text)."""
        return ", ".join(f"{c.name} {c.before} -> {c.after}" for c in self.changes)

    def side_by_side(self, gap: int = 16) -> Image.Image:
        """Before (left) and after (right) on one image, with the changes written underneath."""
        fs = max(12, round(max(self.before.width, self.after.width) / 50))
        _, line_h = text_size("Hg", fs)
        height = max(self.before.height, self.after.height)
        width = self.before.width + gap + self.after.width
        strip = int(line_h * 2.2)
        out = Image.new("RGB", (width, height + strip), BACKGROUND)
        out.paste(self.before, (0, 0))
        out.paste(self.after, (self.before.width + gap, 0))
        x, y = fs * 0.8, height + strip / 2
        parts = [("for the agent (green better, red worse):  ", CAPTION_TEXT)]
        for k, c in enumerate(self.changes):
            colour = SUCCESS_TEXT if c.trend > 0 else FAILURE_TEXT if c.trend < 0 else CAPTION_TEXT
            parts += [("   |   " if k else "", CAPTION_TEXT), (f"{c.name} {c.before} -> {c.after}", colour)]
        size = fs
        while size > 8 and sum(text_size(t, size)[0] for t, _ in parts) > width - 2 * x:
            size -= 1
        for text, colour in parts:
            if text:
                draw_text(out, (x, y), text, size, colour, anchor="lm")
                x += text_size(text, size)[0]
        return out


def moved_objects(original: House, edited: House) -> list[str]:
    """Ids of objects whose position or yaw differs between two versions of a house (or that are new)."""
    old = {o.id: o for o in original.objects}
    out = []
    for o in edited.objects:
        p = old.get(o.id)
        if p is None:
            out.append(o.id)
            continue
        shift = math.hypot(o.position.x - p.position.x, o.position.z - p.position.z)
        turn = abs((o.rotation.y - p.rotation.y + 180.0) % 360.0 - 180.0)
        if shift > SAME_PLACE or turn > SAME_PLACE:
            out.append(o.id)
    return out


def _yes_no(x: bool) -> str:
    return "yes" if x else "no"


def episode_changes(before: Trajectory, after: Trajectory) -> list[Change]:
    """Success, SPL, path length (m), collisions and steps of two episodes, with the direction of each change."""
    if before.metrics is None or after.metrics is None:
        raise AdaptenvError("both trajectories need their metrics (record them with adaptenv.sim.rollout.run_episode)")
    b, a = before.metrics, after.metrics

    def trend(x: float, y: float, higher_is_better: bool) -> int:
        if math.isclose(x, y, abs_tol=1e-9):
            return 0
        return 1 if (y > x) == higher_is_better else -1

    return [Change("success", _yes_no(b.success), _yes_no(a.success), trend(b.success, a.success, True)),
            Change("SPL", f"{b.spl:.2f}", f"{a.spl:.2f}", trend(b.spl, a.spl, True)),
            Change("path", f"{b.path_length:.1f} m", f"{a.path_length:.1f} m", trend(b.path_length, a.path_length, False)),
            Change("collisions", str(b.collisions), str(a.collisions), trend(b.collisions, a.collisions, False)),
            Change("steps", str(b.episode_length), str(a.episode_length), trend(b.episode_length, a.episode_length, False))]


def check_same_task(before: Trajectory, after: Trajectory) -> None:
    """Raise unless both episodes have the same target type and start pose (the comparison is meaningless otherwise)."""
    if before.target_type != after.target_type:
        raise AdaptenvError(f"the after episode looks for a {after.target_type}, the before episode for a "
                            f"{before.target_type}; roll pi_t out again with the same episode")
    s, t = before.start, after.start
    if math.hypot(s.x - t.x, s.z - t.z) > SAME_START or abs((s.yaw - t.yaw + 180) % 360 - 180) > SAME_START:
        raise AdaptenvError(f"the after episode starts at ({t.x:.2f}, {t.z:.2f}, {t.yaw:.0f} deg), the before episode "
                            f"at ({s.x:.2f}, {s.z:.2f}, {s.yaw:.0f} deg); roll pi_t out again from the same start")


def render_before_after(original: House, edited: House, before: Trajectory, after: Trajectory,
                        moved_ids: list[str] | None = None, *, size: int = 768, grid: bool = True,
                        labels: bool = True) -> BeforeAfter:
    """Draw pi_t in e_t (``before``) and pi_t's own rollout in e_{t+1} (``after``).

    Args:
        original: e_t, the house ``before`` ran in.
        edited: e_{t+1}, the house ``after`` ran in (same start and target as ``before``).
        before, after: the two recorded episodes, with metrics.
        moved_ids: objects to fill with :data:`MOVED_COLOUR` on the after side (an id listed twice, e.g.
            by two edits of one object, counts once in the title); default: every object whose pose
            differs between the houses (:func:`moved_objects`).
        size: longer side of each render (px).
        grid: draw the normalized 0..100 grid.
        labels: write object ids and room names.
    """
    check_same_task(before, after)
    moved = moved_objects(original, edited) if moved_ids is None else list(dict.fromkeys(moved_ids))
    changes = episode_changes(before, after)
    n = len(moved)
    left = render_map(original, trajectory=before, grid=grid, size=size, labels=labels, title="before: pi_t in e_t")
    right = render_map(edited, trajectory=after, grid=grid, size=size, labels=labels,
                       highlight={oid: MOVED_COLOUR for oid in moved} or None,
                       title=f"after: pi_t in e_t+1 ({n} moved object{'s' if n != 1 else ''})")
    return BeforeAfter(left.image, right.image, left.layout, right.layout, changes, moved)
