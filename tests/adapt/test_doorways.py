"""Doorway approach zones: furniture may narrow a doorway's approach but not park across it."""

from __future__ import annotations

import pytest

from adaptenv.adapt.doorways import MAX_APPROACH_COVER, approach_zones, covered_width
from adaptenv.adapt.edits import Edit, apply_edit
from adaptenv.adapt.realism import realism
from adaptenv.adapt.validation import EditValidator, validate_scene
from adaptenv.scene.geometry import SceneGeometry
from tests.sim import helpers as H

DRESSER, CHAIR = "Dresser_209_1", "Chair_002_1"  # dresser 2.29 x 0.38 m, chair 0.48 x 0.54 m


def house():
    """Rooms 0..4 and 4..8 (x) by 0..4 (z), a 1.6 m door (z 1.2..2.8) on x = 4, a dresser on the south wall."""
    return H.make_house([(0.0, 0.0, 4.0, 4.0), (4.0, 0.0, 8.0, 4.0)], doors=[H.Door(0, 1, 2.0, 1.6)],
                        objects=[H.Obj(DRESSER, 1.5, 0.3), H.Obj(H.LOW_TARGET, 7.0, 1.0), H.Obj(CHAIR, 1.0, 3.4)],
                        agent=(0.5, 2.0, 0.0))


def kinds(problems):
    return {p.kind for p in problems}


def test_dresser_parked_across_a_doorway_is_rejected_but_the_way_stays_open():
    h = house()
    # Turned along the wall, 0.49 m from it: the agent still passes, but the door's approach is blocked.
    across = apply_edit(h, Edit(object_id="Dresser|0", achieved_dx=1.82, achieved_dz=1.7, yaw_after=90.0))
    problems = validate_scene(across, original=h)
    assert kinds(problems) == {"doorway_approach"}, [str(p) for p in problems]
    assert "1.60 of the 1.60 m" in str(problems[0])
    geom = SceneGeometry.from_house(across)
    zone = approach_zones(geom)[0]
    assert covered_width(zone, [f.polygon for f in geom.floor_objects]) == pytest.approx(1.6, abs=1e-6)
    assert realism(across).door_zones == 0.0 < realism(h).door_zones == 1.0


def test_narrowing_a_doorway_approach_is_allowed():
    h = house()
    beside = apply_edit(h, Edit(object_id="Chair|2", achieved_dx=2.6, achieved_dz=-2.4))  # chair at (3.6, 1.0)
    geom = SceneGeometry.from_house(beside)
    cover = covered_width(approach_zones(geom)[0], [f.polygon for f in geom.floor_objects])
    assert 0.0 < cover < MAX_APPROACH_COVER * 1.6
    assert validate_scene(beside, original=h) == []
    assert 0.0 < realism(beside).door_zones < 1.0


def test_edit_validator_rejects_parking_across_a_doorway():
    h = house()
    # The dresser already stands along the door wall, 0.82 m from it (x 2.81..3.19), clear of the zone.
    near = apply_edit(h, Edit(object_id="Dresser|0", achieved_dx=1.5, achieved_dz=1.7, yaw_after=90.0))
    # 8 m house: 100 units = 8 m, so 2 units = 0.16 m and 4 units = 0.32 m toward the door.
    v = EditValidator(near, original=h, plausibility=False)  # the physical rule alone
    assert v.try_edit("Dresser|0", 2.0, 0.0).accepted  # face at 3.35 m: outside the 0.5 m zone
    v = EditValidator(near, original=h, plausibility=False)
    edit = v.try_edit("Dresser|0", 4.0, 0.0)  # face at 3.51 m: across the zone, the way still open
    assert not edit.accepted
    assert edit.problems == ["Dresser|0 would cover 1.60 of the 1.60 m in front of doorway door|0|1|0"]


def test_edit_validator_counts_an_object_moved_into_the_approach_earlier():
    """Two chairs beside the doorway cover more than half of it together; the first one's committed move counts."""
    h = H.make_house([(0.0, 0.0, 4.0, 4.0), (4.0, 0.0, 8.0, 4.0)], doors=[H.Door(0, 1, 2.0, 1.6)],
                     objects=[H.Obj(DRESSER, 1.5, 0.3), H.Obj(H.LOW_TARGET, 7.0, 1.0), H.Obj(CHAIR, 1.0, 3.4),
                              H.Obj(CHAIR, 2.5, 3.4)], agent=(0.5, 2.0, 0.0))
    v = EditValidator(h, plausibility=False)  # the physical rule alone (plausibility keeps a 1 m clearance)
    assert v.propose("Chair|3", 13.75, -11.25).valid  # to (3.6, 2.5): the door's upper third, alone below the limit
    first = v.try_edit("Chair|2", 32.5, -25.0)  # to (3.6, 1.4): the door's lower third, alone below the limit
    assert first.accepted and first.stop_reason == "reached"
    second = v.propose("Chair|3", 13.75, -11.25)
    assert second.result.stop_reason == "reached"
    assert kinds(second.problems) == {"doorway_approach"}
    assert second.problems[0].object_ids == ("door|0|1|0", "Chair|2", "Chair|3")
    both = apply_edit(v.house, Edit(object_id="Chair|3", achieved_dx=1.1, achieved_dz=-0.9))
    assert kinds(validate_scene(both, original=h)) == {"doorway_approach"}
