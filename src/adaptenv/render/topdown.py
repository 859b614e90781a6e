"""Top-down map of a house, optionally with an episode drawn on it (the image F and G look at).

The map is drawn with Pillow in one pass of named stages (see :func:`render_map`): room floors,
the optional normalized grid (the same mapping as :class:`~adaptenv.scene.grid.NormalizedGrid`:
grid x grows to the right with world +x, grid y grows upward with world +z), room names, floor
furniture as oriented rectangles with a front tick, small objects, walls with door gaps and
windows, wall decor, the trajectory (yellow at the start to orange at the end, collisions as red
x's), every floor object's id, the target crosses and pose markers, captions and the legend.
Where the room names and id labels go is decided by :mod:`adaptenv.render.labels`.

Example:
    >>> from adaptenv.render.topdown import render_house
    >>> render_house(house, grid=True, trajectory=traj).save("map.png")  # doctest: +SKIP
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from PIL import Image, ImageColor, ImageDraw

from adaptenv.errors import AdaptenvError
from adaptenv.files import atomic_path
from adaptenv.render.labels import (
    Box,
    PlacedLabel,
    label_obstacles,
    labels_fit,
    leader_start,
    place_object_labels,
    place_room_names,
    target_boxes,
)
from adaptenv.render.layout import MapLayout, MapTransform
from adaptenv.render.text import RGB, draw_text, text_size
from adaptenv.scene.geometry import Footprint, SceneGeometry, yaw_axes
from adaptenv.scene.grid import NormalizedGrid
from adaptenv.sim.spec import AGENT_RADIUS

if TYPE_CHECKING:
    from adaptenv.scene.house import House
    from adaptenv.sim.trajectory import Trajectory

# ---------------------------------------------------------------- colours
BACKGROUND: RGB = (255, 255, 255)
ROOM_FILLS: dict[str, RGB] = {
    "Kitchen": (252, 234, 208),
    "LivingRoom": (226, 240, 218),
    "Bedroom": (224, 230, 248),
    "Bathroom": (214, 240, 240),
}
ROOM_FILL_OTHER: RGB = (236, 236, 236)
GRID_LINE: RGB = (196, 196, 196)
TICK: RGB = (60, 60, 60)
WALL: RGB = (34, 34, 34)
EMPTY_WALL: RGB = (170, 170, 170)
DOOR: RGB = (120, 72, 30)
CLOSED_DOOR: RGB = (190, 30, 30)
WINDOW: RGB = (150, 205, 240)
WINDOW_LINE: RGB = (40, 120, 200)
MOVABLE_FILL: RGB = (200, 160, 118)
MOVABLE_EDGE: RGB = (92, 60, 30)
FIXED_FILL: RGB = (158, 158, 164)
FIXED_EDGE: RGB = (60, 60, 66)
FRONT_TICK: RGB = (20, 20, 20)
DECOR: RGB = (150, 90, 170)
WALL_TV: RGB = (40, 40, 60)
SMALL_OBJECT: RGB = (60, 60, 60)
LABEL_BG: RGB = (255, 255, 255)
INSIDE_LABEL_BG: RGB = (250, 240, 226)
LABEL_EDGE: RGB = (120, 120, 120)
LABEL_TEXT: RGB = (0, 0, 0)
LEADER: RGB = (90, 90, 90)
PATH_START: RGB = (255, 225, 0)
"""Yellow: the first step of a trajectory (the paper's Figure 1)."""
PATH_END: RGB = (255, 110, 0)
"""Orange: the last step."""
PATH_CASING: RGB = (90, 60, 10)
START_FILL: RGB = (40, 170, 60)
END_FILL: RGB = (150, 50, 170)
COLLISION: RGB = (220, 20, 20)
TARGET: RGB = (255, 120, 0)
SUCCESS_TEXT: RGB = (20, 130, 40)
FAILURE_TEXT: RGB = (200, 30, 30)
CAPTION_TEXT: RGB = (20, 20, 20)

_MOVE_ACTIONS = frozenset({"m", "b", "move_ahead", "move_back"})
_GRID_STEP = 10
_MIN_SIZE = 256
MIN_WIDTH_FRACTION = 0.5
"""A render is at least this fraction of ``size`` wide (a tall, narrow house is centred in the wider panel),
and wider still when its caption or legend needs it, up to ``size``."""


# ---------------------------------------------------------------- layout
_GRID_NOTE = "grid: x grows right, y grows up"
HIGHLIGHT_LEGEND = "moved object"
"""The legend's name for the highlight colour (every caller highlights the objects an edit moved)."""


def _legend_items(trajectory: bool, grid: bool, highlight: bool = False) -> list[str]:
    items = [_GRID_NOTE] if grid else []
    items += ["movable", "fixed", "small object", "wall decor", "door", "closed door", "window"]
    if highlight:
        items.append(HIGHLIGHT_LEGEND)
    if trajectory:
        items += ["path start->end", "start", "end", "collision", "target"]
    return items


def _legend_item_width(item: str, fs: int) -> float:
    return fs * 1.6 + text_size(item, fs)[0] + fs * 1.2


def _wrap_legend(items: list[str], fs: int, width: float) -> list[list[str]]:
    rows: list[list[str]] = [[]]
    used = 0.0
    for item in items:
        w = _legend_item_width(item, fs)
        if rows[-1] and used + w > width:
            rows.append([])
            used = 0.0
        rows[-1].append(item)
        used += w
    return rows


def base_font_size(size: int) -> int:
    """Font size (px) of tick labels, captions and room names in a render of ``size`` px."""
    return max(10, round(size / 80))


def map_layout(geometry: SceneGeometry, *, size: int = 1024, grid: bool = False, captions: int = 0,
               legend: bool = True, trajectory: bool = False, highlight: bool = False,
               header_width: float = 0.0) -> MapLayout:
    """Fit the house into an image whose longer side is ``size`` px, keeping its aspect ratio.

    Margins hold the tick labels (left, bottom) when ``grid``, ``captions`` text lines on top
    and the legend at the bottom. The image is at least :data:`MIN_WIDTH_FRACTION` of ``size`` wide and
    wide enough (up to ``size``) for the caption lines (``header_width`` px at the base font size) and for
    every legend item; the map is centred when the panel is wider than the house.
    """
    if size < _MIN_SIZE:
        raise AdaptenvError(f"render size {size} px is too small to read; use --size {_MIN_SIZE} or more")
    g = geometry.grid or NormalizedGrid.from_bounds(*geometry.bounds)
    min_x, min_z, max_x, max_z = geometry.bounds
    wx, wz = max_x - g.min_x, max_z - g.min_z
    fs = base_font_size(size)
    label_fs = max(9, round(size / 88))
    small = max(9, fs - 2)
    _, line_h = text_size("Hg", fs)
    pad = round(fs * 0.8)
    left = (text_size("100", fs)[0] + fs * 0.6 + pad * 1.5) if grid else pad * 1.5
    right = pad * 2.0
    top = pad + captions * (line_h + 4) + (pad * 0.5 if captions else 0)
    ticks = (fs * 0.6 + line_h + pad * 0.5) if grid else pad
    _, small_h = text_size("Hg", small)
    items = _legend_items(trajectory, grid, highlight) if legend else []
    needed = max([MIN_WIDTH_FRACTION * size, header_width + 2 * left]
                 + [_legend_item_width(item, small) + 2 * pad for item in items])
    rows: list[list[str]] = []
    for _ in range(4):  # the legend may wrap once the width is known; settle in a few rounds
        bottom = ticks + (len(rows) * (small_h + 6) + pad * 0.5 if rows else pad * 0.5)
        scale = min((size - left - right) / wx, (size - top - bottom) / wz)
        width = max(left + right + wx * scale, min(needed, size))
        new_rows = _wrap_legend(items, small, width - 2 * pad) if items else []
        settled = len(new_rows) == len(rows)
        rows = new_rows  # always the rows of this width: the previous width's may overflow it
        if settled:
            break
    height = top + bottom + wz * scale
    shift = (width - (left + right + wx * scale)) / 2  # centre the map in a panel widened for its text
    transform = MapTransform(g, scale, (float(left + shift), float(top + wz * scale)), (wx, wz))
    caption_top = pad * 0.6
    return MapLayout(int(math.ceil(width)), int(math.ceil(height)), transform, fs, label_fs, caption_top,
                     caption_top + captions * (line_h + 4), top + wz * scale + ticks + pad * 0.3, rows, float(left))


# ---------------------------------------------------------------- small geometry helpers
def _pts(transform: MapTransform, xy) -> list[tuple[float, float]]:
    """World points (N, 2) -> list of pixel tuples for ImageDraw."""
    a = np.asarray(xy, dtype=float).reshape(-1, 2)
    px, py = transform.to_px(a[:, 0], a[:, 1])
    return list(zip(px.tolist(), py.tolist(), strict=True))


def _colour(value: str, what: str) -> RGB:
    try:
        return ImageColor.getrgb(value)[:3]
    except ValueError:
        raise AdaptenvError(f"highlight colour {value!r} for {what} is not a colour Pillow knows; "
                            "use a name like 'red' or a hex code like '#ff0000'") from None


@dataclass(frozen=True)
class MapRender:
    """A render plus how it was laid out: the pixel transform and where every id label went."""

    image: Image.Image
    layout: MapLayout
    labels: list[PlacedLabel]

    @property
    def transform(self) -> MapTransform:
        return self.layout.transform


# ---------------------------------------------------------------- drawing
def _wall_pieces(geometry: SceneGeometry) -> tuple[list[tuple[np.ndarray, np.ndarray, bool, bool]], list]:
    """Solid wall pieces (p0, p1, cap0, cap1) with every door cut out, and the empty walls."""
    pieces, empty = [], []
    for w in geometry.walls:
        p0, p1 = np.array(w.p0), np.array(w.p1)
        if w.empty:
            empty.append((p0, p1))
            continue
        length = float(np.linalg.norm(p1 - p0))
        if length < 1e-9:
            continue
        u = (p1 - p0) / length
        holes = []
        for d in geometry.doors:
            a, b = np.array(d.p0) - p0, np.array(d.p1) - p0
            if abs(u[0] * a[1] - u[1] * a[0]) < 1e-3 and abs(u[0] * b[1] - u[1] * b[0]) < 1e-3:
                ta, tb = sorted((float(a @ u), float(b @ u)))
                if tb > 1e-6 and ta < length - 1e-6:
                    holes.append((max(ta, 0.0), min(tb, length)))
        start = 0.0
        for a, b in sorted(holes) + [(length, length)]:
            if a - start > 1e-6:
                pieces.append((p0 + start * u, p0 + a * u, start < 1e-6, a > length - 1e-6))
            start = max(start, b)
    return pieces, empty


def _dashed(draw: ImageDraw.ImageDraw, a: tuple[float, float], b: tuple[float, float], fill: RGB,
            width: int, dash: float, gap: float) -> None:
    length = math.dist(a, b)
    if length < 1e-6:
        return
    ux, uy = (b[0] - a[0]) / length, (b[1] - a[1]) / length
    s = 0.0
    while s < length:
        e = min(s + dash, length)
        draw.line([(a[0] + ux * s, a[1] + uy * s), (a[0] + ux * e, a[1] + uy * e)], fill=fill, width=width)
        s = e + gap


def _draw_grid(image: Image.Image, draw: ImageDraw.ImageDraw, layout: MapLayout) -> None:
    """Light grid lines every 10 units across the house; ticks and labels on the bottom and left axes."""
    t = layout.transform
    left, top, right, bottom = t.area
    gx_max, gy_max = t.grid.meters_to_units(t.size_m[0]), t.grid.meters_to_units(t.size_m[1])
    fs = layout.font_size
    tick = fs * 0.5
    for g in range(0, 101, _GRID_STEP // 2):
        major = g % _GRID_STEP == 0
        if g <= gx_max + 0.05:
            x = float(t.grid_to_px(g, 0)[0])
            if major:
                draw.line([(x, top), (x, bottom)], fill=GRID_LINE, width=1)
            draw.line([(x, bottom + 2), (x, bottom + 2 + (tick if major else tick * 0.5))], fill=TICK, width=1)
            if major:
                draw_text(image, (x, bottom + 3 + tick), str(g), fs, TICK, anchor="mt")
        if g <= gy_max + 0.05:
            y = float(t.grid_to_px(0, g)[1])
            if major:
                draw.line([(left, y), (right, y)], fill=GRID_LINE, width=1)
            draw.line([(left - 2, y), (left - 2 - (tick if major else tick * 0.5), y)], fill=TICK, width=1)
            if major:
                draw_text(image, (left - 4 - tick, y), str(g), fs, TICK, anchor="rm")


def _draw_walls(draw: ImageDraw.ImageDraw, t: MapTransform, pieces: list, empty: list, wall_w: int) -> None:
    """Walls (pieces from :func:`_wall_pieces`, door gaps cut out) with square corners; empty walls dashed."""
    for p0, p1 in empty:
        a, b = _pts(t, [p0, p1])
        _dashed(draw, a, b, EMPTY_WALL, 1, 5, 4)
    half = wall_w / 2
    for p0, p1, cap0, cap1 in pieces:
        a, b = _pts(t, [p0, p1])
        draw.line([a, b], fill=WALL, width=wall_w)
        for cap, p in ((cap0, a), (cap1, b)):
            if cap:
                draw.rectangle([p[0] - half, p[1] - half, p[0] + half - 1, p[1] + half - 1], fill=WALL)


def door_leaves(asset_id: str) -> int:
    """Leaves a door asset has: 0 for a doorframe (an open frame), 2 for a double door, else 1."""
    if asset_id.startswith("Doorframe"):
        return 0
    return 2 if "Double" in asset_id else 1


def _draw_doors(draw: ImageDraw.ImageDraw, geometry: SceneGeometry, t: MapTransform, wall_w: int,
                highlight: dict[str, RGB] | None = None) -> None:
    """Open doors as a gap with their leaves and swing arcs (none for a doorframe, one from each jamb for a
    double door); closed doors as a red bar; a highlighted door on a wide band of its colour."""
    for d in geometry.doors:
        p0, p1 = np.array(d.p0), np.array(d.p1)
        width = float(np.linalg.norm(p1 - p0))
        if width < 1e-6:
            continue
        u = (p1 - p0) / width
        n = np.array([-u[1], u[0]])
        if highlight and d.id in highlight:
            draw.line(_pts(t, [p0, p1]), fill=highlight[d.id], width=wall_w + 8)
        if not d.passable:
            a, b = _pts(t, [p0, p1])
            draw.line([a, b], fill=CLOSED_DOOR, width=wall_w + 2)
            continue
        room = geometry.rooms.get(d.rooms[0])
        if room is not None and float(np.dot(np.array(room.centroid.coords[0]) - p0, n)) < 0:
            n = -n
        leaves = door_leaves(d.asset_id)
        hinges = [(p0, u), (p1, -u)][:leaves]
        leaf_len = width * 0.9 / max(leaves, 1)
        for hinge, along in hinges:
            arc = [hinge + leaf_len * (math.cos(a) * along + math.sin(a) * n) for a in np.linspace(0, math.pi / 2, 10)]
            draw.line(_pts(t, arc), fill=DOOR, width=1)
            draw.line(_pts(t, [hinge, hinge + n * leaf_len]), fill=DOOR, width=max(2, wall_w // 2))
        for p in (p0, p1):  # jambs
            a, b = _pts(t, [p - n * 0.08, p + n * 0.08])
            draw.line([a, b], fill=DOOR, width=2)


def _draw_windows(draw: ImageDraw.ImageDraw, geometry: SceneGeometry, t: MapTransform, wall_w: int) -> None:
    for w in geometry.windows:
        a, b = _pts(t, [w.p0, w.p1])
        draw.line([a, b], fill=WINDOW, width=max(2, wall_w - 2))
        draw.line([a, b], fill=WINDOW_LINE, width=1)


def _draw_furniture(draw: ImageDraw.ImageDraw, floor: list[Footprint], t: MapTransform,
                    highlight: dict[str, RGB], tick_len: float) -> None:
    """Oriented rectangles (movable tan, fixtures grey) with a tick on the front edge (local +z)."""
    for fp in floor:
        corners = _pts(t, fp.corners)
        fill, edge = (MOVABLE_FILL, MOVABLE_EDGE) if fp.movable else (FIXED_FILL, FIXED_EDGE)
        width = 1
        if fp.object_id in highlight:
            fill, edge, width = highlight[fp.object_id], (0, 0, 0), 3
        draw.polygon(_pts(t, fp.outline), fill=fill, outline=edge, width=width)  # true shape (L/C counters)
        # Front edge: corners 2 (front-right) and 3 (front-left).
        fr, fl = corners[2], corners[3]
        mid = ((fr[0] + fl[0]) / 2, (fr[1] + fl[1]) / 2)
        draw.line([fr, fl], fill=FRONT_TICK, width=2)
        _, uz = yaw_axes(fp.yaw)
        depth = fp.size[1] * t.scale
        ln = min(tick_len, depth * 0.4)
        draw.line([mid, (mid[0] - uz[0] * ln, mid[1] + uz[1] * ln)], fill=FRONT_TICK, width=2)


def _draw_decor(draw: ImageDraw.ImageDraw, decor: list[Footprint], t: MapTransform,
                highlight: dict[str, RGB], wall_w: int) -> None:
    """Wall-mounted objects as short thick marks along their wall."""
    for fp in decor:
        ux, _ = yaw_axes(fp.yaw)
        c = np.array(fp.center)
        a, b = _pts(t, [c - ux * fp.size[0] / 2, c + ux * fp.size[0] / 2])
        colour = highlight.get(fp.object_id, WALL_TV if fp.object_type == "Television" else DECOR)
        draw.line([a, b], fill=colour, width=max(3, wall_w // 2 + 1) + (2 if fp.object_id in highlight else 0))


def _draw_small(draw: ImageDraw.ImageDraw, geometry: SceneGeometry, t: MapTransform,
                highlight: dict[str, RGB], radius: float) -> None:
    for kids in geometry.children.values():
        for fp in kids:
            x, y = t.point(*fp.center)
            r, colour = radius, SMALL_OBJECT
            if fp.object_id in highlight:
                r, colour = radius * 2.5, highlight[fp.object_id]
            draw.ellipse([x - r, y - r, x + r, y + r], fill=colour)


def _draw_trajectory(draw: ImageDraw.ImageDraw, traj: Trajectory, t: MapTransform, width: int) -> None:
    """The path as segments coloured yellow -> orange over a dark casing, and collisions as red x's."""
    poses = traj.poses
    xs = np.array([p.x for p in poses])
    zs = np.array([p.z for p in poses])
    px, py = t.to_px(xs, zs)
    pts = list(zip(px.tolist(), py.tolist(), strict=True))
    n = len(pts)
    if n >= 2:
        draw.line(pts, fill=PATH_CASING, width=width + 2, joint="curve")
        frac = np.arange(n - 1) / max(n - 2, 1)
        start, end = np.array(PATH_START, dtype=float), np.array(PATH_END, dtype=float)
        cols = np.rint(start[None] + (end - start)[None] * frac[:, None]).astype(int).tolist()
        for i in range(n - 1):
            if pts[i] != pts[i + 1]:
                draw.line([pts[i], pts[i + 1]], fill=tuple(cols[i]), width=width)
    r = max(3.0, width * 1.3)
    for s in traj.steps:
        if not s.moved and s.action in _MOVE_ACTIONS:
            x, y = t.point(s.pose.x, s.pose.z)
            draw.line([(x - r, y - r), (x + r, y + r)], fill=COLLISION, width=2)
            draw.line([(x - r, y + r), (x + r, y - r)], fill=COLLISION, width=2)


def _pose_marker(draw: ImageDraw.ImageDraw, t: MapTransform, x: float, z: float, yaw: float,
                 fill: RGB, r: float) -> None:
    """A filled disc with a heading tick (yaw 0 faces +z: up in the image)."""
    cx, cy = t.point(x, z)
    h = math.radians(yaw)
    tip = (cx + math.sin(h) * r * 2.0, cy - math.cos(h) * r * 2.0)
    draw.line([(cx, cy), tip], fill=(0, 0, 0), width=3)
    draw.ellipse([cx - r, cy - r, cx + r, cy + r], fill=fill, outline=(0, 0, 0), width=2)


def _target_cross(draw: ImageDraw.ImageDraw, cx: float, cy: float, arm: float, width: int) -> None:
    for (dx0, dy0), (dx1, dy1) in (((-arm, -arm), (arm, arm)), ((-arm, arm), (arm, -arm))):
        draw.line([(cx + dx0, cy + dy0), (cx + dx1, cy + dy1)], fill=(60, 30, 0), width=width + 3)
    for (dx0, dy0), (dx1, dy1) in (((-arm, -arm), (arm, arm)), ((-arm, arm), (arm, -arm))):
        draw.line([(cx + dx0, cy + dy0), (cx + dx1, cy + dy1)], fill=TARGET, width=width)


def _caption_parts(traj: Trajectory) -> list[tuple[str, RGB]]:
    """'target: Fridge | FAILURE | 600 steps | 12 collisions' as (text, colour) runs."""
    n = len(traj.steps)
    collisions = sum(1 for s in traj.steps if not s.moved and s.action in _MOVE_ACTIONS)
    parts: list[tuple[str, RGB]] = [(f"target: {traj.target_type}", CAPTION_TEXT)]
    m = traj.metrics
    bar = "  |  "
    if m is not None:
        parts += [(bar, CAPTION_TEXT),
                  ("SUCCESS" if m.success else "FAILURE", SUCCESS_TEXT if m.success else FAILURE_TEXT)]
        collisions = m.collisions
        tail = f"{bar}{n} steps{bar}path {m.path_length:.1f} m{bar}{collisions} collisions{bar}SPL {m.spl:.2f}"
    else:
        tail = f"{bar}{n} steps{bar}{collisions} collisions"
    if traj.policy and traj.policy != "policy":  # "policy" is a placeholder name, not worth a caption
        tail += f"{bar}policy: {traj.policy}"
    parts.append((tail, CAPTION_TEXT))
    return parts


def header_width(title: str | None, trajectory: Trajectory | None, fs: int) -> float:
    """Pixel width of the caption lines at base font size ``fs`` (the title is one size larger and bold)."""
    widths = [0.0]
    if title is not None:
        widths.append(text_size(title, fs + 1, True)[0])
    if trajectory is not None:
        widths.append(sum(text_size(text, fs)[0] for text, _ in _caption_parts(trajectory)))
    return max(widths)


def _draw_runs(image: Image.Image, x: float, y: float, parts: list[tuple[str, RGB]], fs: int,
               bold: bool, max_w: float) -> None:
    """Draw coloured text runs on one line, shrinking the font until the line fits ``max_w``."""
    size = fs
    while size > 8 and sum(text_size(s, size, bold)[0] for s, _ in parts) > max_w:
        size -= 1
    for s, colour in parts:
        draw_text(image, (x, y), s, size, colour, anchor="lt", bold=bold)
        x += text_size(s, size, bold)[0]


def _draw_legend(image: Image.Image, draw: ImageDraw.ImageDraw, layout: MapLayout, wall_w: int,
                 highlight: RGB | None = None) -> None:
    fs = max(9, layout.font_size - 2)
    _, h = text_size("Hg", fs)
    y = layout.legend_top + h / 2
    x0 = layout.transform.area[0]
    x0 = min(x0, layout.font_size * 0.8)
    for row in layout.legend_rows:
        x = x0
        for item in row:
            sx, sy, s = x + fs * 0.7, y, fs * 0.55
            if item in ("movable", "fixed"):
                fill, edge = (MOVABLE_FILL, MOVABLE_EDGE) if item == "movable" else (FIXED_FILL, FIXED_EDGE)
                draw.rectangle([sx - s, sy - s, sx + s, sy + s], fill=fill, outline=edge)
                draw.line([(sx - s, sy - s), (sx + s, sy - s)], fill=FRONT_TICK, width=2)
            elif item == HIGHLIGHT_LEGEND:
                draw.rectangle([sx - s, sy - s, sx + s, sy + s], fill=highlight, outline=(0, 0, 0), width=2)
            elif item == "small object":
                draw.ellipse([sx - 2.5, sy - 2.5, sx + 2.5, sy + 2.5], fill=SMALL_OBJECT)
            elif item == "wall decor":
                draw.line([(sx - s, sy), (sx + s, sy)], fill=DECOR, width=4)
            elif item == "door":
                draw.line([(sx - s, sy + s), (sx - s, sy - s)], fill=DOOR, width=2)
                draw.arc([sx - 3 * s, sy - s, sx + s, sy + 3 * s], 270, 360, fill=DOOR)
            elif item == "closed door":
                draw.line([(sx - s, sy), (sx + s, sy)], fill=CLOSED_DOOR, width=wall_w + 2)
            elif item == "window":
                draw.line([(sx - s, sy), (sx + s, sy)], fill=WINDOW, width=max(2, wall_w - 2))
                draw.line([(sx - s, sy), (sx + s, sy)], fill=WINDOW_LINE, width=1)
            elif item == "path start->end":
                k = 6
                for i in range(k):
                    f = i / (k - 1)
                    col = tuple(int(round(a + (b - a) * f)) for a, b in zip(PATH_START, PATH_END, strict=True))
                    xa = sx - s * 1.2 + 2.4 * s * i / k
                    draw.line([(xa, sy), (xa + 2.4 * s / k + 1, sy)], fill=col, width=4)
            elif item in ("start", "end"):
                r = s * 0.8
                draw.ellipse([sx - r, sy - r, sx + r, sy + r], fill=START_FILL if item == "start" else END_FILL,
                             outline=(0, 0, 0), width=1)
            elif item == "collision":
                draw.line([(sx - s * 0.7, sy - s * 0.7), (sx + s * 0.7, sy + s * 0.7)], fill=COLLISION, width=2)
                draw.line([(sx - s * 0.7, sy + s * 0.7), (sx + s * 0.7, sy - s * 0.7)], fill=COLLISION, width=2)
            elif item == "target":
                _target_cross(draw, sx, sy, s * 0.8, 3)
            text_x = x if item == _GRID_NOTE else x + fs * 1.6
            draw_text(image, (text_x, y), item, fs, TICK, anchor="lm", bold=item == _GRID_NOTE)
            x += _legend_item_width(item, fs)
        y += h + 6


@dataclass(frozen=True)
class _Canvas:
    """The image being drawn, its drawing context and its layout."""

    image: Image.Image
    draw: ImageDraw.ImageDraw
    layout: MapLayout

    @classmethod
    def blank(cls, layout: MapLayout) -> _Canvas:
        image = Image.new("RGB", (layout.width, layout.height), BACKGROUND)
        return cls(image, ImageDraw.Draw(image), layout)

    @property
    def t(self) -> MapTransform:
        return self.layout.transform


@dataclass(frozen=True)
class _PixelScene:
    """The house in pixels, measured once: what the drawing stages and label placement share."""

    floor: list[Footprint]
    boxes: dict[str, Box]
    """Each floor object's pixel bounding box."""
    anchors: list[tuple[float, float]]
    """Each floor object's pixel centre (where an outside label's leader ends)."""
    pieces: list
    empty: list
    """Solid wall pieces with the doors cut out, and the empty walls (see :func:`_wall_pieces`)."""
    wall_segs: np.ndarray
    wall_w: int
    agent_r: float
    cross_arm: float
    tick_len: float

    @classmethod
    def of(cls, geometry: SceneGeometry, t: MapTransform) -> _PixelScene:
        floor = geometry.floor_objects
        boxes: dict[str, Box] = {}
        for fp in floor:
            px, py = t.to_px(fp.corners[:, 0], fp.corners[:, 1])
            boxes[fp.object_id] = (float(px.min()), float(py.min()), float(px.max()), float(py.max()))
        pieces, empty = _wall_pieces(geometry)
        wall_segs = np.array([_pts(t, [p0, p1]) for p0, p1, _, _ in pieces], dtype=float).reshape(-1, 2, 2)
        return cls(floor, boxes, [t.point(*fp.center) for fp in floor], pieces, empty, wall_segs,
                   wall_w=max(3, round(0.1 * t.scale)), agent_r=max(5.0, AGENT_RADIUS * t.scale),
                   cross_arm=max(7.0, 0.28 * t.scale), tick_len=min(max(4.0, 0.15 * t.scale), 8.0))


def render_map(house: House | None = None, *, trajectory: Trajectory | None = None, grid: bool = False,
               size: int = 1024, highlight: dict[str, str] | None = None, labels: bool = True,
               title: str | None = None, geometry: SceneGeometry | None = None,
               legend: bool = True) -> MapRender:
    """Render the top-down map and also return the layout (pixel transform) it was drawn with.

    The stages, back to front: floors and grid, room names, the house (furniture, walls, openings,
    decor), the path, object id labels, the episode's markers, captions, legend.
    """
    geometry = _geometry_of(house, geometry)
    colours = _highlight_colours(geometry, highlight)
    layout = map_layout(geometry, size=size, grid=grid, captions=int(title is not None) + int(trajectory is not None),
                        legend=legend, trajectory=trajectory is not None, highlight=bool(colours),
                        header_width=header_width(title, trajectory, base_font_size(size)))
    canvas = _Canvas.blank(layout)
    scene = _PixelScene.of(geometry, layout.transform)
    obstacles = label_obstacles(layout, scene.boxes, scene.anchors, scene.wall_segs, scene.wall_w, trajectory,
                                scene.agent_r, scene.cross_arm, grid)

    _draw_floors(canvas, geometry, grid)
    if labels:
        _draw_room_names(canvas, geometry, place_room_names(geometry, canvas.t, layout.font_size, obstacles))
    _draw_house(canvas, geometry, scene, colours)
    if trajectory is not None:
        _draw_trajectory(canvas.draw, trajectory, canvas.t, max(2, round(canvas.t.scale * 0.05)))
    placed = place_object_labels(scene.floor, canvas.t, layout, obstacles, scene.boxes, colours, LABEL_EDGE,
                                 scene.tick_len + 1, target_boxes(canvas.t, trajectory, scene.cross_arm)) \
        if labels and labels_fit(len(scene.floor)) else []
    _draw_labels(canvas, placed)
    if trajectory is not None:
        _draw_markers(canvas, trajectory, scene)
    _draw_captions(canvas, title, trajectory)
    if legend:
        _draw_legend(canvas.image, canvas.draw, layout, scene.wall_w, next(iter(colours.values()), None))
    return MapRender(canvas.image, layout, placed)


def _geometry_of(house: House | None, geometry: SceneGeometry | None) -> SceneGeometry:
    if geometry is not None:
        return geometry
    if house is None:
        raise AdaptenvError("render_map needs a house or its SceneGeometry")
    return SceneGeometry.from_house(house)


def _highlight_colours(geometry: SceneGeometry, highlight: dict[str, str] | None) -> dict[str, RGB]:
    """Object (or door) id -> colour, checked: every id must be in the house and every colour known to Pillow."""
    known = {f.object_id for f in geometry.footprints} | {c.object_id for k in geometry.children.values() for c in k}
    known |= {d.id for d in geometry.doors}
    colours: dict[str, RGB] = {}
    for oid, value in (highlight or {}).items():
        if oid not in known:
            raise AdaptenvError(f"cannot highlight {oid!r}: the house has no object or door with that id; "
                                "use an id from the house's objects or doors")
        colours[oid] = _colour(value, oid)
    return colours


def _draw_floors(canvas: _Canvas, geometry: SceneGeometry, grid: bool) -> None:
    """Room floors, then the grid lines on top of them but under everything else."""
    for rid, poly in geometry.rooms.items():
        fill = ROOM_FILLS.get(geometry.room_types.get(rid, ""), ROOM_FILL_OTHER)
        canvas.draw.polygon(_pts(canvas.t, poly.exterior.coords), fill=fill)
    if grid:
        _draw_grid(canvas.image, canvas.draw, canvas.layout)


def _draw_room_names(canvas: _Canvas, geometry: SceneGeometry, names: list[tuple[str, str, Box]]) -> None:
    """Each room's type in a darker shade of its floor colour, where label placement put it."""
    for rid, name, box in names:
        fill = ROOM_FILLS.get(geometry.room_types.get(rid, ""), ROOM_FILL_OTHER)
        dark = tuple(int(c * 0.55) for c in fill)
        draw_text(canvas.image, ((box[0] + box[2]) / 2, (box[1] + box[3]) / 2), name, canvas.layout.font_size,
                  dark, anchor="mm")


def _draw_house(canvas: _Canvas, geometry: SceneGeometry, scene: _PixelScene, colours: dict[str, RGB]) -> None:
    """Furniture, small objects, walls, windows, doors and wall decor, in that order."""
    draw, t = canvas.draw, canvas.t
    _draw_furniture(draw, scene.floor, t, colours, scene.tick_len)
    _draw_small(draw, geometry, t, colours, max(1.5, 0.035 * t.scale))
    _draw_walls(draw, t, scene.pieces, scene.empty, scene.wall_w)
    _draw_windows(draw, geometry, t, scene.wall_w)
    _draw_doors(draw, geometry, t, scene.wall_w, colours)
    _draw_decor(draw, [f for f in geometry.footprints if f.role == "wall"], t, colours, scene.wall_w)


def _draw_labels(canvas: _Canvas, placed: list[PlacedLabel]) -> None:
    """Leaders first, then every label box and its text (inside labels on a tinted background)."""
    draw = canvas.draw
    for lab in placed:
        if not lab.inside:
            _draw_leader(draw, lab)
    for lab in placed:
        x0, y0, x1, y1 = lab.box
        if lab.inside:
            draw.rectangle([x0 + 1, y0 + 2, x1 - 1, y1 - 1], fill=INSIDE_LABEL_BG)
        else:
            edge_w = 2 if lab.edge != LABEL_EDGE else 1
            draw.rectangle([x0, y0, x1, y1], fill=LABEL_BG, outline=lab.edge, width=edge_w)
        draw_text(canvas.image, ((x0 + x1) / 2, (y0 + y1) / 2), lab.text, lab.size, LABEL_TEXT, anchor="mm")


def _draw_markers(canvas: _Canvas, trajectory: Trajectory, scene: _PixelScene) -> None:
    """The target crosses, then the start and (when the episode moved or ended) the end pose."""
    draw, t = canvas.draw, canvas.t
    for x, z in trajectory.target_positions:
        _target_cross(draw, *t.point(x, z), scene.cross_arm, max(3, round(0.06 * t.scale)))
    s = trajectory.start
    _pose_marker(draw, t, s.x, s.z, s.yaw, START_FILL, scene.agent_r)
    if trajectory.steps or trajectory.final_pose is not None:
        e = trajectory.poses[-1]
        _pose_marker(draw, t, e.x, e.z, e.yaw, END_FILL, scene.agent_r)


def _draw_captions(canvas: _Canvas, title: str | None, trajectory: Trajectory | None) -> None:
    """The bold title line and the episode's one-line summary above the map."""
    layout = canvas.layout
    y, x = layout.caption_top, layout.text_left
    max_w = layout.width - 2 * x
    if title is not None:
        _draw_runs(canvas.image, x, y, [(title, CAPTION_TEXT)], layout.font_size + 1, True, max_w)
        y += text_size("Hg", layout.font_size)[1] + 4
    if trajectory is not None:
        _draw_runs(canvas.image, x, y, _caption_parts(trajectory), layout.font_size, False, max_w)


def _draw_leader(draw: ImageDraw.ImageDraw, lab: PlacedLabel) -> None:
    """A thin line from the label box's nearest edge point to the object's centre, ending in a dot."""
    ax, ay = lab.anchor
    draw.line([leader_start(lab.box, lab.anchor), (ax, ay)], fill=LEADER, width=1)
    draw.ellipse([ax - 2, ay - 2, ax + 2, ay + 2], fill=LEADER)


def env_frame(house: House | None, geometry: SceneGeometry, trajectory: Trajectory) -> np.ndarray:
    """The Gymnasium env's ``render()`` frame: the house and the episode so far, 512 px, no labels or legend."""
    image = render_house(house, geometry=geometry, trajectory=trajectory, size=512, labels=False, legend=False)
    return np.asarray(image.convert("RGB"), dtype=np.uint8)


def render_house(house: House | None = None, *, trajectory: Trajectory | None = None, grid: bool = False,
                 size: int = 1024, highlight: dict[str, str] | None = None, labels: bool = True,
                 title: str | None = None, geometry: SceneGeometry | None = None,
                 legend: bool = True) -> Image.Image:
    """Top-down map of a house as an RGB image whose longer side is ``size`` px.

    Args:
        house: the house (may be None when ``geometry`` is given).
        trajectory: an episode to draw: path (yellow -> orange), start/end poses, collisions,
            target crosses, and a one-line caption.
        grid: draw the paper's normalized 0..100 grid (ticks every 10 on the bottom and left axes).
        size: the image's longer side in pixels (at least 256).
        highlight: object id -> colour (a Pillow colour name or '#rrggbb') to fill that object with;
            the legend names the (first) colour "moved object".
        labels: write every floor object's id (up to ``labels.LABEL_LIMIT`` objects) and each room's type.
        title: a bold line above the map.
        geometry: precomputed ``SceneGeometry.from_house(house)`` (saves ~2 ms per render).
        legend: a key of the symbols under the map.
    """
    return render_map(house, trajectory=trajectory, grid=grid, size=size, highlight=highlight, labels=labels,
                      title=title, geometry=geometry, legend=legend).image


def png_bytes(image: Image.Image) -> bytes:
    """PNG encoding of a render (what the LLM backends send)."""
    buf = io.BytesIO()
    image.save(buf, format="PNG")
    return buf.getvalue()


def save_render(image: Image.Image, path: str | Path) -> Path:
    """Write a render as PNG (or whatever the suffix names), creating parent folders."""
    p = Path(path)
    try:
        with atomic_path(p) as tmp:
            image.save(tmp)
    except (ValueError, OSError) as exc:
        raise AdaptenvError(f"{p}: cannot write the image ({exc}); use a writable path ending in .png") from None
    return p


def render_to_file(house: House, path: str | Path, **kw) -> Path:
    """Render a house (same keywords as :func:`render_house`) straight to an image file."""
    return save_render(render_house(house, **kw), path)
