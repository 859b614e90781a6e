"""Top-down map of a house, optionally with an episode drawn on it (the image F and G look at).

The map is drawn with Pillow in one pass: room floors, the optional normalized grid (the same
mapping as :class:`~adaptenv.scene.grid.NormalizedGrid`: grid x grows to the right with world +x,
grid y grows upward with world +z), walls with door gaps and windows, floor furniture as oriented
rectangles with a front tick and their id, wall decor, small objects, and the trajectory (yellow
at the start to orange at the end, collisions as red x's, targets as orange crosses).

Example:
    >>> from adaptenv.render.topdown import render_house
    >>> render_house(house, grid=True, trajectory=traj).save("map.png")  # doctest: +SKIP
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import shapely
from PIL import Image, ImageColor, ImageDraw, ImageFont

from adaptenv.errors import AdaptenvError
from adaptenv.scene.geometry import Footprint, SceneGeometry, yaw_axes
from adaptenv.scene.grid import NormalizedGrid
from adaptenv.sim.spec import AGENT_RADIUS

if TYPE_CHECKING:
    from adaptenv.scene.house import House
    from adaptenv.sim.trajectory import Trajectory

RGB = tuple[int, int, int]

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
#: Label placement: cost per unit of a label's area covered by each kind of obstacle ...
_W_LABEL, _W_ROOM_NAME, _W_FURNITURE, _W_WALL, _W_MARKER, _W_ANCHOR = 300.0, 20.0, 6.0, 5.0, 40.0, 200.0
#: ... plus a flat cost for touching it at all (thin walls cover little area but must stay visible).
_FLAT_COST = {_W_LABEL: 50.0, _W_ROOM_NAME: 1.0, _W_FURNITURE: 1.0, _W_WALL: 3.0, _W_MARKER: 5.0,
              _W_ANCHOR: 15.0}


# ---------------------------------------------------------------- fonts
@lru_cache(maxsize=64)
def get_font(size: int, bold: bool = False) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    """A TrueType font of this pixel size: DejaVu Sans Condensed when installed, else Pillow's own."""
    name = "DejaVuSansCondensed-Bold.ttf" if bold else "DejaVuSansCondensed.ttf"
    try:
        return ImageFont.truetype(name, size)
    except OSError:
        return ImageFont.load_default(size=size)


@lru_cache(maxsize=8192)
def text_size(text: str, size: int, bold: bool = False) -> tuple[float, float]:
    """Width and line height (px) of ``text`` drawn with :func:`get_font`."""
    font = get_font(size, bold)
    ascent, descent = font.getmetrics() if hasattr(font, "getmetrics") else (size, 0)
    return float(font.getlength(text)), float(ascent + descent)


@lru_cache(maxsize=4096)
def _text_mask(text: str, size: int, bold: bool, anchor: str) -> tuple[Image.Image, int, int]:
    """The anti-aliased coverage of a text as an "L" image plus its offset from the anchor point.

    Cached: a house is re-rendered after every edit with the same ids, so each label is
    rasterized once.
    """
    font = get_font(size, bold)
    left, top, right, bottom = font.getbbox(text, anchor=anchor)
    mask = Image.new("L", (max(1, right - left), max(1, bottom - top)), 0)
    ImageDraw.Draw(mask).text((-left, -top), text, font=font, fill=255, anchor=anchor)
    return mask, left, top


def draw_text(image: Image.Image, xy: tuple[float, float], text: str, size: int, fill: RGB,
              anchor: str = "la", bold: bool = False) -> None:
    """Like ``ImageDraw.text`` with :func:`get_font`, through a cache of rasterized texts."""
    mask, left, top = _text_mask(text, size, bold, anchor)
    image.paste(fill, (int(round(xy[0])) + left, int(round(xy[1])) + top), mask)


# ---------------------------------------------------------------- layout
@dataclass(frozen=True)
class MapTransform:
    """World (x, z) meters -> image pixels with one uniform scale; +x is right, +z is up.

    World (grid.min_x, grid.min_z), the grid's (0, 0), lands on ``origin``: the bottom-left
    corner of the drawing area.
    """

    grid: NormalizedGrid
    scale: float
    """Pixels per meter."""
    origin: tuple[float, float]
    size_m: tuple[float, float]
    """World width (x) and height (z) of the drawing area, m."""

    def to_px(self, x, z) -> tuple[np.ndarray, np.ndarray]:
        """World (x, z) -> pixel (px, py); arrays in, arrays out."""
        px = self.origin[0] + (np.asarray(x, dtype=float) - self.grid.min_x) * self.scale
        py = self.origin[1] - (np.asarray(z, dtype=float) - self.grid.min_z) * self.scale
        return px, py

    def point(self, x: float, z: float) -> tuple[float, float]:
        """Scalar world point -> pixel."""
        return (self.origin[0] + (float(x) - self.grid.min_x) * self.scale,
                self.origin[1] - (float(z) - self.grid.min_z) * self.scale)

    def grid_to_px(self, gx, gy) -> tuple[np.ndarray, np.ndarray]:
        """Normalized grid (gx, gy) -> pixel, through the same NormalizedGrid mapping."""
        return self.to_px(*self.grid.to_world(gx, gy))

    def to_world(self, px, py) -> tuple[np.ndarray, np.ndarray]:
        """Pixel -> world (x, z)."""
        x = (np.asarray(px, dtype=float) - self.origin[0]) / self.scale + self.grid.min_x
        z = (self.origin[1] - np.asarray(py, dtype=float)) / self.scale + self.grid.min_z
        return x, z

    @property
    def area(self) -> tuple[float, float, float, float]:
        """Pixel box (left, top, right, bottom) of the house's bounding box."""
        left, bottom = self.origin
        return left, bottom - self.size_m[1] * self.scale, left + self.size_m[0] * self.scale, bottom


@dataclass(frozen=True)
class MapLayout:
    """Image size, margins and fonts of one render; both the drawing and tests use it."""

    width: int
    height: int
    transform: MapTransform
    font_size: int
    """Base font size (px): tick labels, captions and room names."""
    label_size: int
    """Font size of object id labels."""
    caption_top: float
    header_bottom: float
    """Lowest pixel row of the caption lines; labels stay below it."""
    legend_top: float
    legend_rows: list[list[str]]


_GRID_NOTE = "grid: x grows right, y grows up"


def _legend_items(trajectory: bool, grid: bool) -> list[str]:
    items = [_GRID_NOTE] if grid else []
    items += ["movable", "fixed", "small object", "wall decor", "door", "closed door", "window"]
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


def map_layout(geometry: SceneGeometry, *, size: int = 1024, grid: bool = False, captions: int = 0,
               legend: bool = True, trajectory: bool = False) -> MapLayout:
    """Fit the house into an image whose longer side is ``size`` px, keeping its aspect ratio.

    Margins hold the tick labels (left, bottom) when ``grid``, ``captions`` text lines on top
    and the legend at the bottom.
    """
    if size < _MIN_SIZE:
        raise AdaptenvError(f"render size {size} px is too small to read; use --size {_MIN_SIZE} or more")
    g = geometry.grid or NormalizedGrid.from_bounds(*geometry.bounds)
    min_x, min_z, max_x, max_z = geometry.bounds
    wx, wz = max_x - g.min_x, max_z - g.min_z
    fs = max(10, round(size / 80))
    label_fs = max(9, round(size / 88))
    small = max(9, fs - 2)
    _, line_h = text_size("Hg", fs)
    pad = round(fs * 0.8)
    left = (text_size("100", fs)[0] + fs * 0.6 + pad * 1.5) if grid else pad * 1.5
    right = pad * 2.0
    top = pad + captions * (line_h + 4) + (pad * 0.5 if captions else 0)
    ticks = (fs * 0.6 + line_h + pad * 0.5) if grid else pad
    _, small_h = text_size("Hg", small)
    items = _legend_items(trajectory, grid) if legend else []
    rows: list[list[str]] = []
    for _ in range(4):  # the legend may wrap once the width is known; settle in a few rounds
        bottom = ticks + (len(rows) * (small_h + 6) + pad * 0.5 if rows else pad * 0.5)
        scale = min((size - left - right) / wx, (size - top - bottom) / wz)
        width = left + right + wx * scale
        new_rows = _wrap_legend(items, small, width - 2 * pad) if items else []
        if len(new_rows) == len(rows):
            break
        rows = new_rows
    height = top + bottom + wz * scale
    transform = MapTransform(g, scale, (float(left), float(top + wz * scale)), (wx, wz))
    caption_top = pad * 0.6
    return MapLayout(int(math.ceil(width)), int(math.ceil(height)), transform, fs, label_fs, caption_top,
                     caption_top + captions * (line_h + 4), top + wz * scale + ticks + pad * 0.3, rows)


# ---------------------------------------------------------------- small geometry helpers
def _pts(transform: MapTransform, xy) -> list[tuple[float, float]]:
    """World points (N, 2) -> list of pixel tuples for ImageDraw."""
    a = np.asarray(xy, dtype=float).reshape(-1, 2)
    px, py = transform.to_px(a[:, 0], a[:, 1])
    return list(zip(px.tolist(), py.tolist(), strict=True))


def _overlap(boxes: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Pairwise intersection areas (K, N) of boxes (K, 4) and others (N, 4), as (x0, y0, x1, y1)."""
    if len(others) == 0:
        return np.zeros((len(boxes), 0))
    w = np.minimum(boxes[:, None, 2], others[None, :, 2]) - np.maximum(boxes[:, None, 0], others[None, :, 0])
    h = np.minimum(boxes[:, None, 3], others[None, :, 3]) - np.maximum(boxes[:, None, 1], others[None, :, 1])
    return np.clip(w, 0, None) * np.clip(h, 0, None)


def _crossings(a: np.ndarray, b: np.ndarray, segs: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Weighted count (default weight 1) of the segments (N, 2, 2) each segment a[k]->b properly crosses.

    ``a`` is (K, 2), ``b`` one point (2,).
    """
    if len(segs) == 0:
        return np.zeros(len(a))
    p, q = segs[None, :, 0], segs[None, :, 1]
    a_ = a[:, None, :]
    b_ = np.broadcast_to(b, a_.shape)

    def orient(u, v, w):
        return (v[..., 0] - u[..., 0]) * (w[..., 1] - u[..., 1]) - (v[..., 1] - u[..., 1]) * (w[..., 0] - u[..., 0])

    d1, d2 = orient(a_, b_, p), orient(a_, b_, q)
    d3, d4 = orient(p, q, a_), orient(p, q, b_)
    hit = (d1 * d2 < 0) & (d3 * d4 < 0)
    return hit.sum(axis=1) if weights is None else hit @ weights


def _colour(value: str, what: str) -> RGB:
    try:
        return ImageColor.getrgb(value)[:3]
    except ValueError:
        raise AdaptenvError(f"highlight colour {value!r} for {what} is not a colour Pillow knows; "
                            "use a name like 'red' or a hex code like '#ff0000'") from None


def _camel_words(name: str) -> str:
    """'LivingRoom' -> 'Living Room'."""
    out = []
    for i, ch in enumerate(name):
        if i and ch.isupper() and not name[i - 1].isupper():
            out.append(" ")
        out.append(ch)
    return "".join(out)


# ---------------------------------------------------------------- label placement
def _box_gap(boxes: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Pairwise gap (K, N) between boxes: 0 when they touch or overlap, else the larger axis distance."""
    dx = np.maximum(others[None, :, 0] - boxes[:, None, 2], boxes[:, None, 0] - others[None, :, 2])
    dy = np.maximum(others[None, :, 1] - boxes[:, None, 3], boxes[:, None, 1] - others[None, :, 3])
    return np.maximum(np.maximum(dx, dy), 0.0)


def _box_edges(b: np.ndarray) -> np.ndarray:
    """The four edges (4N, 2, 2) of boxes (N, 4)."""
    tl, tr, br, bl = b[:, [0, 1]], b[:, [2, 1]], b[:, [2, 3]], b[:, [0, 3]]
    return np.stack([np.stack([tl, tr], 1), np.stack([tr, br], 1), np.stack([br, bl], 1),
                     np.stack([bl, tl], 1)], axis=1).reshape(-1, 2, 2)


#: Candidates costing this much more than the best before leader terms are dropped.
_PRUNE = 6.0
#: Where along a leader (0 = label edge, 1 = object centre) it is sampled to keep it off other labels.
_LEADER_SAMPLES = np.linspace(0.05, 0.95, 13)


class _Rows:
    """A growable 2-D float array: appending a few rows at a time without copying everything each time."""

    def __init__(self, width: int, capacity: int = 64):
        self.data = np.zeros((capacity, width))
        self.n = 0

    def extend(self, rows: np.ndarray) -> None:
        rows = np.asarray(rows, dtype=float).reshape(-1, self.data.shape[1])
        if self.n + len(rows) > len(self.data):
            grown = np.zeros((2 * (self.n + len(rows)), self.data.shape[1]))
            grown[:self.n] = self.data[:self.n]
            self.data = grown
        self.data[self.n:self.n + len(rows)] = rows
        self.n += len(rows)

    @property
    def rows(self) -> np.ndarray:
        return self.data[:self.n]


class _Obstacles:
    """What labels steer around, all in pixels.

    - boxes (x0, y0, x1, y1, weight, flat): cost ``weight`` per unit of a label's area they cover,
      plus ``flat`` for touching them at all;
    - segments (px, py, qx, qy, cost, owner, bbox...): cost per leader crossing them (walls, leaders,
      label and furniture edges, small crosses on object centres). ``owner`` is the furniture row
      whose own leader may cross it, else -1;
    - points (x, y, weight): cost per point a label covers (the path, placed leaders).
    """

    def __init__(self, image: tuple[float, float, float, float], area: tuple[float, float, float, float]):
        self.image, self.area = image, area
        self.boxes, self.segs, self.points = _Rows(6, 256), _Rows(10, 512), _Rows(3, 1024)
        self.anchor_row0 = -1

    def add(self, boxes, weight: float, edge_cost: float = 0.0, owner: int = -1) -> None:
        """Append boxes (N, 4); with ``edge_cost`` their edges also cost that much per leader crossing
        (box k's edges then belong to furniture row ``owner + k``)."""
        b = np.asarray(boxes, dtype=float).reshape(-1, 4)
        rows = np.empty((len(b), 6))
        rows[:, :4], rows[:, 4], rows[:, 5] = b, weight, _FLAT_COST.get(weight, 0.0)
        self.boxes.extend(rows)
        if edge_cost:
            owners = np.repeat(np.arange(len(b)) + owner, 4) if owner >= 0 else -1
            self.add_segments(_box_edges(b), edge_cost, owners)

    def add_segments(self, segs, cost: float, owners=-1) -> None:
        segs = np.asarray(segs, dtype=float).reshape(-1, 2, 2)
        rows = np.empty((len(segs), 10))
        rows[:, :4], rows[:, 4], rows[:, 5] = segs.reshape(-1, 4), cost, owners
        rows[:, 6:8], rows[:, 8:10] = segs.min(axis=1), segs.max(axis=1)
        self.segs.extend(rows)

    def add_points(self, pts, weight: float) -> None:
        pts = np.asarray(pts, dtype=float).reshape(-1, 2)
        rows = np.empty((len(pts), 3))
        rows[:, :2], rows[:, 2] = pts, weight
        self.points.extend(rows)

    def add_anchors(self, anchors: np.ndarray) -> None:
        """The objects' centre dots: a label must not hide one, and a leader through one seems to
        point at it (each dot becomes a small cross of two segments)."""
        a = np.asarray(anchors, dtype=float).reshape(-1, 2)
        self.anchor_row0 = self.boxes.n  # the dot of furniture row k is box row anchor_row0 + k
        self.add(np.column_stack([a - 5.0, a + 5.0]), _W_ANCHOR)
        r = 4.0
        horiz = np.stack([a - (r, 0), a + (r, 0)], axis=1)
        vert = np.stack([a - (0, r), a + (0, r)], axis=1)
        owners = np.repeat(np.arange(len(a)), 2)
        self.add_segments(np.stack([horiz, vert], axis=1).reshape(-1, 2, 2), 3.0, owners)

    def add_label(self, box: tuple[float, float, float, float], anchor: tuple[float, float] | None) -> None:
        """A placed label (and its leader to ``anchor``, when it has one)."""
        self.add(box, _W_LABEL, edge_cost=5.0)
        if anchor is not None:
            a, b = np.asarray(_leader_start(box, anchor)), np.asarray(anchor)
            self.add_points(a + _LEADER_SAMPLES[:, None] * (b - a), 15.0)
            self.add_segments(np.stack([a, b]), 10.0)

    def cost(self, boxes: np.ndarray, anchor: tuple[float, float] | None, ring: np.ndarray,
             own: int | None = None) -> np.ndarray:
        """Badness of each candidate label box (K, 4): weighted overlaps, crossings, distance.

        ``own`` is the row of the labelled object's own box: a label nearer to another object than
        to its own reads as that object's label, which costs extra.
        """
        area = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
        rx0, ry0 = boxes[:, 0].min(), boxes[:, 1].min()
        rx1, ry1 = boxes[:, 2].max(), boxes[:, 3].max()
        ob = self.boxes.rows
        near = (ob[:, 0] < rx1) & (ob[:, 2] > rx0) & (ob[:, 1] < ry1) & (ob[:, 3] > ry0)
        if own is not None and self.anchor_row0 >= 0:
            near[self.anchor_row0 + own] = False
        nb = ob[near]
        ov = _overlap(boxes, nb[:, :4])
        c = (ov @ nb[:, 4]) / area + (ov > 0) @ nb[:, 5]
        pts = self.points.rows
        pts = pts[(pts[:, 0] >= rx0) & (pts[:, 0] <= rx1) & (pts[:, 1] >= ry0) & (pts[:, 1] <= ry1)]
        if len(pts):
            inside = ((pts[None, :, 0] >= boxes[:, 0:1]) & (pts[None, :, 0] <= boxes[:, 2:3])
                      & (pts[None, :, 1] >= boxes[:, 1:2]) & (pts[None, :, 1] <= boxes[:, 3:4]))
            c += inside @ pts[:, 2]
        ax0, ay0, ax1, ay1 = self.area
        inside_w = np.clip(np.minimum(boxes[:, 2], ax1) - np.maximum(boxes[:, 0], ax0), 0, None)
        inside_h = np.clip(np.minimum(boxes[:, 3], ay1) - np.maximum(boxes[:, 1], ay0), 0, None)
        c += 1.5 * (1.0 - inside_w * inside_h / area) + 0.8 * ring
        ix0, iy0, ix1, iy1 = self.image
        c[(boxes[:, 0] < ix0) | (boxes[:, 1] < iy0) | (boxes[:, 2] > ix1) | (boxes[:, 3] > iy1)] = np.inf
        if anchor is None:
            return c
        # The leader terms are dearer to compute: only for candidates that can still win.
        keep = np.flatnonzero(c <= c.min() + _PRUNE)
        if len(keep) == 0:
            return c
        kb = boxes[keep]
        extra = self._leader_cost(kb, anchor, own)
        if own is not None:
            extra += 2.0 * self._nearer_to_other(kb, own, near)
        out = np.full(len(c), np.inf)
        out[keep] = c[keep] + extra
        return out

    def _nearer_to_other(self, boxes: np.ndarray, own: int, near: np.ndarray) -> np.ndarray:
        """1 where some other furniture box is clearly closer to the candidate than the object's own box."""
        ob = self.boxes.rows
        others = near & (ob[:, 4] == _W_FURNITURE)
        others[own] = False
        if not others.any():
            return np.zeros(len(boxes))
        d_own = _box_gap(boxes, ob[own:own + 1, :4])[:, 0]
        d_other = _box_gap(boxes, ob[others, :4]).min(axis=1)
        return (d_other + 2.0 < d_own).astype(float)

    def _leader_cost(self, boxes: np.ndarray, anchor: tuple[float, float], own: int | None) -> np.ndarray:
        """Leaders crossing walls, other leaders, labels, other furniture or another object's
        centre dot are confusing: the summed cost of the segments each would cross."""
        ax, ay = anchor
        sx, sy = np.clip(ax, boxes[:, 0], boxes[:, 2]), np.clip(ay, boxes[:, 1], boxes[:, 3])
        x0, y0 = min(sx.min(), ax), min(sy.min(), ay)
        x1, y1 = max(sx.max(), ax), max(sy.max(), ay)
        sg = self.segs.rows
        sel = (sg[:, 6] <= x1) & (sg[:, 8] >= x0) & (sg[:, 7] <= y1) & (sg[:, 9] >= y0)
        if own is not None:
            sel &= sg[:, 5] != own
        sg = sg[sel]
        return _crossings(np.stack([sx, sy], axis=1), np.asarray(anchor, dtype=float),
                          sg[:, :4].reshape(-1, 2, 2), sg[:, 4])


@lru_cache(maxsize=8)
def _candidate_template(rings: int, gap: float = 3.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Candidate label centres as linear maps of (1, hw, hh, w, h) around an object's box centre.

    For the object box half-sizes (hw, hh) and the label size (w, h): above and below the box
    sliding along it, left and right of it, and at its four corners, ring r pushed r label
    heights further out. Returns the x and y coefficient matrices (K, 5) and each candidate's
    distance rank (its ring; sides and corners slightly worse).
    """
    mx, my, rank = [], [], []
    for r in range(rings):
        out = [gap + 2 * r, 0, 0, 0, r]  # gap + r * (h + 2)
        side = [gap + 3 * r, 0, 0, 0, 1.5 * r]  # sideways rings step wider
        for sign in (-1, 1):  # above, below
            for k, slide in enumerate((0.0, -0.5, 0.5, -1.0, 1.0)):
                mx.append([0, 0, 0, slide / 2, 0])
                my.append([sign * (out[0]), 0, sign, 0, sign * (out[4] + 0.5)])
                rank.append(r + 0.05 * (k > 0) + 0.05 * (k > 2))
        for sign in (-1, 1):  # left, right
            for ys in ([0, 0, 0, 0, 0], [0, 0, -1, 0, 0.5], [0, 0, 1, 0, -0.5]):
                mx.append([sign * side[0], sign, 0, sign * 0.5, sign * side[4]])
                my.append(ys)
                rank.append(r + 0.1)
        for sx in (-1, 1):  # corners
            for sy in (-1, 1):
                mx.append([sx * out[0], sx, 0, sx * 0.5, sx * out[4]])
                my.append([sy * out[0], 0, sy, 0, sy * (out[4] + 0.5)])
                rank.append(r + 0.3)
    return np.array(mx, dtype=float), np.array(my, dtype=float), np.array(rank)


def _candidates(box: tuple[float, float, float, float], w: float, h: float,
                rings: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Candidate label boxes (K, 4) around a pixel box and their distance ranks (see the template)."""
    mx, my, rank = _candidate_template(rings)
    x0, y0, x1, y1 = box
    v = np.array([1.0, (x1 - x0) / 2, (y1 - y0) / 2, w, h])
    px = (x0 + x1) / 2 + mx @ v
    py = (y0 + y1) / 2 + my @ v
    return np.stack([px - w / 2, py - h / 2, px + w / 2, py + h / 2], axis=1), rank


@dataclass(frozen=True)
class PlacedLabel:
    """An object id label as drawn: its pixel box, font size, and whether it sits inside the object."""

    text: str
    box: tuple[float, float, float, float]
    size: int
    inside: bool
    anchor: tuple[float, float]
    """Pixel centre of the labelled object (where an outside label's leader ends)."""
    edge: RGB = LABEL_EDGE


@dataclass(frozen=True)
class MapRender:
    """A render plus how it was laid out: the pixel transform and where every id label went."""

    image: Image.Image
    layout: MapLayout
    labels: list[PlacedLabel]

    @property
    def transform(self) -> MapTransform:
        return self.layout.transform


def _fits_inside(fp: Footprint, t: MapTransform, w: float, h: float, inset: float) -> bool:
    """Whether an axis-aligned w x h text box centred on the object lies inside its oriented rectangle.

    ``inset`` (px) is kept clear at the front and back (the front tick) and 2 px at the sides.
    """
    a = math.radians(fp.yaw)
    c, s = abs(math.cos(a)), abs(math.sin(a))
    hx, hz = fp.size[0] * t.scale / 2 - 2.0, fp.size[1] * t.scale / 2 - inset
    # Half-extent of the text box projected on the object's local x and z axes.
    return w / 2 * c + h / 2 * s <= hx and w / 2 * s + h / 2 * c <= hz


def _place_object_labels(floor: list[Footprint], t: MapTransform, layout: MapLayout, obst: _Obstacles,
                         boxes: dict[str, tuple[float, float, float, float]], edges: dict[str, RGB],
                         inset: float) -> list[PlacedLabel]:
    """Put every floor object's full id inside its rectangle when it fits, else beside it with a leader."""
    out: list[PlacedLabel] = []
    outside: list[Footprint] = []
    index = {oid: i for i, oid in enumerate(boxes)}  # furniture rows come first in ``obst``
    fs, min_fs = layout.label_size, max(9, layout.label_size - 2)
    for fp in floor:
        anchor = t.point(*fp.center)
        for s in range(fs, min_fs - 1, -1):
            w, h = text_size(fp.object_id, s)
            w += 4
            if _fits_inside(fp, t, w, h, inset):
                box = (anchor[0] - w / 2, anchor[1] - h / 2, anchor[0] + w / 2, anchor[1] + h / 2)
                out.append(PlacedLabel(fp.object_id, box, s, True, anchor, edges.get(fp.object_id, LABEL_EDGE)))
                obst.add_label(box, None)
                break
        else:
            outside.append(fp)
    # Most crowded first: their good spots are scarcest.
    centres = np.array([t.point(*fp.center) for fp in outside]).reshape(-1, 2)
    crowd = [int((np.hypot(*(centres - c).T) < 6 * fs).sum()) for c in centres]
    for i in sorted(range(len(outside)), key=lambda k: -crowd[k]):
        fp = outside[i]
        w, h = text_size(fp.object_id, fs)
        w, h = w + 6, h + 2
        anchor = t.point(*fp.center)
        # Near spots first; look further out only when none of them is clean.
        cand, ring = _candidates(boxes[fp.object_id], w, h)
        cost = obst.cost(cand, anchor, ring, own=index[fp.object_id])
        k = int(np.argmin(cost))
        box = tuple(float(v) for v in cand[k])
        out.append(PlacedLabel(fp.object_id, box, fs, False, anchor, edges.get(fp.object_id, LABEL_EDGE)))
        obst.add_label(box, anchor)
    return out


def _room_name_boxes(geometry: SceneGeometry, t: MapTransform, fs: int, obst: _Obstacles
                     ) -> list[tuple[str, str, tuple[float, float, float, float]]]:
    """Where to write each room's type: inside the room, away from furniture and other labels."""
    out = []
    for rid, poly in geometry.rooms.items():
        name = _camel_words(geometry.room_types.get(rid, "room"))
        w, h = text_size(name, fs)
        w, h = w + 4, h
        x0, z0, x1, z1 = poly.bounds
        (px0, py1), (px1, py0) = t.point(x0, z0), t.point(x1, z1)
        if px1 - px0 < w or py1 - py0 < h:
            continue
        cx = np.linspace(px0 + w / 2 + 4, px1 - w / 2 - 4, 7)
        cy = np.linspace(py0 + h / 2 + 4, py1 - h / 2 - 4, 7)
        gx, gy = (a.ravel() for a in np.meshgrid(cx, cy))
        boxes = np.stack([gx - w / 2, gy - h / 2, gx + w / 2, gy + h / 2], axis=1)
        cornx = np.concatenate([boxes[:, 0], boxes[:, 2], boxes[:, 2], boxes[:, 0]])
        corny = np.concatenate([boxes[:, 1], boxes[:, 1], boxes[:, 3], boxes[:, 3]])
        wx, wz = t.to_world(cornx, corny)
        ok = shapely.contains_xy(poly, wx, wz).reshape(4, -1).all(axis=0)
        if not ok.any():
            continue
        centre = np.array(t.point(*poly.centroid.coords[0]))
        dist = np.hypot(gx - centre[0], gy - centre[1]) / max(px1 - px0, py1 - py0)
        cost = obst.cost(boxes, None, np.zeros(len(boxes))) + dist
        cost[~ok] = np.inf
        k = int(np.argmin(cost))
        box = tuple(float(v) for v in boxes[k])
        obst.add(box, _W_ROOM_NAME)
        out.append((rid, name, box))
    return out


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


def _draw_doors(draw: ImageDraw.ImageDraw, geometry: SceneGeometry, t: MapTransform, wall_w: int) -> None:
    """Open doors as a gap with their leaves and swing arcs (none for a doorframe, one from each jamb for a
    double door); closed doors as a red bar."""
    for d in geometry.doors:
        p0, p1 = np.array(d.p0), np.array(d.p1)
        width = float(np.linalg.norm(p1 - p0))
        if width < 1e-6:
            continue
        u = (p1 - p0) / width
        n = np.array([-u[1], u[0]])
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
    if m is not None:
        parts += [("   |   ", CAPTION_TEXT),
                  ("SUCCESS" if m.success else "FAILURE", SUCCESS_TEXT if m.success else FAILURE_TEXT)]
        collisions = m.collisions
        tail = f"   |   {n} steps   |   {collisions} collisions   |   SPL {m.spl:.2f}"
    else:
        tail = f"   |   {n} steps   |   {collisions} collisions"
    if traj.policy:
        tail += f"   |   policy: {traj.policy}"
    parts.append((tail, CAPTION_TEXT))
    return parts


def _draw_runs(image: Image.Image, x: float, y: float, parts: list[tuple[str, RGB]], fs: int,
               bold: bool, max_w: float) -> None:
    """Draw coloured text runs on one line, shrinking the font until the line fits ``max_w``."""
    size = fs
    while size > 8 and sum(text_size(s, size, bold)[0] for s, _ in parts) > max_w:
        size -= 1
    for s, colour in parts:
        draw_text(image, (x, y), s, size, colour, anchor="lt", bold=bold)
        x += text_size(s, size, bold)[0]


def _draw_legend(image: Image.Image, draw: ImageDraw.ImageDraw, layout: MapLayout, wall_w: int) -> None:
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


def _obstacles(layout: MapLayout, boxes: dict[str, tuple[float, float, float, float]], anchors: list,
               wall_segs: np.ndarray,
               wall_w: int, trajectory: Trajectory | None, agent_r: float, cross_arm: float,
               grid: bool) -> _Obstacles:
    """Everything labels should not cover: furniture, walls, markers, the path and the tick labels."""
    t = layout.transform
    left, top, right, bottom = t.area
    path = np.zeros((0, 2))
    if trajectory is not None:
        px, py = t.to_px([p.x for p in trajectory.poses], [p.z for p in trajectory.poses])
        path = np.stack([px, py], axis=1)
    image = (1.0, layout.header_bottom + 1.0, layout.width - 1.0, min(layout.legend_top - 2, layout.height - 1.0))
    obst = _Obstacles(image, t.area)
    obst.add(list(boxes.values()), _W_FURNITURE, edge_cost=1.5, owner=0)  # furniture rows come first
    obst.add_anchors(np.asarray(anchors, dtype=float))
    obst.add_segments(wall_segs, 8.0)
    obst.add_points(path, 0.25)
    half = wall_w / 2 + 1
    if len(wall_segs):
        obst.add(np.stack([wall_segs[:, :, 0].min(1) - half, wall_segs[:, :, 1].min(1) - half,
                           wall_segs[:, :, 0].max(1) + half, wall_segs[:, :, 1].max(1) + half], axis=1), _W_WALL)
    if trajectory is not None:
        for pose in (trajectory.start, trajectory.poses[-1]):
            cx, cy = t.point(pose.x, pose.z)
            obst.add((cx - agent_r * 2, cy - agent_r * 2, cx + agent_r * 2, cy + agent_r * 2), _W_MARKER)
        for x, z in trajectory.target_positions:
            cx, cy = t.point(x, z)
            obst.add((cx - cross_arm - 2, cy - cross_arm - 2, cx + cross_arm + 2, cy + cross_arm + 2), _W_MARKER)
    if grid:  # keep labels off the tick labels
        obst.add([(0, bottom + 1, layout.width, layout.height), (0, 0, left - 1, layout.height)], _W_LABEL)
    return obst


def render_map(house: House | None = None, *, trajectory: Trajectory | None = None, grid: bool = False,
               size: int = 1024, highlight: dict[str, str] | None = None, labels: bool = True,
               title: str | None = None, geometry: SceneGeometry | None = None,
               legend: bool = True) -> MapRender:
    """Render the top-down map and also return the layout (pixel transform) it was drawn with."""
    if geometry is None:
        if house is None:
            raise AdaptenvError("render_map needs a house or its SceneGeometry")
        geometry = SceneGeometry.from_house(house)
    known = {f.object_id for f in geometry.footprints} | {c.object_id for k in geometry.children.values() for c in k}
    colours: dict[str, RGB] = {}
    for oid, value in (highlight or {}).items():
        if oid not in known:
            raise AdaptenvError(f"cannot highlight {oid!r}: the house has no object with that id; "
                                "use an id from the house's objects")
        colours[oid] = _colour(value, oid)
    captions = int(title is not None) + int(trajectory is not None)
    layout = map_layout(geometry, size=size, grid=grid, captions=captions, legend=legend,
                        trajectory=trajectory is not None)
    t = layout.transform
    image = Image.new("RGB", (layout.width, layout.height), BACKGROUND)
    draw = ImageDraw.Draw(image)
    wall_w = max(3, round(0.1 * t.scale))
    area = t.area

    # Floors, then the grid lines on top of them but under everything else.
    for rid, poly in geometry.rooms.items():
        fill = ROOM_FILLS.get(geometry.room_types.get(rid, ""), ROOM_FILL_OTHER)
        draw.polygon(_pts(t, poly.exterior.coords), fill=fill)
    if grid:
        _draw_grid(image, draw, layout)

    floor = geometry.floor_objects
    decor = [f for f in geometry.footprints if f.role == "wall"]
    boxes: dict[str, tuple[float, float, float, float]] = {}
    for fp in floor:
        px, py = t.to_px(fp.corners[:, 0], fp.corners[:, 1])
        boxes[fp.object_id] = (float(px.min()), float(py.min()), float(px.max()), float(py.max()))

    pieces, empty = _wall_pieces(geometry)
    wall_segs = np.array([_pts(t, [p0, p1]) for p0, p1, _, _ in pieces], dtype=float).reshape(-1, 2, 2)
    agent_r = max(5.0, AGENT_RADIUS * t.scale)
    cross_arm = max(7.0, 0.28 * t.scale)
    anchors = [t.point(*fp.center) for fp in floor]
    obst = _obstacles(layout, boxes, anchors, wall_segs, wall_w, trajectory, agent_r, cross_arm, grid)

    room_names = _room_name_boxes(geometry, t, layout.font_size, obst) if labels else []
    for rid, name, box in room_names:
        fill = ROOM_FILLS.get(geometry.room_types.get(rid, ""), ROOM_FILL_OTHER)
        dark = tuple(int(c * 0.55) for c in fill)
        draw_text(image, ((box[0] + box[2]) / 2, (box[1] + box[3]) / 2), name, layout.font_size, dark,
                  anchor="mm")

    tick_len = min(max(4.0, 0.15 * t.scale), 8.0)
    _draw_furniture(draw, floor, t, colours, tick_len)
    _draw_small(draw, geometry, t, colours, max(1.5, 0.035 * t.scale))
    _draw_walls(draw, t, pieces, empty, wall_w)
    _draw_windows(draw, geometry, t, wall_w)
    _draw_doors(draw, geometry, t, wall_w)
    _draw_decor(draw, decor, t, colours, wall_w)
    if trajectory is not None:
        _draw_trajectory(draw, trajectory, t, max(2, round(t.scale * 0.05)))

    placed: list[PlacedLabel] = []
    if labels:
        placed = _place_object_labels(floor, t, layout, obst, boxes, colours, tick_len + 1)
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
            draw_text(image, ((x0 + x1) / 2, (y0 + y1) / 2), lab.text, lab.size, LABEL_TEXT, anchor="mm")

    if trajectory is not None:
        for x, z in trajectory.target_positions:
            _target_cross(draw, *t.point(x, z), cross_arm, max(3, round(0.06 * t.scale)))
        s = trajectory.start
        _pose_marker(draw, t, s.x, s.z, s.yaw, START_FILL, agent_r)
        if trajectory.steps or trajectory.final_pose is not None:
            e = trajectory.poses[-1]
            _pose_marker(draw, t, e.x, e.z, e.yaw, END_FILL, agent_r)

    y = layout.caption_top
    max_w = layout.width - 2 * area[0] if area[0] > 0 else layout.width
    if title is not None:
        _draw_runs(image, area[0], y, [(title, CAPTION_TEXT)], layout.font_size + 1, True, max_w)
        y += text_size("Hg", layout.font_size)[1] + 4
    if trajectory is not None:
        _draw_runs(image, area[0], y, _caption_parts(trajectory), layout.font_size, False, max_w)
    if legend:
        _draw_legend(image, draw, layout, wall_w)
    return MapRender(image, layout, placed)


def _leader_start(box: tuple[float, float, float, float], anchor: tuple[float, float]) -> tuple[float, float]:
    """The point of a label box nearest to its object's centre: where the leader leaves the label."""
    return min(max(anchor[0], box[0]), box[2]), min(max(anchor[1], box[1]), box[3])


def _draw_leader(draw: ImageDraw.ImageDraw, lab: PlacedLabel) -> None:
    """A thin line from the label box's nearest edge point to the object's centre, ending in a dot."""
    ax, ay = lab.anchor
    draw.line([_leader_start(lab.box, lab.anchor), (ax, ay)], fill=LEADER, width=1)
    draw.ellipse([ax - 2, ay - 2, ax + 2, ay + 2], fill=LEADER)


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
        highlight: object id -> colour (a Pillow colour name or '#rrggbb') to fill that object with.
        labels: write every floor object's id and each room's type.
        title: a bold line above the map.
        geometry: precomputed ``SceneGeometry.from_house(house)`` (saves ~2 ms per render).
        legend: a key of the symbols under the map.
    """
    return render_map(house, trajectory=trajectory, grid=grid, size=size, highlight=highlight, labels=labels,
                      title=title, geometry=geometry, legend=legend).image


def save_render(image: Image.Image, path: str | Path) -> Path:
    """Write a render as PNG (or whatever the suffix names), creating parent folders."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    try:
        image.save(p)
    except (ValueError, OSError) as exc:
        raise AdaptenvError(f"{p}: cannot write the image ({exc}); use a writable path ending in .png") from None
    return p


def render_to_file(house: House, path: str | Path, **kw) -> Path:
    """Render a house (same keywords as :func:`render_house`) straight to an image file."""
    return save_render(render_house(house, **kw), path)
