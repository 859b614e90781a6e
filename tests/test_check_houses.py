"""tools/check_houses.py: the real-house conformance table and its --check verdict."""

from __future__ import annotations

import json

from adaptenv.scene.house import save_house
from tests.conftest import REAL_HOUSE
from tests.sim import helpers as H
from tests.tools import load_tool


def _tool():
    return load_tool("check_houses")


def test_counts_every_stage_and_fails_the_check_on_a_broken_house(tmp_path, capsys):
    tool = _tool()
    d = tmp_path / "houses"
    save_house(H.corridor_house(), d / "a_good.json")
    save_house(H.one_room(), d / "b_no_target.json")
    (d / "c_broken.json").write_text("{", encoding="utf-8")
    (d / "d_real.json").write_text(REAL_HOUSE.read_text(encoding="utf-8"), encoding="utf-8")
    rep = tool.check_set(str(d), episodes=6, seed=0, agent=None)
    assert (rep.houses, rep.loaded, rep.round_trip, rep.usable) == (4, 3, 3, 2)
    assert rep.sampled == 6 and rep.solvable == rep.expert_success == 6
    assert [s.name for s in rep.skipped] == ["b_no_target"]
    assert tool.failed([rep], 0.98) == [f"{d}: 1 house(s) failed to load, 0 to round-trip"]
    assert tool.main([str(d), "--episodes", "2", "--agent", "none", "--check"]) == 1
    out = capsys.readouterr().out
    assert "round trip" in out and "3/3 (100.0%)" in out and "c_broken" in out
    (d / "c_broken.json").unlink()
    assert tool.main([str(d), "--episodes", "2", "--agent", "none", "--check"]) == 0


def test_reads_a_sliced_house_dataset(tmp_path):
    tool = _tool()
    path = tmp_path / "houses.jsonl"
    docs = [H.corridor_house().to_dict(), json.loads(REAL_HOUSE.read_text(encoding="utf-8"))]
    path.write_text("\n".join([*map(json.dumps, docs), "{"]) + "\n", encoding="utf-8")  # a broken line past the slice
    rep = tool.check_set(f"{path}:0:2", episodes=2, seed=0, agent=None)
    assert (rep.houses, rep.loaded, rep.round_trip, rep.usable, rep.solvable) == (2, 2, 2, 2, 2)


def test_counts_objaverse_houses_that_all_fail_to_load(tmp_path, capsys, monkeypatch):
    from adaptenv.scene.assets import SKIP_UNKNOWN_ENV
    from tests.conftest import objaverse_house_doc

    monkeypatch.setenv(SKIP_UNKNOWN_ENV, "0")  # restored after the test (main's flag sets it)
    tool = _tool()
    path = tmp_path / "objaverse.jsonl"
    docs = [objaverse_house_doc(floor=False), objaverse_house_doc(floor=True), objaverse_house_doc(floor=False)]
    path.write_text("".join(json.dumps(d) + "\n" for d in docs), encoding="utf-8")
    rep = tool.check_set(str(path), episodes=2, seed=0, agent=None)
    assert (rep.houses, rep.loaded, rep.usable) == (3, 0, 0)
    assert rep.failures[-1] == "none of the 3 houses read loaded, so none can be used"
    assert not any("none of the 0" in f for f in rep.failures)
    assert tool.counts_line(rep).startswith("read 3 house(s): 3 left out at load")
    assert tool.main([str(path), "--episodes", "2", "--agent", "none", "--skip-unknown-assets"]) == 0
    out = capsys.readouterr().out
    assert "read 3 house(s): 1 left out at load (invalid or unreadable), 0 left out as unusable (no episode), " \
           "2 usable" in " ".join(out.split()) and "'Fridge|2|1'" in out
