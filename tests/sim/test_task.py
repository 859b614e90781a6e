"""Success condition, visibility and episode sampling on small synthetic houses."""

from __future__ import annotations

import numpy as np
import pytest

from adaptenv.errors import AdaptenvError
from adaptenv.sim.geodesic import geodesic_distance
from adaptenv.sim.spec import AGENT_RADIUS
from adaptenv.sim.task import (
    Episode,
    available_targets,
    is_success,
    sample_episode,
    sample_points,
    trivial_targets,
    visible_instances,
)
from adaptenv.sim.world import compile_world
from tests.sim import helpers as H

# GarbageCan bin_1 at (4.5, 2.0), yaw 0: its left edge is x = 4.25; the nearest sample point is
# the inset edge midpoint (4.30, 2.0).
TX, TZ = 4.5, 2.0
LEFT_EDGE = TX - 0.5037 / 2


def room_with(*extra: H.Obj):
    return compile_world(H.one_room((7.0, 4.0), objects=[H.Obj(H.LOW_TARGET, TX, TZ), *extra]), "room")


def test_sample_points_cover_corners_edges_and_centre():
    corners = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]])
    pts = sample_points(corners, 0.05)
    assert [1.0, 0.5] in pts.tolist()  # centre
    assert [0.05, 0.05] in pts.tolist() and [1.95, 0.95] in pts.tolist()  # inset corners
    # Long edges are split every <= 0.5 m: 4 pieces along 1.9 m.
    assert np.sum(np.isclose(pts[:, 1], 0.05)) == 5
    assert pts[:, 0].min() == pytest.approx(0.05) and pts[:, 0].max() == pytest.approx(1.95)


@pytest.mark.parametrize(("gap", "expected"), [(1.9, True), (2.1, False)])
def test_success_distance_threshold(gap, expected):
    w = room_with()
    x = LEFT_EDGE - gap
    assert is_success(w, x, TZ, 90.0, "GarbageCan") is expected
    assert bool(visible_instances(w, x, TZ, 90.0, "GarbageCan")) is expected


def test_target_behind_wall_is_not_success():
    w = compile_world(H.target_behind_wall())
    assert not is_success(w, 3.5, 2.0, 90.0, "GarbageCan")
    # Same geometry with a door in the wall: now it is seen.
    open_w = compile_world(H.two_rooms(1.2, objects=[H.Obj(H.LOW_TARGET, 5.0, 2.0)]))
    assert is_success(open_w, 3.5, 2.0, 90.0, "GarbageCan")


@pytest.mark.parametrize(("yaw", "expected"), [(90.0, True), (120.0, True), (150.0, False), (270.0, False), (30.0, False)])
def test_field_of_view(yaw, expected):
    w = room_with()
    assert is_success(w, LEFT_EDGE - 1.5, TZ, yaw, "GarbageCan") is expected


def test_low_furniture_does_not_occlude_but_tall_does():
    x = LEFT_EDGE - 1.6
    low = room_with(H.Obj(H.LOW_FURNITURE, 3.55, TZ, 90.0))
    tall = room_with(H.Obj(H.TALL_FURNITURE, 3.55, TZ, 90.0))
    assert is_success(low, x, TZ, 90.0, "GarbageCan")
    assert not is_success(tall, x, TZ, 90.0, "GarbageCan")
    # The tall desk only hides what is behind it: from the side the can is visible again.
    assert is_success(tall, TX, TZ + 1.5, 180.0, "GarbageCan")


def test_visible_instances_returns_ids_and_respects_range():
    w = room_with(H.Obj(H.LOW_TARGET, 1.0, 1.0))
    ids = visible_instances(w, 3.0, 2.0, 90.0, "GarbageCan", max_distance=5.0, fov_deg=360.0)
    assert ids == ["GarbageCan|0", "GarbageCan|1"]
    assert visible_instances(w, 3.0, 2.0, 90.0, "GarbageCan", max_distance=5.0) == ["GarbageCan|0"]
    assert visible_instances(w, 3.0, 2.0, 90.0, "Chair") == []


def test_sample_episode_is_deterministic_and_valid(real_house):
    w = compile_world(real_house, "real")
    a = sample_episode(w, np.random.default_rng(7))
    b = sample_episode(w, np.random.default_rng(7))
    assert a == b
    seen = set()
    for seed in range(30):
        ep = sample_episode(w, seed)
        assert ep.seed == seed and ep.target_type in available_targets(w)
        x, z, yaw = ep.start
        assert yaw % 30 == 0
        assert w.grid.clearance_at(x, z) >= AGENT_RADIUS
        assert 0 < geodesic_distance(w, ep.target_type, x, z) < np.inf
        assert not is_success(w, x, z, yaw, ep.target_type)
        seen.add(ep.target_type)
    assert len(seen) > 2


def test_sample_episode_with_fixed_target_and_house_start():
    w = compile_world(H.corridor_house())
    ep = sample_episode(w, 0, target_type="GarbageCan", use_house_start=True)
    assert ep == Episode("GarbageCan", (1.0, 0.5, 0.0), 0)


def test_sample_episode_errors():
    sealed = compile_world(H.sealed_target_house(), "sealed")
    assert available_targets(sealed) == ["Fridge"]
    with pytest.raises(AdaptenvError, match="Fridge"):
        sample_episode(sealed, 0, target_type="Bed")
    with pytest.raises(AdaptenvError, match="not an ObjectNav target"):
        sample_episode(sealed, 0, target_type="Desk")
    empty = compile_world(H.one_room(), "empty")
    with pytest.raises(AdaptenvError, match="no ObjectNav target type is solvable"):
        sample_episode(empty, 0)


def _trivial_garbage_can_house():
    """A 2 x 3.6 m room: the garbage can in the middle is seen from every cell; the fridge at the end is not."""
    return H.one_room((2.0, 3.6), objects=[H.Obj(H.LOW_TARGET, 1.0, 1.8), H.Obj(H.TALL_TARGET, 1.0, 3.2, 180.0)])


def test_sampler_skips_a_target_seen_from_everywhere():
    w = compile_world(_trivial_garbage_can_house(), "trivial")
    assert trivial_targets(w) == ["GarbageCan"]
    assert available_targets(w) == ["Fridge"]
    assert {sample_episode(w, s).target_type for s in range(8)} == {"Fridge"}
    with pytest.raises(AdaptenvError, match="trivial for GarbageCan") as err:
        sample_episode(w, 0, target_type="GarbageCan")
    msg = str(err.value)
    assert "choose another target (Fridge)" in msg and "(GarbageCan" not in msg


def test_sampler_reports_a_house_trivial_for_its_only_target():
    w = compile_world(H.one_room((2.0, 3.6), objects=[H.Obj(H.LOW_TARGET, 1.0, 1.8)]), "one")
    assert available_targets(w) == [] and trivial_targets(w) == ["GarbageCan"]
    with pytest.raises(AdaptenvError, match="no episode exists") as err:
        sample_episode(w, 0)
    assert "cannot be reached" not in str(err.value)
    with pytest.raises(AdaptenvError, match="no other target type") as err:
        sample_episode(w, 0, target_type="GarbageCan")
