"""Dry runs of an edit on an :class:`~adaptenv.adapt.validation.EditValidator`: place and check, keep nothing.

Generators that search over candidate moves need the placement result and the validation verdict
of many proposals before committing one; :func:`trial_edit` runs the same placement and the same
incremental checks as ``EditValidator.try_edit`` without changing the validator's scene, and
:func:`edited_copy` builds the candidate house for scoring. Committing the chosen proposal with
``try_edit`` afterwards gives the identical result (placement is deterministic).

The incremental path mirrors ``try_edit``'s private checks; if the validator's internals change,
it falls back to the exact :func:`~adaptenv.adapt.validation.validate_scene` on the edited copy.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from adaptenv.adapt.placement import PlacementResult, place_units
from adaptenv.adapt.validation import EditValidator, ValidationProblem, validate_scene
from adaptenv.scene.geometry import SceneGeometry
from adaptenv.scene.house import House, move_object


def trial_edit(v: EditValidator, object_id: str, dx_units: float, dy_units: float,
               rotation: float | None = None) -> tuple[PlacementResult, list[ValidationProblem]]:
    """Placement result and validation problems of one proposal; the validator is left unchanged."""
    res = place_units(v.ctx, object_id, dx_units, dy_units, rotation, step=v.step)
    if res.stop_reason == "invalid":
        return res, [ValidationProblem("invalid", res.message, (object_id,))]
    if not res.changed:
        return res, []
    try:
        return res, _incremental_problems(v, res)
    except (AttributeError, TypeError):  # the validator's internals changed: use the exact, slower check
        return res, validate_scene(edited_copy(v.house, res), episode_targets=sorted(v.need_targets),
                                   start=v.start, original=v.house)


def _incremental_problems(v: EditValidator, res: PlacementResult) -> list[ValidationProblem]:
    """The checks of ``EditValidator.try_edit`` (incremental raster, exact geodesic fallback), without commit."""
    from adaptenv.adapt.validation import _world_reaches

    i = v.ctx.index[res.object_id]
    center = v.ctx.centers[i] + np.array(res.achieved)
    corners = v.ctx.corners(i, center, res.yaw_after)
    inf = v.raster.inflate(corners)
    problems = v._check(v.raster.navigable_with(i, inf), i, inf, corners)
    missing = {p.object_ids[0] for p in problems if p.kind == "target_unreachable"}
    if missing and len(missing) == len(problems):
        world, _ = v._trial_world(i, center, res.yaw_after)
        problems = [p for p in problems if not _world_reaches(world, p.object_ids[0], v.start)]
    return problems


def edited_copy(house: House, res: PlacementResult, *, share: bool = False) -> House:
    """A copy of ``house`` with the placement result applied (children move rigidly).

    With ``share`` only the moved object is copied and every other object is shared with
    ``house`` (fast; for short-lived candidates that are read, never edited).
    """
    if share:
        out = house.model_copy()
        out.objects = [o.model_copy(deep=True) if o.id == res.object_id else o for o in house.objects]
    else:
        out = house.model_copy(deep=True)
    for obj in out.objects:
        if obj.id == res.object_id:
            move_object(obj, res.achieved[0], res.achieved[1], res.yaw_after - res.yaw_before)
            break
    return out


def moved_geometry(geometry: SceneGeometry, res: PlacementResult) -> SceneGeometry:
    """``geometry`` with the moved object's footprint at its new pose (enough to compile a world)."""
    fps = [replace(f, center=(f.center[0] + res.achieved[0], f.center[1] + res.achieved[1]),
                   yaw=res.yaw_after % 360.0) if f.object_id == res.object_id else f for f in geometry.footprints]
    return replace(geometry, footprints=fps)
