"""Edit counts a person can trust (distinct objects, net moves) and object types beside typeless ids
(ProcTHOR-100K's ``6|1|3``) in the adapt log, ``audit --json`` and the renders."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from adaptenv.adapt.analysis import BuiltinAnalyzer
from adaptenv.adapt.edits import Edit, edit_counts, replay
from adaptenv.adapt.generators import make_generator
from adaptenv.adapt.step import adapt_scene, summarize, write_outputs
from adaptenv.agents.policy import ExpertPolicy
from adaptenv.agents.rollout import draw_episode
from adaptenv.cli import app
from adaptenv.cli.adapt import edit_counts_text
from adaptenv.render.topdown import render_map
from adaptenv.scene.assets import object_label
from adaptenv.scene.house import House, save_house
from adaptenv.sim.world import compile_world


@pytest.fixture(scope="module")
def house() -> House:
    from adaptenv.scene.procedural import GenerationConfig, generate_house

    return generate_house(5, GenerationConfig(n_rooms=4))


def typeless(house: House) -> House:
    """The house with ProcTHOR-100K-style ids: ``Fridge|2|0`` becomes ``2|0`` (children too)."""
    out = house.model_copy(deep=True)
    for obj, _ in out.iter_objects():
        obj.id = obj.id.split("|", 1)[1]
    return out


def test_object_label_adds_the_type_only_where_the_id_lacks_it():
    assert object_label("6|1|3", "Chair") == "Chair 6|1|3"
    assert object_label("Chair|3|0|3", "Chair") == "Chair|3|0|3"
    assert object_label("CounterTop|2|0", "CounterTop") == "CounterTop|2|0"
    assert object_label("door|2|3", "Doorway") == "door|2|3"
    assert object_label("6|1|3", None) == "6|1|3"


def test_one_object_moved_five_times_or_back_and_forth_counts_as_it_is(house):
    mover, back = house.objects[0].id, house.objects[3].id
    edits = [Edit(object_id=mover, achieved_dx=0.1) for _ in range(5)]
    edits += [Edit(object_id=back, achieved_dz=0.3), Edit(object_id=back, achieved_dz=-0.3)] * 3
    c = edit_counts(edits, house, replay(house, edits))
    assert (c["edits"], c["objects_edited"], c["objects_changed"]) == (11, 2, 1)
    assert c["net_displacement_m"] == pytest.approx(0.5)
    assert [(o["id"], o["edits"], o["changed"]) for o in c["objects"]] == [(mover, 5, True), (back, 6, False)]
    text = edit_counts_text({**c, "objects": [{**o, "type": "Fridge"} for o in c["objects"]]})
    assert text.startswith("11 edits of 2 objects") and "1 changed on net, net displacement 0.50 m" in text
    assert "x6 (back where it stood)" in text
    turned = [Edit(object_id=mover, yaw_before=0.0, yaw_after=90.0)]
    assert edit_counts(turned, house, replay(house, turned))["objects_changed"] == 1


def test_the_adapt_log_and_summary_carry_types_beside_typeless_ids(house, tmp_path):
    h = typeless(house)
    world = compile_world(h, "h")
    ep = draw_episode(world, np.random.default_rng([1, 1]))
    res = adapt_scene(h, ep, policy=ExpertPolicy(), analyzer=BuiltinAnalyzer(),
                      generator=make_generator("builtin", max_candidates=10), steps=2, rng=np.random.default_rng(1),
                      name="h")
    summary = summarize(res, analyzer=BuiltinAnalyzer(), seed=1)
    write_outputs(res, summary, tmp_path)
    # the original ids name the type: Fridge|2|0 is the Fridge 2|0
    types = {o.id.split("|", 1)[1]: o.id.split("|", 1)[0] for o in house.objects}
    edits = json.loads((tmp_path / "edits.json").read_text())
    logged = [s["edit"] for s in edits["steps"] if s["edit"]] + edits["edit_log"]
    assert logged and all(e["object_type"] == types[e["object_id"]] for e in logged)
    counted = json.loads((tmp_path / "summary.json").read_text())["edit_counts"]
    assert counted["edits"] == summary["edits_applied"] >= 1
    assert all(o["type"] == types[o["id"]] for o in counted["objects"])


def test_audit_json_and_renders_name_the_type(house, tmp_path):
    h = typeless(house)
    moved = h.model_copy(deep=True)
    obj = moved.objects[0]
    obj.position = obj.position.model_copy(update={"x": obj.position.x + 0.05})
    before, after = save_house(h, tmp_path / "before.json"), save_house(moved, tmp_path / "after.json")
    res = CliRunner().invoke(app, ["audit", str(before), str(after), "--json"])
    doc = json.loads(res.output)
    assert doc["moved"] == [obj.id] and doc["moved_types"] == [house.objects[0].id.split("|")[0]]
    texts = {lab.text for lab in render_map(h, size=512).labels}
    assert f"{house.objects[0].id.split('|')[0]} {obj.id}" in texts
    assert obj.id not in texts  # never the bare typeless id


def test_audit_lines_name_the_type_of_every_typeless_id(house, tmp_path):
    h = typeless(house)
    moved = h.model_copy(deep=True)
    obj = moved.objects[13]  # moved into the clearance of a door: the door_approach message names no type
    obj.position = obj.position.model_copy(update={"x": obj.position.x - 0.4})
    kind = house.objects[13].id.split("|")[0]
    before, after = save_house(h, tmp_path / "before.json"), save_house(moved, tmp_path / "after.json")
    res = CliRunner().invoke(app, ["audit", str(before), str(after)])
    lines = [line for line in res.output.splitlines() if obj.id in line]
    assert res.exit_code == 1 and lines
    assert all(f"{obj.id} ({kind})" in line or f"{obj.id} is a {kind}" in line for line in lines)
