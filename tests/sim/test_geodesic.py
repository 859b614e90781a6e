"""Success regions and geodesic distance fields on synthetic houses and the real house."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from adaptenv.sim.geodesic import (
    distance_field,
    enterable,
    field_at,
    geodesic_distance,
    is_solvable,
    navigable,
    optimal_path_length,
    success_region,
)
from adaptenv.sim.task import Episode, visible_instances
from adaptenv.sim.world import compile_world
from tests.sim import helpers as H


def straight_line_to(region: np.ndarray, res: float) -> np.ndarray:
    """Euclidean distance (m) from each cell centre to the nearest region cell centre."""
    return ndimage.distance_transform_edt(~region) * res


def test_empty_room_field_is_straight_line_distance():
    w = compile_world(H.one_room((5.0, 4.0), objects=[H.Obj(H.LOW_TARGET, 4.6, 3.7)]))
    region = success_region(w, "GarbageCan")
    field = distance_field(w, "GarbageCan")
    nav = navigable(w)
    assert region.any() and np.isfinite(field[nav]).all()
    assert (field[region] == 0).all() and (field[nav & ~region] > 0).all()
    ref = straight_line_to(region, w.grid.resolution)
    err = field[nav] - ref[nav]
    # Never shorter than the straight line; longer by at most a cell plus the 16-neighbour
    # metric's 2.7% worst case.
    assert err.min() >= -1e-4
    assert (err <= w.grid.resolution + 0.0275 * ref[nav]).all()
    assert np.max(ref[nav]) > 2.5


def test_field_goes_around_a_wall():
    w = compile_world(H.two_rooms(1.0, objects=[H.Obj(H.LOW_TARGET, 7.7, 0.3)]))
    region = success_region(w, "GarbageCan")
    field = distance_field(w, "GarbageCan")
    x, z = 3.0, 0.5  # in room 0, just across the wall from the region
    straight = float(field_at(w, straight_line_to(region, w.grid.resolution), x, z))
    via_door = geodesic_distance(w, "GarbageCan", x, z)
    assert np.isfinite(via_door)
    assert via_door > straight + 0.5  # the wall forces a detour through the door at z = 2
    # ... but it is no longer than walking to the door centre, then on to the region.
    door = (4.0, 2.0)
    to_region = float(field_at(w, field, door[0] + 0.3, door[1])) + 0.3
    assert via_door <= np.hypot(door[0] - x, door[1] - z) + to_region + 0.1


def test_sealed_room_is_unreachable():
    w = compile_world(H.sealed_target_house())
    field = distance_field(w, "GarbageCan")
    assert success_region(w, "GarbageCan").any()
    ep = Episode("GarbageCan", (2.0, 2.0, 90.0))
    assert geodesic_distance(w, "GarbageCan", 2.0, 2.0) == np.inf
    assert optimal_path_length(w, ep) == np.inf and not is_solvable(w, ep)
    assert np.isfinite(field[success_region(w, "GarbageCan")]).all()
    assert is_solvable(w, Episode("Fridge", (4.0, 1.0, 0.0)))


def test_region_matches_visibility_at_cell_centres(real_house):
    """Reference loop: an enterable cell is in the region iff the target is visible from its centre in some
    direction."""
    w = compile_world(real_house)
    rng = np.random.default_rng(0)
    for target in ("Bed", "Fridge", "GarbageCan"):
        region = success_region(w, target)
        nav = enterable(w)
        # Cells near the region boundary are the interesting ones; add random navigable cells.
        edge = region ^ ndimage.binary_dilation(region, iterations=3)
        cand = np.flatnonzero(edge & nav)
        cells = np.concatenate([rng.choice(cand, 150, replace=False), rng.choice(np.flatnonzero(nav), 50)])
        rows, cols = np.divmod(cells, w.grid.shape[1])
        xs, zs = w.grid.cell_center(rows, cols)
        for r, c, x, z in zip(rows, cols, xs, zs, strict=True):
            seen = bool(visible_instances(w, x, z, 0.0, target, fov_deg=360.0))
            assert seen == region[r, c], (target, r, c)


def test_geodesic_distance_is_vectorized_and_never_stuck_on_cell_edges():
    w = compile_world(H.one_room((4.0, 4.0), objects=[H.Obj(H.LOW_TARGET, 3.6, 3.7)]))
    xs = np.array([0.5, 1.0, 2.0])
    out = geodesic_distance(w, "GarbageCan", xs, np.full(3, 0.5))
    assert out.shape == (3,) and np.all(np.diff(out) < 0)
    # A point just inside the agent-radius band along the wall reads its navigable neighbour.
    x = 0.19
    assert not navigable(w)[w.grid.to_cell(x, 1.0)]
    assert np.isfinite(geodesic_distance(w, "GarbageCan", x, 1.0))
    assert geodesic_distance(w, "GarbageCan", -5.0, 1.0) == np.inf


def test_fields_are_cached(real_house):
    w = compile_world(real_house)
    assert distance_field(w, "Bed") is distance_field(w, "Bed")
    assert ("distance", "Bed") in w.cache and w.cache[("distance", "Bed")].dtype == np.float32
    assert distance_field(w, "Bed").shape == w.grid.shape


@pytest.mark.parametrize("target", ["Toilet", "Sofa"])
def test_real_house_fields_are_finite_on_the_main_floor(real_house, target):
    w = compile_world(real_house)
    comp, _ = w.grid.components(0.2)
    largest = np.argmax(np.bincount(comp.ravel())[1:]) + 1
    assert np.isfinite(distance_field(w, target)[comp == largest]).all()


def test_success_region_is_enterable_and_drops_only_slivers(real_house):
    w = compile_world(real_house)
    for t in ("Toilet", "Sofa", "Bed"):
        region = success_region(w, t)
        assert not (region & ~enterable(w)).any()
    assert enterable(w).sum() > 0.97 * navigable(w).sum() and not (enterable(w) & ~navigable(w)).any()


def _gap_house(gap: float, can_z: float = 5.5, depth: float = 6.0):
    """A room cut at z = 3 by four tall desks (1.39 x 0.69 m) with one ``gap`` (m) between them and a garbage
    can behind them at ``can_z`` (seen only from behind the desks); the room is ``depth`` m deep."""
    d = 1.39
    width = 4 * d + gap
    objs = [H.Obj(H.TALL_FURNITURE, x, 3.0) for x in (d / 2, 1.5 * d, 2.5 * d + gap, 3.5 * d + gap)]
    return H.make_house([(0.0, 0.0, width, depth)], objects=[*objs, H.Obj(H.LOW_TARGET, width / 2, can_z)]), width


def test_a_one_cell_strip_is_navigable_but_not_enterable():
    """A 0.5 m gap between tall desks leaves a strip of floor one cell wide where the disc fits: the
    agent may pass along it but cannot stop in it, so no success region lies there."""
    h, width = _gap_house(0.5)
    w = compile_world(h)
    gap = w.grid.to_cell(width / 2, 3.0)
    assert navigable(w)[gap] and not enterable(w)[gap]
    assert not success_region(w, "GarbageCan")[gap]


@pytest.mark.parametrize("gap", [0.5, 0.6])
def test_corridors_the_disc_fits_stay_passable_and_the_expert_gets_through(gap):
    from adaptenv.sim.rollout import expert_policy, run_episode

    h, width = _gap_house(gap)
    w = compile_world(h)
    ep = Episode("GarbageCan", (width / 2 - 1.5, 1.0, 0.0))
    assert is_solvable(w, ep)
    assert run_episode(w, ep, expert_policy(), max_steps=600).metrics.success


def test_reuse_region_keeps_only_what_a_move_cannot_change(real_house):
    """A move far from every target keeps the base world's success region (exactly what computing it gives); a move
    near one, or of a target itself, is refused and the region is computed."""
    from dataclasses import replace

    from adaptenv.scene.geometry import SceneGeometry
    from adaptenv.sim.geodesic import reuse_region

    base = compile_world(real_house)
    geometry = SceneGeometry.from_house(real_house)
    target = "Bed"
    success_region(base, target)
    beds = [t.center for t in base.instances_of(target)]
    kept, refused = 0, 0
    for f in geometry.floor_objects:
        for dx, dz in ((0.4, 0.0), (0.0, -0.4), (-0.3, 0.3)):
            moved = replace(geometry, footprints=[replace(g, center=(g.center[0] + dx, g.center[1] + dz))
                                                  if g is f else g for g in geometry.footprints])
            world = compile_world(real_house, geometry=moved)
            if reuse_region(world, base, target):
                kept += 1
                fresh = compile_world(real_house, geometry=moved)
                assert np.array_equal(world.cache[("region", target)], success_region(fresh, target))
            else:
                refused += 1
                assert ("region", target) not in world.cache
                near = min(np.hypot(f.center[0] - x, f.center[1] - z) for x, z in beds)
                assert f.object_type == target or near < 6.0, "refused only near a target"
    assert kept >= 10 and refused >= 5, "both outcomes are exercised"
