"""The HTML report: self-contained folder, escaping, experiment summary, empty runs, CLI errors."""

from __future__ import annotations

import json
import math
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote

import pytest

from adaptenv.curriculum.records import RUN_INFO, RunInfo
from adaptenv.errors import AdaptenvError
from adaptenv.report import build_report
from adaptenv.report.data import find_pvalues, load_run, mean_se, parse_edits


class Refs(HTMLParser):
    """Every src/href of a page, and the tags seen."""

    def __init__(self) -> None:
        super().__init__()
        self.refs: list[str] = []
        self.tags: list[tuple[str, dict]] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append((tag, a))
        self.refs += [v for k, v in attrs if k in ("src", "href") and v is not None]


def parse(page: Path) -> Refs:
    p = Refs()
    p.feed(page.read_text(encoding="utf-8"))
    return p


def assert_self_contained(root: Path) -> int:
    """Every page under ``root`` references only files inside ``root`` that exist; returns the file refs checked."""
    checked = 0
    for page in root.rglob("*.html"):
        text = page.read_text(encoding="utf-8")
        assert "http://" not in text and "https://" not in text, page
        for ref in parse(page).refs:
            if ref.startswith("#"):
                continue
            assert ":" not in ref and not ref.startswith("/"), f"{page}: non-relative reference {ref}"
            target = (page.parent / unquote(ref.split("#")[0])).resolve()
            assert target.is_relative_to(root.resolve()), f"{page}: {ref} leaves the report folder"
            assert target.is_file(), f"{page}: {ref} does not exist"
            checked += 1
    return checked


def test_run_report_is_a_self_contained_folder(tmp_path, make_run):
    run = make_run(tmp_path / "run", iterations=3, scenes=2)
    index = build_report(run)
    assert index == run / "report" / "index.html"
    assert assert_self_contained(index.parent) >= 3 * 2 * 2 + 1 + 3  # renders, curves, raw records
    # the report still works after the run folder is gone (it is a copy, not a view)
    moved = tmp_path / "moved"
    index.parent.rename(moved)
    assert_self_contained(moved)
    refs = parse(moved / "index.html")
    gallery = [a for t, a in refs.tags if t == "img" and "img/" in a["src"]]
    assert len(gallery) == 12
    assert all(a.get("loading") == "lazy" and int(a["width"]) > 0 for a in gallery)
    assert not any(t in ("script", "link", "iframe") for t, _ in refs.tags)


def test_run_report_sections_and_figures(tmp_path, make_run):
    run = make_run(tmp_path / "run", iterations=3, scenes=2)
    text = build_report(run).read_text(encoding="utf-8")
    for section in ('id="curves"', 'id="results"', 'id="gallery"', 'id="iter-3"', 'id="iter-1"'):
        assert section in text
    assert "60,000" in text and "65.0%" in text  # env steps and held-out success of iteration 3
    # analysis as lists, edits with requested vs achieved (grid units), stop reason and verification
    assert "narrow_passage" in text and "late_sight" in text
    assert "(+10.0, -5.0)" in text and "(+6.5, -5.0)" in text
    assert "blocked_by_object" in text and "DiningTable|3|2" in text
    assert "verified (objective)" in text and "rejected" in text and "no candidate improved the objective" in text


def test_text_from_files_is_escaped(tmp_path, make_run, evil):
    run = make_run(tmp_path / "run", iterations=1, scenes=2, text=evil)
    page = build_report(run)
    text = page.read_text(encoding="utf-8")
    assert "<script" not in text.lower()
    assert "<img src=x" not in text
    assert "&lt;script&gt;alert(&quot;x&quot;)&lt;/script&gt;" in text
    assert assert_self_contained(page.parent) > 0  # scene names with markup still give valid file names


def test_experiment_summary_with_several_methods(tmp_path, make_experiment):
    exp = make_experiment(tmp_path / "exp", methods=("ours", "accel", "dr"), seeds=(0, 1, 2))
    index = build_report(exp)
    text = index.read_text(encoding="utf-8")
    for m in ("ours", "accel", "dr"):
        assert f"<strong>{m}</strong>" in text
        for s in (0, 1, 2):
            assert (index.parent / "runs" / m / f"seed_{s}" / "index.html").is_file()
            assert f'href="runs/{m}/seed_{s}/index.html"' in text
    assert "significance" in text and "compares ours with the method of each row" in text
    # accel (second method) differs from ours with p=0.003 on success; dr has p=0.2 (no star); spl p is null
    rows = {m: text.split(f"<strong>{m}</strong>")[1].split("</tr>")[0] for m in ("ours", "accel", "dr")}
    assert "success p=0.003**" in rows["accel"] and "success p=0.2<" in rows["dr"] and "p=" not in rows["ours"]
    assert "SPL p=" not in text
    for data in ("data/summary.json", "data/summary.md", "data/accel/per_seed.csv"):
        assert f'href="{data}"' in text and (index.parent / data).is_file()
    assert (index.parent / "plots" / "curves_rearranged.png").is_file()
    assert (index.parent / "plots" / "curves_unseen.png").is_file()
    assert "± " in text
    assert_self_contained(index.parent)
    nested = (index.parent / "runs" / "dr" / "seed_2" / "index.html").read_text(encoding="utf-8")
    assert 'href="../../../index.html"' in nested


def test_experiment_report_shows_the_final_evaluation(tmp_path, make_experiment):
    from adaptenv.curriculum.experiment import ExperimentConfig, write_summary

    exp = make_experiment(tmp_path / "exp", methods=("ours", "dr"), seeds=(0, 1, 2))
    ours, dr = (0.70, 0.75, 0.65), (0.60, 0.62, 0.61)  # differences +0.10, +0.13, +0.04
    table = {m: {s: {"success:unseen": v[s], "spl:unseen": v[s] / 2} for s in range(3)}
             for m, v in (("ours", ours), ("dr", dr))}
    write_summary(exp, ExperimentConfig(methods=["ours", "dr"], seeds=[0, 1, 2], reference="ours"), table,
                  suffix="_final", episodes=300)
    text = build_report(exp).read_text(encoding="utf-8")
    final = text.split('id="final"')[1].split("</section>")[0]
    assert "on 300 episodes per held-out set" in final and "<strong>dr</strong>" in final
    assert "70.0%" in final and "61.0%" in final  # the means, from summary_final.json, not the runs' records
    # ours - dr: mean +0.090, s.d. 0.0458, t(2) = 3.40, p = 0.077; one comparison, so Holm's p is the same
    assert "<td>+9.0</td><td>[-2.4, +20.4]</td><td>0.0766</td><td>0.0766</td>" in final
    assert 'href="#final"' in text


def test_experiment_without_summary_has_no_significance_column(tmp_path, make_experiment):
    exp = make_experiment(tmp_path / "exp", methods=("a", "b"), seeds=(0,), iterations=1, summary=False)
    text = build_report(exp, tmp_path / "out").read_text(encoding="utf-8")
    assert "significance" not in text
    assert "<strong>a</strong>" in text and "<strong>b</strong>" in text


def test_empty_run_gives_a_clear_message(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / RUN_INFO).write_text(RunInfo(method="ours", seed=0).model_dump_json(), encoding="utf-8")
    index = build_report(run)
    text = index.read_text(encoding="utf-8")
    assert "No iterations have finished yet" in text
    assert not (index.parent / "plots").exists()
    assert_self_contained(index.parent)


def test_partial_records_become_warnings(tmp_path, make_run):
    run = make_run(tmp_path / "run", iterations=2, scenes=1)
    with open(run / "iterations.jsonl", "a", encoding="utf-8") as f:
        f.write('{"iteration": 3, "env_st')  # a crash mid-write
    (run / "iter_0001" / "gallery" / "scene0" / "after.png").unlink()
    (run / "iter_0002" / "gallery" / "scene0" / "analysis.json").write_text("{not json", encoding="utf-8")
    index = build_report(run)
    text = index.read_text(encoding="utf-8")
    assert "iterations.jsonl line 3 skipped" in text
    assert "no render recorded" in text and "after.png is missing" in text
    assert "analysis.json is unreadable" in text
    assert len(load_run(run).iterations) == 2
    assert_self_contained(index.parent)


def test_rewriting_a_report_deletes_no_file_of_yours(tmp_path, make_run):
    """build_report writes its files and deletes nothing; adaptenv report removes its own earlier files (by its
    manifest, tests/test_cli_outputs.py), never one of yours."""
    run = make_run(tmp_path / "run", iterations=2, scenes=1)
    index = build_report(run)
    mine = index.parent / "img" / "mine.png"
    mine.write_bytes(b"x")
    keep = index.parent / "notes.txt"
    keep.write_text("mine", encoding="utf-8")
    build_report(run)
    assert mine.read_bytes() == b"x" and keep.read_text(encoding="utf-8") == "mine"
    with pytest.raises(AdaptenvError, match="cannot be written into the folder it reads"):
        build_report(run, run)


def test_not_a_run_folder_is_an_error(tmp_path):
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "file.txt").write_text("x", encoding="utf-8")
    with pytest.raises(AdaptenvError, match="not a run folder"):
        build_report(tmp_path / "junk")
    with pytest.raises(AdaptenvError, match="no such folder"):
        build_report(tmp_path / "missing")


def run_cli(monkeypatch, capsys, *args: str) -> tuple[int, str, str]:
    from adaptenv.cli import main

    monkeypatch.setattr(sys, "argv", ["adaptenv", "report", *args])
    code = 0
    try:
        main()
    except SystemExit as exc:
        code = int(exc.code or 0)
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.parametrize("case", ["missing", "not_a_run"])
def test_cli_errors_are_one_line(tmp_path, monkeypatch, capsys, case):
    folder = tmp_path / case
    if case == "not_a_run":
        folder.mkdir()
    code, out, err = run_cli(monkeypatch, capsys, str(folder))
    assert code == 1 and out == ""
    assert len(err.strip().splitlines()) == 1, err
    assert str(folder) in err and "Traceback" not in err
    assert ("no such folder" if case == "missing" else "not a run folder") in err


def test_cli_prints_the_index_path(tmp_path, monkeypatch, capsys, make_run):
    run = make_run(tmp_path / "run", iterations=1, scenes=1)
    code, out, _ = run_cli(monkeypatch, capsys, str(run), "-o", str(tmp_path / "rep"))
    assert code == 0
    assert out.strip() == str(tmp_path / "rep" / "index.html")
    assert (tmp_path / "rep" / "index.html").is_file()


def test_find_pvalues_reads_nested_and_flat_shapes():
    methods, sets = ["ours", "dr"], ["unseen", "rearranged"]
    nested = {"p_values": {"ours": {"unseen": {"success": 0.01, "spl": 0.2}}}, "ours": {"mean": 0.5}}
    assert find_pvalues(nested, methods, sets) == {("ours", "unseen", "success"): 0.01, ("ours", "unseen", "spl"): 0.2}
    flat = [{"method": "dr", "set": "rearranged", "p": 0.04}, {"method": "x", "set": "unseen", "p": 0.1}]
    assert find_pvalues(flat, methods, sets) == {("dr", "rearranged", ""): 0.04}
    assert find_pvalues({"ours": {"unseen": {"success": {"mean": 0.3}}}}, methods, sets) == {}
    runner = {"tests": {"dr": {"success:unseen": 0.03, "success_gain:unseen": 0.5}}}
    assert find_pvalues(runner, methods, sets) == {("dr", "unseen", "success"): 0.03}
    runner = {"methods": {"dr": {"success:unseen": {"mean": 0.4, "se": 0.1, "n": 3}}}, "reference": "ours",
              "tests": {"dr": {"success:unseen": 0.03, "spl:unseen": None}}}
    assert find_pvalues(runner, methods, sets) == {("dr", "unseen", "success"): 0.03}


def test_mean_and_standard_error():
    s = mean_se([0.5, 0.7])
    assert s is not None and math.isclose(s.mean, 0.6) and math.isclose(s.se, 0.1)
    one = mean_se([0.4])
    assert one is not None and one.se is None and one.n == 1
    assert mean_se([]) is None


def test_parse_edits_accepts_both_formats():
    from adaptenv.adapt.edits import Edit, EditLog

    log = EditLog(edits=[Edit(object_id="Chair|1", dx_units=5, achieved_dx_units=2.5, source="llm")])
    gen, rows = parse_edits(json.loads(log.to_json()))
    assert gen == "llm" and rows[0].requested == (5.0, 0.0) and rows[0].achieved == (2.5, 0.0)
    gen, rows = parse_edits({"generator": "builtin", "steps": [{"step": 1, "status": "skipped", "reason": "none fit"}]})
    assert gen == "builtin" and rows[0].note == "none fit" and rows[0].object_id == "-"
