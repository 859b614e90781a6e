"""Candidate scenes of a proposed edit, for scoring before it is committed.

Generators that search over candidate moves dry-run each with
:meth:`~adaptenv.adapt.validation.EditValidator.propose` (placement plus validation, the scene
unchanged); :func:`edited_copy` and :func:`moved_geometry` build the candidate house and geometry
from the proposal's placement result so objectives can be measured on it. The chosen proposal is
then applied with :meth:`~adaptenv.adapt.validation.EditValidator.commit`.
"""

from __future__ import annotations

from dataclasses import replace

from adaptenv.adapt.placement import PlacementResult
from adaptenv.scene.geometry import SceneGeometry
from adaptenv.scene.house import House, move_object


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
