"""The agent-pose stage and the guarantees every generated house must meet (a pure check).

Both use the shared navigable-space definition, :func:`adaptenv.scene.occupancy.rasterize`: a
disc of the agent's radius fits at a cell when the cell's clearance is at least that radius, and
reachable means 4-connected through such cells.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from adaptenv.scene.assets import AssetCatalog
from adaptenv.scene.geometry import Footprint, SceneGeometry, yaw_axes
from adaptenv.scene.house import House, is_shut
from adaptenv.scene.occupancy import OccupancyGrid, rasterize
from adaptenv.scene.procedural.config import GenerationConfig, StageFailed
from adaptenv.scene.validate import validate_house
from adaptenv.vocabulary import TARGET_TYPES

#: Agent start positions lie on this lattice (m), as in ProcTHOR.
POSE_GRID = 0.25
#: Footprints may overlap by at most this area (m^2) before it counts as an overlap.
OVERLAP_AREA = 1e-6
#: How far (m) a footprint may stick out of its room (rounding of written coordinates).
ROOM_TOLERANCE = 1e-3


@dataclass
class Navigation:
    """A house's occupancy grid and its navigable components for one agent radius."""

    geometry: SceneGeometry
    grid: OccupancyGrid
    labels: np.ndarray
    """int (H, W): component of each navigable cell, 0 where the agent does not fit."""

    @classmethod
    def of(cls, house: House, catalog: AssetCatalog, radius: float) -> Navigation:
        geometry = SceneGeometry.from_house(house, catalog)
        grid = rasterize(geometry)
        labels, _ = grid.components(radius)
        return cls(geometry, grid, labels)

    def component_at(self, x: float, z: float) -> int:
        """Component label at a world point (0 when not navigable or outside)."""
        row, col = self.grid.to_cell(x, z)
        if not self.grid.in_bounds(row, col):
            return 0
        return int(self.labels[row, col])

    def main_component(self) -> int:
        """The component touching the most rooms (ties: the largest); 0 when nothing is navigable."""
        best, key = 0, (0, 0)
        for c in np.unique(self.labels[self.labels > 0]):
            cells = self.labels == c
            k = (len(np.unique(self.grid.room[cells & (self.grid.room >= 0)])), int(cells.sum()))
            if k > key:
                best, key = int(c), k
        return best

    def near(self, fp: Footprint, component: int, reach: float) -> bool:
        """Whether a cell of ``component`` lies within ``reach`` of the footprint."""
        g = self.grid
        corners = fp.corners
        (r0, c0), (r1, c1) = (g.to_cell(corners[:, 0].min() - reach, corners[:, 1].min() - reach),
                              g.to_cell(corners[:, 0].max() + reach, corners[:, 1].max() + reach))
        h, w = g.shape
        r0, c0, r1, c1 = max(int(r0), 0), max(int(c0), 0), min(int(r1) + 1, h), min(int(c1) + 1, w)
        if r0 >= r1 or c0 >= c1:
            return False
        win = self.labels[r0:r1, c0:c1] == component
        if not win.any():
            return False
        xs, zs = g.cell_center(np.arange(r0, r1)[:, None], np.arange(c0, c1)[None, :])
        ux, uz = yaw_axes(fp.yaw)
        dx, dz = xs - fp.center[0], zs - fp.center[1]
        lx = np.abs(dx * ux[0] + dz * ux[1]) - fp.size[0] / 2
        lz = np.abs(dx * uz[0] + dz * uz[1]) - fp.size[1] / 2
        dist = np.hypot(np.maximum(lx, 0), np.maximum(lz, 0))
        return bool((win & (dist <= reach)).any())


def stage_agent_pose(house: House, *, rng: np.random.Generator, catalog: AssetCatalog, cfg: GenerationConfig) -> None:
    """Start pose: an open spot on the 0.25 m lattice in a random room, yaw in {0, 90, 180, 270}.

    The spot lies in the navigable component that reaches the most rooms, among the lattice points
    with at least 80% of the room's best clearance (ProcTHOR: the centre of the largest free area).
    """
    nav = Navigation.of(house, catalog, cfg.agent_radius)
    x, z = choose_start(rng, nav)
    house.set_agent_pose(x, z, float(rng.integers(4) * 90.0))


def choose_start(rng: np.random.Generator, nav: Navigation, keep: tuple[float, float] | None = None) -> tuple[float, float]:
    """A start position in the main component (``keep`` if it is still in it)."""
    main = nav.main_component()
    if main == 0:
        raise StageFailed("no navigable space for the agent")
    if keep is not None and nav.component_at(*keep) == main:
        return keep
    x0, z0, x1, z1 = nav.geometry.bounds
    xs = np.arange(np.ceil(x0 / POSE_GRID), np.floor(x1 / POSE_GRID) + 1) * POSE_GRID
    zs = np.arange(np.ceil(z0 / POSE_GRID), np.floor(z1 / POSE_GRID) + 1) * POSE_GRID
    px, pz = (a.ravel() for a in np.meshgrid(xs, zs))
    row, col = nav.grid.to_cell(px, pz)
    ok = nav.grid.in_bounds(row, col)
    px, pz, row, col = px[ok], pz[ok], row[ok], col[ok]
    on = nav.labels[row, col] == main
    px, pz, row, col = px[on], pz[on], row[on], col[on]
    if len(px) == 0:
        raise StageFailed("no start position on the 0.25 m lattice")
    rooms = nav.grid.room[row, col]
    choices = np.unique(rooms[rooms >= 0])
    room = int(choices[int(rng.integers(len(choices)))]) if len(choices) else -1
    pick = rooms == room
    clearance = nav.grid.clearance[row[pick], col[pick]]
    best = np.nonzero(clearance >= 0.8 * clearance.max())[0]
    i = int(best[int(rng.integers(len(best)))])
    return float(round(px[pick][i], 4)), float(round(pz[pick][i], 4))


def reachable_target_types(nav: Navigation, component: int, reach: float) -> set[str]:
    """Target types with an instance within ``reach`` of the component."""
    found = set()
    for fp in nav.geometry.floor_objects:
        if fp.object_type in TARGET_TYPES and fp.object_type not in found and nav.near(fp, component, reach):
            found.add(fp.object_type)
    return found


def house_problems(house: House, cfg: GenerationConfig, catalog: AssetCatalog,
                   required_targets: tuple[str, ...] = (),
                   allowed_overlaps: frozenset[frozenset[str]] = frozenset()) -> list[str]:
    """Every violated guarantee of a generated house (empty when it is fine).

    Checks: the start pose is navigable; every room is reachable from it (with closed interior doors opened: a
    shut door may close rooms off by design, ``GenerationConfig.closed_door_prob``); at least
    ``cfg.min_target_types`` target types (and all of ``required_targets``) have a reachable
    instance; no two floor footprints overlap; every floor footprint lies in a room;
    :func:`adaptenv.scene.validate.validate_house` finds nothing. ``allowed_overlaps`` lists id
    pairs that may overlap (chairs tucked under a table in a real house that was rearranged).
    """
    problems: list[str] = []
    nav = Navigation.of(house, catalog, cfg.agent_radius)
    pose = house.agent_pose()
    start = nav.component_at(pose[0], pose[1]) if pose else 0
    if start == 0:
        problems.append("the agent start pose is missing or not navigable")
    else:
        rooms = nav if not closed_interior_doors(house) else Navigation.of(opened(house), catalog, cfg.agent_radius)
        here = rooms.component_at(pose[0], pose[1])
        g = rooms.grid
        for k, rid in enumerate(g.room_ids):
            if not ((g.room == k) & (rooms.labels == here)).any():
                problems.append(f"{rid} is not reachable from the start")
        found = reachable_target_types(nav, start, cfg.target_reach)
        if len(found) < cfg.min_target_types:
            problems.append(f"only {len(found)} target types are reachable ({', '.join(sorted(found)) or 'none'}); "
                            f"need {cfg.min_target_types}")
        missing = sorted(set(required_targets) - found)
        if missing:
            problems.append(f"target types {', '.join(missing)} are no longer reachable")
    problems += footprint_problems(nav.geometry, allowed_overlaps)
    problems += [str(p) for p in validate_house(house, catalog=catalog)]
    return problems


def closed_interior_doors(house: House) -> list[str]:
    """Ids of the interior doors that are shut (openness 0)."""
    return [d.id for d in house.doors if d.room0 != d.room1 and is_shut(d)]


def opened(house: House) -> House:
    """A copy of ``house`` with every shut interior door opened."""
    shut = set(closed_interior_doors(house))
    return house.model_copy(update={"doors": [d.model_copy(update={"openness": 1}) if d.id in shut else d
                                              for d in house.doors]})


def overlapping_pairs(geometry: SceneGeometry) -> list[tuple[str, str, float]]:
    """Pairs of floor footprints (ids) that overlap by more than OVERLAP_AREA, with the area."""
    floor = geometry.floor_objects
    if len(floor) < 2:
        return []
    polys = np.array([f.polygon for f in floor])
    a, b = shapely.STRtree(polys).query(polys, predicate="intersects")
    keep = a < b
    a, b = a[keep], b[keep]
    areas = shapely.area(shapely.intersection(polys[a], polys[b]))
    return [(floor[i].object_id, floor[j].object_id, float(area))
            for i, j, area in zip(a, b, areas, strict=True) if area > OVERLAP_AREA]


def footprint_problems(geometry: SceneGeometry, allowed: frozenset[frozenset[str]] = frozenset()) -> list[str]:
    """Overlapping floor footprints (except ``allowed`` id pairs) and footprints outside every room."""
    out = [f"{i} and {j} overlap ({area:.4f} m^2)" for i, j, area in overlapping_pairs(geometry)
           if frozenset((i, j)) not in allowed]
    rooms = [p.buffer(ROOM_TOLERANCE, join_style="mitre") for p in geometry.rooms.values()]
    for f in geometry.floor_objects:
        if not any(r.covers(f.polygon) for r in rooms):
            out.append(f"{f.object_id} is not inside a single room")
    return out
