"""The realism score: untouched homes score high; displaced, turned, scattered or door-blocking furniture lowers it."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from adaptenv.adapt.edits import Edit, apply_edit
from adaptenv.adapt.realism import RealismReference, realism
from adaptenv.scene.geometry import SceneGeometry


def _move_to(house, object_id: str, x: float, z: float, yaw: float | None = None):
    obj = house.object_by_id(object_id)
    after = obj.yaw if yaw is None else yaw
    return apply_edit(house, Edit(object_id=object_id, achieved_dx=x - obj.position.x, achieved_dz=z - obj.position.z,
                                  yaw_before=obj.yaw, yaw_after=after))


def test_untouched_houses_score_high(real_house):
    from adaptenv.scene.procedural import GenerationConfig, generate_house

    r = realism(real_house)
    assert r.total > 0.95 and r.door_zones == 1.0 and r.wall_anchored == 1.0
    assert 0.0 <= r.total <= 1.0
    assert realism(generate_house(0, GenerationConfig(n_rooms=5))).total > 0.8


def test_bed_in_the_middle_turned_37_degrees_scores_lower(real_house):
    base = realism(real_house, original=real_house)
    room = SceneGeometry.from_house(real_house).rooms["room|8"]
    c = room.centroid
    moved = _move_to(real_house, "Bed|8|0", c.x, c.y, yaw=37.0)
    r = realism(moved, original=real_house)
    assert r.total < base.total
    assert r.wall_anchored < base.wall_anchored and r.angles < base.angles
    assert "Bed|8|0" in r.offenders["wall_anchored"] and "Bed|8|0" in r.offenders["angles"]


def test_chair_away_from_its_table_lowers_the_group_term(real_house):
    base = realism(real_house, original=real_house)
    chair = real_house.object_by_id("Chair|3|0|1")
    table = real_house.object_by_id("DiningTable|3|0|0")
    away = np.array([chair.position.x - table.position.x, chair.position.z - table.position.z])
    away = away / np.linalg.norm(away) * 1.5
    moved = _move_to(real_house, "Chair|3|0|1", chair.position.x + away[0], chair.position.z + away[1])
    r = realism(moved, original=real_house)
    assert r.groups < base.groups and "Chair|3|0|1" in r.offenders["groups"]


def test_blocking_a_door_zone_lowers_the_score(real_house):
    geometry = SceneGeometry.from_house(real_house)
    door = next(d for d in geometry.doors if d.id == "door|6|7")
    mx, mz = door.midpoint
    # Put the bedroom's dresser right in front of the doorway, on the side of room 6.
    room6 = geometry.rooms["room|6"]
    p = np.array(door.p1) - np.array(door.p0)
    n = np.array([-p[1], p[0]]) / np.linalg.norm(p)
    if not room6.covers(shapely.Point(mx + 0.4 * n[0], mz + 0.4 * n[1])):
        n = -n
    dresser = next(f for f in geometry.floor_objects if f.object_type == "Dresser")
    moved = _move_to(real_house, dresser.object_id, mx + 0.35 * n[0], mz + 0.35 * n[1])
    r = realism(moved)
    assert r.door_zones < 1.0 and "door|6|7" in r.offenders["door_zones"]
    assert r.total < realism(real_house).total


@pytest.mark.parametrize("seed", [0, 1])
def test_terms_are_in_unit_interval(seed, real_house):
    rng = np.random.default_rng(seed)
    house = real_house
    for f in SceneGeometry.from_house(real_house).movable_objects[:10]:
        house = _move_to(house, f.object_id, f.center[0] + rng.uniform(-1, 1), f.center[1] + rng.uniform(-1, 1),
                         float(rng.uniform(0, 360)))
    r = realism(house, original=real_house)
    assert all(v is None or 0.0 <= v <= 1.0 for v in r.terms().values()) and 0.0 <= r.total <= 1.0
    assert r.total < realism(real_house, original=real_house).total


def test_a_reference_built_once_scores_edits_as_the_original_house_does(real_house):
    chair = real_house.object_by_id("Chair|3|0|1")
    edited = [_move_to(real_house, "Chair|3|0|1", chair.position.x + 1.5, chair.position.z),
              _move_to(real_house, "Bed|8|0", *SceneGeometry.from_house(real_house).rooms["room|8"].centroid.coords[0],
                       yaw=37.0)]
    reference = RealismReference.of(real_house)
    assert "Bed|8|0" in reference.anchored and any(m == "Chair|3|0|1" for m, _, _ in reference.groups)
    for house in edited:
        assert realism(house, original=reference) == realism(house, original=real_house)
    assert realism(edited[1], original=reference).total < realism(real_house, original=reference).total
