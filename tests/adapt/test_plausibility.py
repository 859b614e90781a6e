"""The plausibility audit: each rule on a small hand-built house, the validator refusing what it finds, the CLI."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from typer.testing import CliRunner

from adaptenv.adapt.edits import Edit, apply_edit
from adaptenv.adapt.plausibility import RULES, audit, group_pairs
from adaptenv.adapt.step import verdict
from adaptenv.adapt.validation import EditValidator
from adaptenv.cli import app
from adaptenv.scene.house import save_house
from tests.sim import helpers as H

# Room 0 (6 x 5 m) holds the furniture; a 1 m doorway at z = 2.5 in the wall x = 6 leads to room 1.
OBJECTS = [
    H.Obj("Bed_1", 1.0, 1.05, 0.0),                  # Bed|0: back against the wall z = 0
    H.Obj("TV_Stand_201_1", 3.5, 0.34, 0.0),         # TVStand|1: against the wall z = 0
    H.Obj("RoboTHOR_sofa_alrid", 3.5, 2.6, 180.0),   # Sofa|2: in the room, facing the stand
    H.Obj("ArmChair_213_1", 1.0, 4.62, 180.0),       # ArmChair|3: against the wall z = 5
    H.Obj("Floor_Lamp_1", 1.85, 4.74, 0.0),          # FloorLamp|4: beside the armchair (lamp-armchair)
    H.Obj("Plunger_1", 5.85, 4.85, 0.0),             # Plunger|5: in the corner
]


@pytest.fixture(scope="module")
def home():
    return H.make_house([(0.0, 0.0, 6.0, 5.0), (6.0, 0.0, 9.0, 5.0)], doors=[H.Door(0, 1, 2.5)], objects=OBJECTS,
                        agent=(7.5, 2.5, 0.0))


def _moved(house, object_id: str, x: float, z: float, yaw: float | None = None):
    obj = house.object_by_id(object_id)
    return apply_edit(house, Edit(object_id=object_id, achieved_dx=x - obj.position.x,
                                  achieved_dz=z - obj.position.z, yaw_before=obj.yaw,
                                  yaw_after=obj.yaw if yaw is None else yaw))


def _rules(original, adapted) -> set[str]:
    """The hand-written rules broken (the learned ``unlike_reference`` is tested in test_placement_model.py)."""
    return {v.rule for v in audit(original, adapted).violations} - {"unlike_reference"}


def test_the_untouched_home_and_a_slide_along_the_wall_break_nothing(home, real_house):
    assert audit(home, home).total == 0 and audit(real_house, real_house).total == 0
    assert audit(home, _moved(home, "Bed|0", 1.3, 1.05)).total == 0  # 0.3 m along its wall
    assert ("ArmChair", "FloorLamp", "lamp-armchair") in group_pairs()


def test_bed_off_its_wall_or_facing_it(home):
    assert _rules(home, _moved(home, "Bed|0", 2.0, 2.8)) == {"edge_off_wall"}
    assert _rules(home, _moved(home, "Bed|0", 1.0, 1.05, yaw=180.0)) == {"edge_off_wall"}


def test_bed_across_the_doorway_approach(home):
    # the case: a bed 0.67 m in front of the only doorway, across most of its width
    assert "door_approach" in _rules(home, _moved(home, "Bed|0", 6.0 - 0.67 - 1.04, 2.5, yaw=90.0))


def test_lamp_left_behind_by_its_armchair(home):
    report = audit(home, _moved(home, "FloorLamp|4", 4.5, 4.74))
    assert [(v.rule, v.others) for v in report.violations] == [("group_split", ("ArmChair|3",))]
    assert report.counts() == {**dict.fromkeys(RULES, 0), "group_split": 1}


def test_plunger_on_open_floor_and_in_front_of_the_door(home):
    assert _rules(home, _moved(home, "Plunger|5", 3.0, 4.0)) == {"open_floor"}
    assert "door_approach" in _rules(home, _moved(home, "Plunger|5", 5.5, 2.5))


def test_sofa_turned_away_from_the_television(home):
    assert _rules(home, _moved(home, "Sofa|2", 3.5, 2.6, yaw=90.0)) == {"facing_broken"}


def test_validator_refuses_with_the_rule_name_and_keeps_targets(home):
    v = EditValidator(home, episode_targets=["Sofa"], start=(7.5, 2.5))
    bed = v.propose("Bed|0", 0.0, 15.0)
    assert bed.result.changed and not bed.valid
    assert any(p.kind == "implausible" and p.message.startswith("implausible (edge_off_wall)") for p in bed.problems)
    assert [p.kind for p in v.propose("Sofa|2", 3.0, 0.0).problems] == ["target_moved"]
    assert v.propose("Bed|0", 3.0, 0.0).valid  # along its wall
    free = EditValidator(home, episode_targets=["Sofa"], start=(7.5, 2.5), plausibility=False, move_targets=True)
    assert free.propose("Bed|0", 0.0, 15.0).valid and free.propose("Sofa|2", 3.0, 0.0).valid


def test_audit_command(home, tmp_path):
    runner = CliRunner()
    a, b = save_house(home, tmp_path / "a.json"), save_house(_moved(home, "Plunger|5", 3.0, 4.0), tmp_path / "b.json")
    bad = runner.invoke(app, ["audit", str(a), str(b)])
    assert bad.exit_code == 1 and "open_floor: Plunger|5" in bad.output
    assert "unlike_reference: Plunger|5 (Plunger) isolation 0.85 m, above the reference's central 98%" in bad.output
    assert "1 moved object(s), 2 violation(s)" in bad.output
    ok = runner.invoke(app, ["audit", str(a), str(a)])
    assert ok.exit_code == 0 and "0 violation(s)" in ok.output


@pytest.mark.parametrize(("before", "after", "expected"), [
    ((True, 0.9), (True, 0.8), "harder"), ((True, 0.8), (True, 0.9), "easier"), ((True, 0.8), (True, 0.8), "unchanged"),
    ((True, 0.5), (False, 0.0), "harder"), ((False, 0.0), (True, 0.4), "easier")])
def test_verdict_follows_success_then_spl(before, after, expected):
    assert verdict({"success": before[0], "spl": before[1]}, {"success": after[0], "spl": after[1]}) == expected


def test_random_perturbation_of_the_real_house_breaks_rules(real_house):
    from adaptenv.adapt.generators.random_perturbation import random_single_edits

    house, _ = random_single_edits(real_house, 12, np.random.default_rng(0), max_units=40.0)
    assert audit(real_house, house).total > 0


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("name", ["builtin", "failure-modes"])
def test_offline_generators_pass_the_audit(name, seed):
    from adaptenv.adapt.generators import GenerationContext, make_generator
    from tests.adapt.scenes import procedural_scene

    house, world, ep, traj, analysis = procedural_scene(seed, 4, [seed, 7])
    res = make_generator(name).generate(house, analysis, steps=2, rng=np.random.default_rng(seed),
                                        context=GenerationContext(episode=ep, trajectory=traj, render=False))
    report = audit(house, res.house)
    assert report.total == 0, [str(v) for v in report.violations]
    targets = {t.object_id for t in world.instances_of(ep.target_type)}
    assert not targets & set(report.moved), "targets move only with an opt-in edit kind"


def test_llm_proposal_refused_by_a_rule_is_re_asked_with_its_name(llm_scene):
    from adaptenv.adapt.generators import GenerationContext
    from adaptenv.adapt.generators.llm import LLMGenerator
    from tests.adapt.llm_mock import Mock, move, verify

    house, world, ep, traj, analysis = llm_scene
    mock = Mock(move(xu=0.0, yu=8.0), move(), verify(True))  # up into the doorway at (6, 3), then a plain move
    res = LLMGenerator(mock.backend()).generate(house, analysis, steps=1, rng=np.random.default_rng(0),
                                                context=GenerationContext(episode=ep, trajectory=traj, render_size=320))
    refused = res.edit_log.edits[0]
    assert not refused.accepted and refused.problems[0].startswith("implausible (door_approach)")
    assert "implausible (door_approach)" in mock.bodies[1]["messages"][-1]["content"]
    assert res.steps[0].status == "applied" and audit(house, res.house).total == 0


def test_adapt_verdict_line_says_what_decided():
    from adaptenv.cli.adapt import _verdict_text

    assert _verdict_text("easier", {"success": False}, {"success": True}) == "the scene got easier for the agent " \
        "(success rose)"
    assert _verdict_text("harder", {"success": True}, {"success": True}).endswith("(SPL at equal success fell)")
    assert _verdict_text("unchanged", {"success": True}, {"success": True}).startswith("unchanged")


def test_open_floor_and_wall_distance_agree_with_plain_distances(real_house):
    """The open-floor rule's cached wall distances and within-distance test give what plain distances give."""
    import shapely

    from adaptenv.adapt.plausibility import OPEN_FLOOR, PlausibilityReference, _on_open_floor
    from adaptenv.scene.geometry import SceneGeometry

    geometry = SceneGeometry.from_house(real_house)
    ref = PlausibilityReference.of(real_house, geometry=geometry)
    floor = geometry.floor_objects
    shifts = np.random.default_rng(0).uniform(-1.5, 1.5, (len(floor), 8, 2))
    outcomes = set()
    for _ in range(2):  # the second pass reads every wall distance from the cache
        for f, moves in zip(floor, shifts, strict=True):
            for dx, dz in moves:
                fp = replace(f, center=(f.center[0] + dx, f.center[1] + dz))
                wall = float(shapely.distance(fp.polygon, ref.walls.union))
                assert ref.walls.distance(fp) == wall
                others = [o.polygon for o in floor if o.object_id != fp.object_id]
                plain = wall > OPEN_FLOOR and float(np.min(shapely.distance(fp.polygon, others))) > OPEN_FLOOR
                assert _on_open_floor(fp, ref.walls, floor) == plain
                outcomes.add(plain)
    assert outcomes == {True, False}, "both answers are exercised"


def _plain_overhang(walls, fp) -> float:
    """The wall overhang from its definition, with shapely distances and plain loops (the kernel's reference)."""
    import math

    import shapely

    from adaptenv.scene.graph import AGAINST_WALL_ANGLE, AGAINST_WALL_DISTANCE, MIN_WALL_OVERLAP

    worst, a = 0.0, fp.outline
    for e in range(len(a)):
        p, q = a[e], a[(e + 1) % len(a)]
        le = float(np.hypot(*(q - p)))
        if le < 1e-6:
            continue
        u = (q - p) / le
        edge = shapely.LineString([p, q])
        spans = []
        for k in range(len(walls.p0)):
            w = walls.units[k]
            if abs(w[0] * u[1] - w[1] * u[0]) > math.sin(math.radians(AGAINST_WALL_ANGLE)):
                continue
            if shapely.distance(edge, walls.lines[k]) > AGAINST_WALL_DISTANCE:
                continue
            t0, t1 = float((walls.p0[k] - p) @ u), float((walls.p1[k] - p) @ u)
            spans.append((min(max(min(t0, t1), 0.0), le), min(max(max(t0, t1), 0.0), le)))
        covered, end = 0.0, 0.0
        for lo, hi in sorted(spans):
            if hi > end:
                covered, end = covered + hi - max(lo, end), hi
        if spans and covered >= MIN_WALL_OVERLAP:
            worst = max(worst, le - covered)
    return worst


def test_wall_overhang_kernel_matches_its_definition(real_house):
    """The compiled overhang gives what shapely distances and plain loops give, for objects slid along, onto and off
    their walls and turned (nonzero overhangs included)."""
    from adaptenv.adapt.plausibility import PlausibilityReference
    from adaptenv.scene.geometry import SceneGeometry

    geometry = SceneGeometry.from_house(real_house)
    walls = PlausibilityReference.of(real_house, geometry=geometry).walls
    rng = np.random.default_rng(1)
    values = []
    for f in geometry.floor_objects:
        for dx, dz, turn in zip(*rng.uniform(-1.0, 1.0, (2, 12)), rng.choice([0.0, 0.0, 90.0, 7.0], 12), strict=True):
            fp = replace(f, center=(f.center[0] + dx, f.center[1] + dz), yaw=(f.yaw + turn) % 360.0)
            values.append((walls.overhang(fp), _plain_overhang(walls, fp)))
    got, want = np.array(values).T
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    assert (want > 0.1).sum() >= 10 and (want == 0).sum() >= 10, "both outcomes are exercised"


def test_wall_overhang_leaves_distances_at_the_limit_to_geos():
    """An edge exactly AGAINST_WALL_DISTANCE from a wall is marked a tie for shapely to decide, not rounded."""
    from adaptenv.adapt.plausibility import _TIE, _edges_along
    from adaptenv.scene.graph import AGAINST_WALL_DISTANCE

    square = np.array([[0.0, 0.25], [1.0, 0.25], [1.0, 1.0], [0.0, 1.0]])
    p0, p1 = np.array([[-1.0, 0.25 - AGAINST_WALL_DISTANCE], [-1.0, 0.5]]), np.array([[2.0, 0.25 - AGAINST_WALL_DISTANCE], [-1.0, 3.0]])
    units = (p1 - p0) / np.linalg.norm(p1 - p0, axis=1)[:, None]
    near = _edges_along(square, units, np.minimum(p0, p1), np.maximum(p0, p1), p0, p1, 0.5, AGAINST_WALL_DISTANCE)
    assert near[0, 0] == _TIE and near[0, 1] == 0 and near[1, 0] == 0  # the bottom edge; the wall x = -1 is too far


def test_boxes_apart_only_where_the_shapes_are_further_apart_than_the_gap():
    """The rules' bounding-box test skips shapely only where the footprints' distance exceeds the gap."""
    import shapely

    from adaptenv.adapt.plausibility import _apart
    from adaptenv.scene.geometry import Footprint

    rng = np.random.default_rng(0)
    skipped = 0
    for _ in range(2000):
        a, b = (Footprint("o", "Chair", "a", tuple(rng.uniform(0, 3, 2)), tuple(rng.uniform(0.1, 1.5, 2)),
                          float(rng.uniform(0, 360)), 1.0, "floor", True) for _ in range(2))
        gap = float(rng.choice([0.0, 0.3]))
        assert a.bounds == tuple(shapely.bounds(a.polygon))
        if _apart(a.bounds, b.bounds, gap):
            skipped += 1
            assert shapely.distance(a.polygon, b.polygon) > gap
    assert 200 < skipped < 1800, "both outcomes are exercised"


def _plain_against(walls, fp) -> bool:
    """The scene graph's ``against_wall`` from shapely distances and ``backs_onto``'s array form, as the rule defines
    it."""
    import math

    import shapely

    from adaptenv.scene.graph import AGAINST_WALL_ANGLE, AGAINST_WALL_DISTANCE, _backs_onto_arrays

    near = shapely.distance(shapely.linestrings(fp.corners[:2]), walls.lines) <= AGAINST_WALL_DISTANCE
    return any(_backs_onto_arrays(fp, walls.p0[k], walls.p1[k], math.cos(math.radians(AGAINST_WALL_ANGLE)))
               for k in np.flatnonzero(near))


def test_against_wall_test_matches_its_definition(real_house):
    """The compiled distances and float arithmetic of the edge_off_wall test give what shapely and ``backs_onto``
    give, for objects slid along, onto and off their walls and turned."""
    from adaptenv.adapt.plausibility import PlausibilityReference
    from adaptenv.scene.geometry import SceneGeometry

    geometry = SceneGeometry.from_house(real_house)
    walls = PlausibilityReference.of(real_house, geometry=geometry).walls
    rng = np.random.default_rng(2)
    got, want = [], []
    for f in geometry.floor_objects:
        for dx, dz, turn in zip(*rng.uniform(-0.3, 0.3, (2, 12)), rng.choice([0.0, 0.0, 90.0, 180.0, 7.0], 12),
                                strict=True):
            fp = replace(f, center=(f.center[0] + dx, f.center[1] + dz), yaw=(f.yaw + turn) % 360.0)
            got.append(walls.against(fp))
            want.append(_plain_against(walls, fp))
    assert got == want
    assert 20 < sum(want) < len(want) - 20, "both outcomes are exercised"


def test_the_first_broken_rule_decides_as_the_full_check_does(real_house):
    """``breaks_rules`` (which stops at the first rule broken) is True exactly where ``check_move`` finds a
    violation, over random moves and turns of every floor object."""
    from adaptenv.adapt.plausibility import PlausibilityReference, breaks_rules, check_move
    from adaptenv.scene.geometry import SceneGeometry

    geometry = SceneGeometry.from_house(real_house)
    ref = PlausibilityReference.of(real_house, geometry=geometry)
    current = {f.object_id: f for f in geometry.floor_objects}
    rng = np.random.default_rng(3)
    found = []
    for f in geometry.floor_objects:
        for dx, dz, turn in zip(*rng.uniform(-0.5, 0.5, (2, 6)), rng.choice([0.0, 90.0, 33.0], 6), strict=True):
            fp = replace(f, center=(f.center[0] + dx, f.center[1] + dz), yaw=(f.yaw + turn) % 360.0)
            found.append(check_move(ref, fp, current))
            assert breaks_rules(ref, fp, current) == bool(found[-1])
    assert 20 < sum(map(bool, found)) < len(found) - 20, "both outcomes are exercised"
    assert len({v.rule for vs in found for v in vs}) >= 4, "several rules are exercised"


def test_facing_cosine_is_numpys_bit_for_bit():
    """The facing rule's cosine in Python floats equals numpy's norm-and-dot form exactly, and backs_onto's float
    form agrees with its array form, on random poses."""
    import math

    from adaptenv.adapt.plausibility import _faces
    from adaptenv.scene.geometry import Footprint, heading
    from adaptenv.scene.graph import _backs_onto_arrays, backs_onto

    rng = np.random.default_rng(4)
    for _ in range(3000):
        a, b = (Footprint("o", "Sofa", "a", tuple(rng.uniform(0, 5, 2)), tuple(rng.uniform(0.2, 2.0, 2)),
                          float(rng.choice([0.0, 90.0, rng.uniform(0, 360)])), 1.0, "floor", True) for _ in range(2))
        v = np.array(b.center) - np.array(a.center)
        assert _faces(a, b) == float(np.dot(heading(a.yaw), v / float(np.linalg.norm(v))))
        p0, p1 = rng.uniform(0, 5, (2, 2))
        cos = math.cos(math.radians(float(rng.choice([5.0, 30.0]))))
        assert backs_onto(a, p0, p1, cos) == _backs_onto_arrays(a, p0, p1, cos)
