"""Label placement for the top-down map: where each object id and room name goes.

Every floor object gets its full id, inside its rectangle when the text fits, else beside it with
a leader line to its centre. Outside labels are placed one at a time (most crowded first) by
scoring candidate boxes around the object against an :class:`Obstacles` store: the boxes,
segments and points already on the map, each record tagged with its :class:`Kind`. A kind's
:class:`Costs` say what a label pays for covering it (per unit of label area, plus a flat touch
cost), for a leader crossing it, or for covering one of its points. Room names are placed first,
inside their rooms, away from furniture.

Nothing here draws: :mod:`adaptenv.render.topdown` draws what this module places.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np
import shapely

from adaptenv.render.layout import MapLayout, MapTransform
from adaptenv.render.text import RGB, text_size
from adaptenv.scene.assets import object_label
from adaptenv.scene.geometry import Footprint, SceneGeometry

if TYPE_CHECKING:
    from adaptenv.sim.trajectory import Trajectory

Box = tuple[float, float, float, float]
"""A pixel box (x0, y0, x1, y1)."""


class Kind(IntEnum):
    """What an obstacle record is: the column that says what a label pays for it (see :data:`COSTS`)."""

    FURNITURE = 0
    """A floor object's pixel bounding box (and its edges)."""
    ANCHOR = 1
    """An object's centre dot, where its leader ends (a box and a small cross of two segments)."""
    WALL = 2
    """A drawn wall piece: its segment and its bounding box."""
    PATH = 3
    """A trajectory pose."""
    MARKER = 4
    """The start and end pose markers and the target crosses."""
    TICK_LABELS = 5
    """The margins holding the grid's tick labels."""
    ROOM_NAME = 6
    """A placed room name."""
    LABEL = 7
    """A placed object id label (and its edges)."""
    LEADER = 8
    """A placed label's leader line (a segment and points sampled along it)."""


@dataclass(frozen=True)
class Costs:
    """What a label pays for one kind of obstacle (0 where the kind has no such record)."""

    cover: float = 0.0
    """Per unit of the label's area a box covers."""
    touch: float = 0.0
    """Flat, for covering a box at all (thin walls cover little area but must stay visible)."""
    edge: float = 0.0
    """Per leader crossing one of a box's edges."""
    cross: float = 0.0
    """Per leader crossing a segment."""
    point: float = 0.0
    """Per point the label covers."""


COSTS: dict[Kind, Costs] = {
    Kind.FURNITURE: Costs(cover=6.0, touch=1.0, edge=1.5),
    Kind.ANCHOR: Costs(cover=200.0, touch=15.0, cross=3.0),
    Kind.WALL: Costs(cover=5.0, touch=3.0, cross=8.0),
    Kind.PATH: Costs(point=0.25),
    Kind.MARKER: Costs(cover=40.0, touch=5.0),
    Kind.TICK_LABELS: Costs(cover=300.0, touch=50.0),
    Kind.ROOM_NAME: Costs(cover=20.0, touch=1.0),
    Kind.LABEL: Costs(cover=300.0, touch=50.0, edge=5.0),
    Kind.LEADER: Costs(cross=10.0, point=15.0),
}
#: The most floor objects that get id labels. Each label is weighed against every record near its candidate spots,
#: and a fixed-size map packs more objects closer together, so placement grows with the square of the objects (2,000
#: took 21 s): a house with more is drawn with its room names only, where the ids would cover the map anyway.
LABEL_LIMIT = 500


def labels_fit(n_objects: int) -> bool:
    """Whether ``n_objects`` floor objects get id labels (at most :data:`LABEL_LIMIT`)."""
    return n_objects <= LABEL_LIMIT


# ---------------------------------------------------------------- pixel box geometry


def _overlap(boxes: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Pairwise intersection areas (K, N) of boxes (K, 4) and others (N, 4), as (x0, y0, x1, y1)."""
    if len(others) == 0:
        return np.zeros((len(boxes), 0))
    w = np.minimum(boxes[:, None, 2], others[None, :, 2]) - np.maximum(boxes[:, None, 0], others[None, :, 0])
    h = np.minimum(boxes[:, None, 3], others[None, :, 3]) - np.maximum(boxes[:, None, 1], others[None, :, 1])
    return np.clip(w, 0, None) * np.clip(h, 0, None)


def _touches(boxes: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Per box (K, 4): whether it intersects (or touches) any of ``others`` (N, 4)."""
    if len(others) == 0:
        return np.zeros(len(boxes), dtype=bool)
    return ((boxes[:, None, 0] <= others[None, :, 2]) & (boxes[:, None, 2] >= others[None, :, 0])
            & (boxes[:, None, 1] <= others[None, :, 3]) & (boxes[:, None, 3] >= others[None, :, 1])).any(axis=1)


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


def camel_words(name: str) -> str:
    """'LivingRoom' -> 'Living Room'."""
    out = []
    for i, ch in enumerate(name):
        if i and ch.isupper() and not name[i - 1].isupper():
            out.append(" ")
        out.append(ch)
    return "".join(out)


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


# ---------------------------------------------------------------- the obstacle store and candidates
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


class Obstacles:
    """What labels steer around, all in pixels; every record has a :class:`Kind` column.

    - boxes (x0, y0, x1, y1, kind, cover, touch): cost ``cover`` per unit of a label's area they
      cover, plus ``touch`` for touching them at all (both from :data:`COSTS` of the kind);
    - segments (px, py, qx, qy, kind, cost, owner, bbox...): cost per leader crossing them (walls,
      leaders, label and furniture edges, small crosses on object centres). ``owner`` is the
      furniture row whose own leader may cross it, else -1;
    - points (x, y, kind, cost): cost per point a label covers (the path, placed leaders).
    """

    def __init__(self, image: Box, area: Box):
        self.image, self.area = image, area
        self.boxes, self.segs, self.points = _Rows(7, 256), _Rows(11, 512), _Rows(4, 1024)
        self.anchor_row0 = -1

    def add(self, boxes, kind: Kind, owner: int = -1) -> None:
        """Append boxes (N, 4) of one kind; when the kind has an edge cost their edges are also
        segments (box k's edges then belong to furniture row ``owner + k``)."""
        b = np.asarray(boxes, dtype=float).reshape(-1, 4)
        rows = np.empty((len(b), 7))
        rows[:, :4], rows[:, 4], rows[:, 5], rows[:, 6] = b, kind, COSTS[kind].cover, COSTS[kind].touch
        self.boxes.extend(rows)
        if COSTS[kind].edge:
            owners = np.repeat(np.arange(len(b)) + owner, 4) if owner >= 0 else -1
            self._add_segments(_box_edges(b), kind, COSTS[kind].edge, owners)

    def add_segments(self, segs, kind: Kind, owners=-1) -> None:
        """Append segments (N, 2, 2) of one kind (a leader crossing one costs the kind's ``cross``)."""
        self._add_segments(segs, kind, COSTS[kind].cross, owners)

    def _add_segments(self, segs, kind: Kind, cost: float, owners) -> None:
        segs = np.asarray(segs, dtype=float).reshape(-1, 2, 2)
        rows = np.empty((len(segs), 11))
        rows[:, :4], rows[:, 4], rows[:, 5], rows[:, 6] = segs.reshape(-1, 4), kind, cost, owners
        rows[:, 7:9], rows[:, 9:11] = segs.min(axis=1), segs.max(axis=1)
        self.segs.extend(rows)

    def add_points(self, pts, kind: Kind) -> None:
        """Append points (N, 2) of one kind (a label covering one costs the kind's ``point``)."""
        pts = np.asarray(pts, dtype=float).reshape(-1, 2)
        rows = np.empty((len(pts), 4))
        rows[:, :2], rows[:, 2], rows[:, 3] = pts, kind, COSTS[kind].point
        self.points.extend(rows)

    def add_anchors(self, anchors: np.ndarray) -> None:
        """The objects' centre dots: a label must not hide one, and a leader through one seems to
        point at it (each dot becomes a small cross of two segments)."""
        a = np.asarray(anchors, dtype=float).reshape(-1, 2)
        self.anchor_row0 = self.boxes.n  # the dot of furniture row k is box row anchor_row0 + k
        self.add(np.column_stack([a - 5.0, a + 5.0]), Kind.ANCHOR)
        r = 4.0
        horiz = np.stack([a - (r, 0), a + (r, 0)], axis=1)
        vert = np.stack([a - (0, r), a + (0, r)], axis=1)
        owners = np.repeat(np.arange(len(a)), 2)
        self.add_segments(np.stack([horiz, vert], axis=1).reshape(-1, 2, 2), Kind.ANCHOR, owners)

    def add_label(self, box: Box, anchor: tuple[float, float] | None) -> None:
        """A placed label (and its leader to ``anchor``, when it has one)."""
        self.add(box, Kind.LABEL)
        if anchor is not None:
            a, b = np.asarray(leader_start(box, anchor)), np.asarray(anchor)
            self.add_points(a + _LEADER_SAMPLES[:, None] * (b - a), Kind.LEADER)
            self.add_segments(np.stack([a, b]), Kind.LEADER)

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
        c = (ov @ nb[:, 5]) / area + (ov > 0) @ nb[:, 6]
        pts = self.points.rows
        pts = pts[(pts[:, 0] >= rx0) & (pts[:, 0] <= rx1) & (pts[:, 1] >= ry0) & (pts[:, 1] <= ry1)]
        if len(pts):
            inside = ((pts[None, :, 0] >= boxes[:, 0:1]) & (pts[None, :, 0] <= boxes[:, 2:3])
                      & (pts[None, :, 1] >= boxes[:, 1:2]) & (pts[None, :, 1] <= boxes[:, 3:4]))
            c += inside @ pts[:, 3]
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
        others = near & (ob[:, 4] == Kind.FURNITURE)
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
        sel = (sg[:, 7] <= x1) & (sg[:, 9] >= x0) & (sg[:, 8] <= y1) & (sg[:, 10] >= y0)
        if own is not None:
            sel &= sg[:, 6] != own
        sg = sg[sel]
        return _crossings(np.stack([sx, sy], axis=1), np.asarray(anchor, dtype=float),
                          sg[:, :4].reshape(-1, 2, 2), sg[:, 5])


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


def _candidates(box: Box, w: float, h: float,
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
    box: Box
    size: int
    inside: bool
    anchor: tuple[float, float]
    """Pixel centre of the labelled object (where an outside label's leader ends)."""
    edge: RGB
    """Colour of the label's frame (the object's highlight colour, else the default)."""


def fits_inside(fp: Footprint, t: MapTransform, w: float, h: float, inset: float) -> bool:
    """Whether an axis-aligned w x h text box centred on the object lies inside its oriented rectangle.

    ``inset`` (px) is kept clear at the front and back (the front tick) and 2 px at the sides.
    """
    a = math.radians(fp.yaw)
    c, s = abs(math.cos(a)), abs(math.sin(a))
    hx, hz = fp.size[0] * t.scale / 2 - 2.0, fp.size[1] * t.scale / 2 - inset
    # Half-extent of the text box projected on the object's local x and z axes.
    return w / 2 * c + h / 2 * s <= hx and w / 2 * s + h / 2 * c <= hz


def place_object_labels(floor: list[Footprint], t: MapTransform, layout: MapLayout, obst: Obstacles,
                        boxes: dict[str, Box], edges: dict[str, RGB], default_edge: RGB,
                        inset: float, keep_off: Sequence[Box] = ()) -> list[PlacedLabel]:
    """Put every floor object's full id (led by its type when the id does not name it: :func:`object_label`)
    inside its rectangle when it fits, else beside it with a leader.

    ``boxes`` are the objects' pixel bounding boxes (the first rows of ``obst``), ``edges`` the
    frame colours of highlighted objects, ``inset`` the pixels kept clear at an object's front and back;
    no label may cover a box of ``keep_off`` (the target crosses, drawn over the labels).
    """
    off = np.asarray(keep_off, dtype=float).reshape(-1, 4)
    out: list[PlacedLabel] = []
    outside: list[Footprint] = []
    index = {oid: i for i, oid in enumerate(boxes)}  # furniture rows come first in ``obst``
    fs, min_fs = layout.label_size, max(9, layout.label_size - 2)
    for fp in floor:
        anchor = t.point(*fp.center)
        text = object_label(fp.object_id, fp.object_type)
        for s in range(fs, min_fs - 1, -1):
            w, h = text_size(text, s)
            w += 4
            box = (anchor[0] - w / 2, anchor[1] - h / 2, anchor[0] + w / 2, anchor[1] + h / 2)
            if fits_inside(fp, t, w, h, inset) and not _touches(np.array([box]), off).any():
                out.append(PlacedLabel(text, box, s, True, anchor, edges.get(fp.object_id, default_edge)))
                obst.add_label(box, None)
                break
        else:
            outside.append(fp)
    # Most crowded first: their good spots are scarcest.
    centres = np.array([t.point(*fp.center) for fp in outside]).reshape(-1, 2)
    crowd = [int((np.hypot(*(centres - c).T) < 6 * fs).sum()) for c in centres]
    for i in sorted(range(len(outside)), key=lambda k: -crowd[k]):
        fp = outside[i]
        text = object_label(fp.object_id, fp.object_type)
        w, h = text_size(text, fs)
        w, h = w + 6, h + 2
        anchor = t.point(*fp.center)
        # Near spots first; look further out only when none of them is clean.
        cand, ring = _candidates(boxes[fp.object_id], w, h)
        cost = obst.cost(cand, anchor, ring, own=index[fp.object_id])
        cost[_touches(cand, off)] = np.inf
        k = int(np.argmin(cost))
        box = tuple(float(v) for v in cand[k])
        out.append(PlacedLabel(text, box, fs, False, anchor, edges.get(fp.object_id, default_edge)))
        obst.add_label(box, anchor)
    return out


def place_room_names(geometry: SceneGeometry, t: MapTransform, fs: int, obst: Obstacles) -> list[tuple[str, str, Box]]:
    """Where to write each room's type: inside the room, away from furniture and other labels."""
    out = []
    for rid, poly in geometry.rooms.items():
        name = camel_words(geometry.room_types.get(rid, "room"))
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
        obst.add(box, Kind.ROOM_NAME)
        out.append((rid, name, box))
    return out


def label_obstacles(layout: MapLayout, boxes: dict[str, Box], anchors: list, wall_segs: np.ndarray,
                    wall_w: int, trajectory: Trajectory | None, agent_r: float, cross_arm: float,
                    grid: bool) -> Obstacles:
    """Everything labels should not cover: furniture, walls, markers, the path and the tick labels.

    ``boxes`` and ``anchors`` are the floor objects' pixel bounding boxes and centres, ``wall_segs``
    the drawn wall pieces (N, 2, 2) in pixels; ``agent_r`` and ``cross_arm`` the marker sizes.
    """
    t = layout.transform
    left, top, right, bottom = t.area
    path = np.zeros((0, 2))
    if trajectory is not None:
        px, py = t.to_px([p.x for p in trajectory.poses], [p.z for p in trajectory.poses])
        path = np.stack([px, py], axis=1)
    image = (1.0, layout.header_bottom + 1.0, layout.width - 1.0, min(layout.legend_top - 2, layout.height - 1.0))
    obst = Obstacles(image, t.area)
    obst.add(list(boxes.values()), Kind.FURNITURE, owner=0)  # furniture rows come first
    obst.add_anchors(np.asarray(anchors, dtype=float))
    obst.add_segments(wall_segs, Kind.WALL)
    obst.add_points(path, Kind.PATH)
    half = wall_w / 2 + 1
    if len(wall_segs):
        obst.add(np.stack([wall_segs[:, :, 0].min(1) - half, wall_segs[:, :, 1].min(1) - half,
                           wall_segs[:, :, 0].max(1) + half, wall_segs[:, :, 1].max(1) + half], axis=1), Kind.WALL)
    if trajectory is not None:
        for pose in (trajectory.start, trajectory.poses[-1]):
            cx, cy = t.point(pose.x, pose.z)
            obst.add((cx - agent_r * 2, cy - agent_r * 2, cx + agent_r * 2, cy + agent_r * 2), Kind.MARKER)
        obst.add(target_boxes(t, trajectory, cross_arm), Kind.MARKER)
    if grid:  # keep labels off the tick labels
        obst.add([(0, bottom + 1, layout.width, layout.height), (0, 0, left - 1, layout.height)], Kind.TICK_LABELS)
    return obst


def target_boxes(t: MapTransform, trajectory: Trajectory | None, cross_arm: float) -> list[Box]:
    """Pixel boxes of the episode's target crosses (with a 2 px margin)."""
    if trajectory is None:
        return []
    centres = [t.point(x, z) for x, z in trajectory.target_positions]
    return [(cx - cross_arm - 2, cy - cross_arm - 2, cx + cross_arm + 2, cy + cross_arm + 2) for cx, cy in centres]


def leader_start(box: Box, anchor: tuple[float, float]) -> tuple[float, float]:
    """The point of a label box nearest to its object's centre: where the leader leaves the label."""
    return min(max(anchor[0], box[0]), box[2]), min(max(anchor[1], box[1]), box[3])
