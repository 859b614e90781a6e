"""Scene geometry of the real house: merged walls, openings, footprints and blocking segments."""

from __future__ import annotations

import numpy as np
import pytest

from adaptenv.scene.geometry import SceneGeometry, wall_floor_segment


@pytest.fixture
def geometry(real_house) -> SceneGeometry:
    return SceneGeometry.from_house(real_house)


def _dist(p, a, b) -> float:
    """Distance from point p to segment ab."""
    p, a, b = (np.asarray(v, dtype=float) for v in (p, a, b))
    ab = b - a
    t = np.clip(np.dot(p - a, ab) / max(float(np.dot(ab, ab)), 1e-12), 0.0, 1.0)
    return float(np.linalg.norm(p - (a + t * ab)))


def _on_blocking(geometry: SceneGeometry, p) -> bool:
    return any(_dist(p, a, b) < 1e-6 for a, b in geometry.blocking_segments())


def test_walls_are_merged(real_house, geometry):
    ids = [wid for w in geometry.walls for wid in w.wall_ids]
    assert sorted(ids) == sorted(w.id for w in real_house.walls)  # every wall side in exactly one segment
    keys = {tuple(sorted((tuple(np.round(w.p0, 3)), tuple(np.round(w.p1, 3))))) for w in geometry.walls}
    assert len(keys) == len(geometry.walls)  # no physical wall listed twice
    for w in geometry.walls:
        exterior = [wid for wid in w.wall_ids if "exterior" in wid]
        # An interior wall has one side per room; a boundary wall one room side plus its exterior copy.
        assert (len(w.rooms), len(exterior)) in ((2, 0), (1, 1)), w.wall_ids
    assert sum(len(w.rooms) == 2 for w in geometry.walls) > 0


def test_two_empty_walls_are_passable(geometry):
    empty = [w for w in geometry.walls if w.empty]
    assert len(empty) == 2
    for w in empty:
        mid = (np.array(w.p0) + np.array(w.p1)) / 2
        assert not _on_blocking(geometry, mid)


def test_door_segments_lie_on_their_walls(real_house, geometry):
    walls = {w.id: w for w in real_house.walls}
    by_id = {d.id: d for d in real_house.doors}
    assert len(geometry.doors) == len(real_house.doors) == 8
    for seg in geometry.doors:
        a, b = wall_floor_segment(walls[by_id[seg.id].wall0])
        assert _dist(seg.p0, a, b) < 1e-9 and _dist(seg.p1, a, b) < 1e-9
        assert 0.8 < seg.width < 2.1


def test_exterior_door_is_not_passable(geometry):
    passable = {d.id: d.passable for d in geometry.doors}
    assert passable.pop("door|1|3") is False
    assert all(passable.values())
    assert not any(w.passable for w in geometry.windows)


def test_blocking_segments_exclude_door_holes(geometry):
    for d in geometry.doors:
        assert _on_blocking(geometry, d.midpoint) is (not d.passable), d.id
    # The wall next to a door hole still blocks.
    d = next(d for d in geometry.doors if d.passable)
    u = (np.array(d.p1) - np.array(d.p0)) / d.width
    assert _on_blocking(geometry, np.array(d.p1) + 0.05 * u)


def test_tvs_and_paintings_are_not_floor_obstacles(real_house, geometry):
    floor_types = {f.object_type for f in geometry.floor_objects}
    assert "Television" not in floor_types and "Painting" not in floor_types
    assert len(geometry.footprints) == len(real_house.objects) == 68
    assert len(geometry.floor_objects) == 49
    assert {f.object_type for f in geometry.footprints if f.role == "wall"} == {"Television", "Painting"}
    assert all(f.movable == (f.object_type not in ("CounterTop", "Sink", "Toilet")) for f in geometry.floor_objects)


def test_children_are_counted(real_house, geometry):
    assert sum(len(c) for c in geometry.children.values()) == sum(len(o.children) for o in real_house.objects) == 109
    assert all(f.role == "small" for c in geometry.children.values() for f in c)


def test_rooms_and_lookup(geometry):
    assert len(geometry.rooms) == 10
    assert geometry.room_of_point(12.5, 2.5) == "room|2"
    assert geometry.room_of_point(-1.0, -1.0) is None
    assert geometry.bounds == pytest.approx((0.0, 0.0, 15.781, 17.535))
