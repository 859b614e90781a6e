"""What a reader looks for: house thumbnails, held-out results per house, edit intents, curve notes, glossary."""

from __future__ import annotations

from adaptenv.curriculum.records import RUN_INFO, RunInfo, atomic_write_text
from adaptenv.report import build_report
from adaptenv.scene.house import save_house
from adaptenv.scene.procedural import generate_house


def test_run_report_has_houses_heldout_intents_and_glossary(tmp_path, make_run, renders):
    run = make_run(tmp_path / "run", iterations=2, scenes=2)
    for k in range(3):
        save_house(generate_house(k), tmp_path / "houses" / "train" / f"house_{k:02d}.json")
    save_house(generate_house(7), tmp_path / "houses" / "unseen" / "house_00.json")
    info = RunInfo.model_validate_json((run / RUN_INFO).read_text(encoding="utf-8"))
    info.config = {"houses": "houses/train", "heldout": {"unseen": "houses/unseen", "rearranged": "preset:tiny"}}
    atomic_write_text(run / RUN_INFO, info.model_dump_json())  # relative paths: found from the run's parent
    held = run / "iter_0002" / "heldout" / "unseen"
    held.mkdir(parents=True)
    (held / "houses.csv").write_text("house,episodes,success,spl,sel,collisions,steps\n"
                                     "house_00,8,0.625,0.41,0.5,3.25,212.5\n", encoding="utf-8")
    (held / "failures.png").write_bytes(renders[0].read_bytes())

    index = build_report(run)
    text = index.read_text(encoding="utf-8")
    thumbs = sorted(p.name for p in (index.parent / "img" / "houses").rglob("*.png"))
    assert thumbs == ["house_00.png", "house_00.png", "house_01.png", "house_02.png"]
    assert "(houses/train, 3 houses)" in text and "regenerate with adaptenv houses generate --preset tiny" in text
    assert "<code>house_00</code></td><td>8</td><td>0.625</td>" in text
    assert list((index.parent / "img" / "heldout").rglob("failures.png"))
    # intents: the generator log names the suggestion kind, the edit log only free text
    assert "<td class=l>narrow a passage</td><td>2</td><td>2</td><td>2</td>" in text
    assert "narrow the corridor" in text  # free text without a kind stays as written
    assert "Delta R is a point&#x27;s height above iteration 0" in text
    for term in ("pi_t", "e_t", "Delta R", "house_00~t02a00"):
        assert f"<dt><code>{term}</code></dt>" in text


def test_experiment_report_has_the_curve_note_and_glossary(tmp_path, make_experiment):
    exp = make_experiment(tmp_path / "exp", methods=("ours", "dr"), seeds=(0,), iterations=1)
    text = build_report(exp).read_text(encoding="utf-8")
    assert "How to read the curves" in text and 'id="glossary"' in text
