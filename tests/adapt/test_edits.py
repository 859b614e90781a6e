"""Edit records: JSON round trip and replaying achieved moves from the parent scene."""

from __future__ import annotations

import numpy as np
import pytest

from adaptenv.adapt.edits import Edit, EditLog, apply_edit, replay
from adaptenv.adapt.validation import EditValidator
from adaptenv.errors import AdaptenvError


def test_log_round_trips_through_json(tmp_path):
    log = EditLog(edits=[Edit(object_id="Chair|1", dx_units=20, dy_units=5, rotation=90.0, achieved_dx=1.2,
                              stop_reason="blocked_by_object", blocked_by="Bed|2", source="llm", intent="narrow"),
                         Edit(object_id="Sofa|3", accepted=False, problems=["room|4 would become unreachable"])])
    back = EditLog.load(log.save(tmp_path / "log.json"))
    assert back == log and back.edits[0].blocked_by == "Bed|2" and not back.edits[1].accepted


def test_bad_log_file_is_one_sentence(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text("{\"edits\": 3}")
    with pytest.raises(AdaptenvError, match="not a valid edit log"):
        EditLog.load(p)


def test_apply_edit_moves_children_rigidly(real_house):
    parent = next(o for o in real_house.objects if o.children)
    edit = Edit(object_id=parent.id, achieved_dx=0.3, achieved_dz=-0.2, yaw_before=parent.yaw,
                yaw_after=(parent.yaw + 90.0) % 360.0)
    out = apply_edit(real_house, edit)
    moved = out.object_by_id(parent.id)
    assert moved.position.x == pytest.approx(parent.position.x + 0.3)
    assert moved.yaw == pytest.approx((parent.yaw + 90.0) % 360.0)
    for before, after in zip(parent.children, moved.children, strict=True):
        r0 = np.array([before.position.x - parent.position.x, before.position.z - parent.position.z])
        r1 = np.array([after.position.x - moved.position.x, after.position.z - moved.position.z])
        assert np.linalg.norm(r0) == pytest.approx(np.linalg.norm(r1))  # rigid: same distance to the centre
        assert after.position.y == before.position.y
    assert real_house.object_by_id(parent.id).position.x == parent.position.x  # the parent scene is untouched


def test_replaying_the_log_reproduces_the_validator_scene(real_house):
    v = EditValidator(real_house)
    rng = np.random.default_rng(0)
    ids = [oid for oid, m in zip(v.ctx.ids, v.ctx.movable, strict=True) if m]
    for _ in range(40):
        yaw = float(rng.uniform(0, 360)) if rng.random() < 0.5 else None
        v.try_edit(ids[int(rng.integers(len(ids)))], *rng.uniform(-20, 20, 2), yaw, source="random")
    log = EditLog.from_json(v.log.to_json())
    child = replay(real_house, log)
    for a, b in zip(child.objects, v.house.objects, strict=True):
        assert a.position.x == pytest.approx(b.position.x) and a.position.z == pytest.approx(b.position.z)
        assert a.yaw == pytest.approx(b.yaw)
    assert sum(e.changed for e in log) > 5


def test_rejected_edits_replay_as_no_ops(real_house):
    edit = Edit(object_id="Bed|6|0|0", achieved_dx=5.0, accepted=False)
    assert apply_edit(real_house, edit).to_dict() == real_house.to_dict()
    with pytest.raises(AdaptenvError, match="no top-level object"):
        apply_edit(real_house, Edit(object_id="Ghost|1", achieved_dx=1.0))
