"""The validation module: validate_scene's rules, the incremental raster, and the edit validator's guarantees."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from adaptenv.adapt.edits import Edit, apply_edit
from adaptenv.adapt.generators._trial import edited_copy
from adaptenv.adapt.validation import (
    EditValidator,
    NavRaster,
    StaleProposalError,
    check_edit,
    reference_target_problems,
    validate_scene,
)
from adaptenv.scene.geometry import SceneGeometry
from adaptenv.scene.house import load_house
from adaptenv.scene.occupancy import rasterize
from adaptenv.sim.geodesic import geodesic_distance
from adaptenv.sim.world import compile_world
from tests.conftest import REAL_HOUSE
from tests.sim import helpers as H

BED, CHAIR = "Bed_1", "Chair_002_1"


def door_house():
    """Rooms 0..4 and 4..8 (x) by 0..4 (z), a 1 m door at z = 2 on x = 4, a bed near the door, a can in room 1."""
    return H.make_house([(0.0, 0.0, 4.0, 4.0), (4.0, 0.0, 8.0, 4.0)], doors=[H.Door(0, 1, 2.0, 1.0)],
                        objects=[H.Obj(BED, 1.8, 1.9), H.Obj(H.LOW_TARGET, 7.0, 1.0), H.Obj(CHAIR, 0.6, 0.6)],
                        agent=(0.5, 3.5, 0.0))


def kinds(problems) -> set[str]:
    return {p.kind for p in problems}


def test_untouched_houses_are_valid(real_house):
    assert validate_scene(real_house) == []
    assert validate_scene(real_house, original=real_house) == []
    assert validate_scene(door_house()) == []


def test_moving_into_a_doorway_that_disconnects_rooms_is_rejected():
    house = door_house()
    # 8 m house: 100 units = 8 m; 18.125 units = 1.45 m puts the bed flush against the door wall.
    out, edit = check_edit(house, "Bed|0", 18.125, 0.0)
    assert edit.stop_reason == "reached"  # placement allows it: blocking a door is not a collision
    assert not edit.accepted and any("room|1" in p for p in edit.problems)
    assert out.object_by_id("Bed|0").position.x == pytest.approx(1.8)  # the scene was left unchanged
    moved = apply_edit(house, Edit(object_id="Bed|0", achieved_dx=1.45))
    assert {"room_unreachable", "doorway_blocked", "target_unreachable"} <= kinds(validate_scene(moved, original=house))


def test_a_relocation_to_another_room_is_validated_logged_and_replayable():
    house = H.make_house([(0.0, 0.0, 6.0, 4.0), (6.0, 0.0, 9.0, 4.0)], doors=[H.Door(0, 1, 2.0, 1.0)],
                         objects=[H.Obj("Chair_002_1", 1.0, 1.5), H.Obj("Bed_1", 3.5, 2.0)], agent=(0.5, 3.5, 0.0))
    units = 100.0 / 9.0  # the grid's 100 units span the 9 m house
    v = EditValidator(house, start=(0.5, 3.5))
    # into a corner of the other room: a chair set down alone in the middle of a room is unlike the reference
    edit = v.try_edit("Chair|0", 7.72 * units, -1.23 * units, relocate=True, source="test")
    assert edit.accepted and edit.relocate and edit.achieved_dx == pytest.approx(7.72)
    assert validate_scene(v.house, original=house) == []
    assert apply_edit(house, edit).model_dump() == v.house.model_dump()
    assert Edit.model_validate_json(edit.model_dump_json()).relocate


def test_validate_scene_reports_new_overlaps_walls_and_start():
    house = door_house()
    onto_bed = apply_edit(house, Edit(object_id="Chair|2", achieved_dx=1.0, achieved_dz=1.0))
    assert "overlap" in kinds(validate_scene(onto_bed, original=house))
    through_wall = apply_edit(house, Edit(object_id="Chair|2", achieved_dx=-0.5))
    assert "outside_room" in kinds(validate_scene(through_wall, original=house))
    blocked = house.model_copy(deep=True)
    blocked.set_agent_pose(1.8, 1.9, 0.0)  # inside the bed
    assert kinds(validate_scene(blocked)) == {"start_blocked"}


def test_preexisting_overlaps_are_allowed_but_may_not_grow(real_house):
    assert validate_scene(real_house, original=real_house) == []
    chair = real_house.object_by_id("Chair|3|0|1")
    table = real_house.object_by_id("DiningTable|3|0|0")
    d = np.array([table.position.x - chair.position.x, table.position.z - chair.position.z])
    deeper = apply_edit(real_house, Edit(object_id="Chair|3|0|1", achieved_dx=d[0] * 0.5, achieved_dz=d[1] * 0.5))
    assert "overlap_grew" in kinds(validate_scene(deeper, original=real_house))


def test_nav_raster_matches_the_full_raster_after_edits(real_house):
    v = EditValidator(real_house)
    rng = np.random.default_rng(5)
    ids = [oid for oid, m in zip(v.ctx.ids, v.ctx.movable, strict=True) if m]
    for _ in range(20):
        v.try_edit(ids[int(rng.integers(len(ids)))], *rng.uniform(-25, 25, 2), float(rng.uniform(0, 360)))
    full = rasterize(SceneGeometry.from_house(v.house)).navigable(0.2)
    assert np.array_equal(v.raster.navigable(), full)
    assert np.array_equal(NavRaster(SceneGeometry.from_house(v.house)).navigable(), full)


@cache
def _houses():
    from adaptenv.scene.procedural import GenerationConfig, generate_house

    return (load_house(REAL_HOUSE, validate=False), generate_house(1, GenerationConfig(n_rooms=5)), door_house())


edit_st = st.tuples(st.integers(0, 10_000), st.floats(-30, 30), st.floats(-30, 30),
                    st.one_of(st.none(), st.floats(0, 360, exclude_max=True)))


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(which=st.integers(0, 2), edits=st.lists(edit_st, min_size=1, max_size=8))
def test_random_edit_sequences_never_yield_an_invalid_scene(which, edits):
    house = _houses()[which]
    v = EditValidator(house)
    ids = [oid for oid, m in zip(v.ctx.ids, v.ctx.movable, strict=True) if m]
    for k, dx, dy, yaw in edits:
        v.try_edit(ids[k % len(ids)], dx, dy, yaw, source="hypothesis")
    assert validate_scene(v.house, original=house) == []
    # The expert-level solvability check: every target type reachable before still is.
    world = compile_world(v.house)
    x, z, _ = house.agent_pose()
    for t in v.need_targets:
        assert math.isfinite(geodesic_distance(world, t, x, z)), t


def test_episode_targets_are_kept_reachable():
    house = door_house()
    v = EditValidator(house, episode_targets=["GarbageCan"])
    assert v.need_targets == {"GarbageCan"}
    edit = v.try_edit("Bed|0", 18.125, 0.0)
    assert not edit.accepted and any("GarbageCan" in p or "room|1" in p for p in edit.problems)


# --------------------------------------------------------------------------- propose / commit / try_edit

@cache
def _generated_houses():
    from adaptenv.scene.procedural import GenerationConfig, generate_house

    return tuple(generate_house(seed, GenerationConfig(n_rooms=4)) for seed in range(3))


def _request(v: EditValidator, edit: tuple) -> tuple[str, float, float, float | None]:
    """A random move, or a move of the object onto a doorway (the edits that get rejected)."""
    k, onto_door, door, dx, dy, frac, yaw = edit
    ids = [oid for oid, m in zip(v.ctx.ids, v.ctx.movable, strict=True) if m]
    oid = ids[k % len(ids)]
    if onto_door:
        doors = [d for d in v.geometry.doors if d.passable]
        d = doors[door % len(doors)]
        to = (np.add(d.p0, d.p1) / 2 - v.ctx.centers[v.ctx.index[oid]]) * frac * v.ctx.grid.units_per_meter
        dx, dy = float(to[0]), float(to[1])
    return oid, dx, dy, yaw


def _found(problems) -> list[tuple[str, tuple[str, ...]]]:
    return sorted((p.kind, p.object_ids) for p in problems)


# Three in four proposals move an object onto a doorway, so that rejections are common.
proposal_st = st.tuples(st.integers(0, 10_000), st.integers(0, 3).map(bool), st.integers(0, 100), st.floats(-30, 30),
                        st.floats(-30, 30), st.floats(0.8, 1.1), st.one_of(st.none(), st.floats(0, 355)))


@settings(max_examples=8, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(which=st.integers(0, 2), edits=st.lists(proposal_st, min_size=1, max_size=3))
def test_propose_commit_equals_try_edit_equals_validate_scene(which, edits):
    house = _generated_houses()[which]
    # validate_scene is physical validity and feasibility; the plausibility rules are the validator's own
    staged, direct = EditValidator(house, plausibility=False), EditValidator(house, plausibility=False)
    for edit in edits:
        oid, dx, dy, yaw = _request(staged, edit)
        before = staged.house.model_copy(deep=True)
        proposal = staged.propose(oid, dx, dy, yaw)
        assert staged.house == before and len(staged.log) == len(direct.log)  # a dry run keeps nothing
        res = proposal.result
        if res.stop_reason == "invalid":
            assert _found(proposal.problems) == [("invalid", (oid,))]
        else:
            edited = edited_copy(before, res)
            assert _found(proposal.problems) == _found(validate_scene(edited, original=house))
        committed = staged.commit(proposal, source="test")
        tried = direct.try_edit(oid, dx, dy, yaw, source="test")
        assert committed == tried
        assert committed.accepted == proposal.valid
        assert staged.house == direct.house
        assert staged.house == (edited if proposal.valid and res.changed else before)


def test_a_proposal_is_refused_after_another_commit_or_by_another_validator():
    house = door_house()
    v = EditValidator(house)
    first, second = v.propose("Chair|2", 5.0, 0.0), v.propose("Chair|2", 0.0, 5.0)
    assert first.valid and second.valid
    with pytest.raises(StaleProposalError, match="another EditValidator"):
        EditValidator(house).commit(first)
    assert v.commit(first).accepted
    with pytest.raises(StaleProposalError, match="propose again"):
        v.commit(second)
    assert v.commit(v.propose("Chair|2", 0.0, 5.0)).accepted


def test_a_rejected_proposal_commits_as_a_logged_rejection():
    v = EditValidator(door_house())
    proposal = v.propose("Bed|0", 18.125, 0.0)
    assert not proposal.valid and proposal.result.stop_reason == "reached"
    edit = v.commit(proposal)
    assert not edit.accepted and list(v.log) == [edit]
    assert v.house == door_house()


def _differential_requests(v: EditValidator, rng: np.random.Generator) -> tuple[str, float, float, float | None]:
    """A random edit: a target-type object moved (half the time), often onto a doorway."""
    movable = [ty for ty, m in zip(v.ctx.types, v.ctx.movable, strict=True) if m]
    targets = [k for k, ty in enumerate(movable) if ty in v.need_targets]
    k = int(rng.integers(10_000))
    if targets and rng.random() < 0.5:
        k = targets[k % len(targets)]
    yaw = None if rng.random() < 0.5 else float(rng.uniform(0, 355))
    edit = (k, bool(rng.random() < 0.6), int(rng.integers(100)), *rng.uniform(-30, 30, 2), rng.uniform(0.8, 1.1), yaw)
    return _request(v, edit)


@pytest.mark.parametrize("which", [0, 1, 2])
def test_fast_target_check_equals_the_compiled_world_check(which):
    """Differential: propose's target verdicts (cached regions, then the early-exit kernel on the
    incremental label grids) equal compiling the candidate world, for every needed type."""
    house = _generated_houses()[which]
    v = EditValidator(house)
    rng = np.random.default_rng(100 + which)
    moved_target = decided = rejected = 0
    for _ in range(30):
        proposal = v.propose(*_differential_requests(v, rng))
        if proposal.result.changed:
            fast = [p for p in proposal.problems if p.kind == "target_unreachable"]
            assert _found(fast) == _found(reference_target_problems(v, proposal))
            moved_target += v.ctx.types[v.ctx.index[proposal.object_id]] in v.need_targets
            decided += bool(proposal.exact_targets)
            rejected += bool(fast)
        v.commit(proposal, source="test")
    world = compile_world(v.house)  # the incremental label and occluder grids are the compiled world's
    assert np.array_equal(v.labels.label, world.grid.label) and np.array_equal(v.labels.occluder, world.occluder)
    assert moved_target >= 5 and decided >= 3 and rejected >= 1  # the exact path ran, moved targets, rejected
