"""The learned G: its data (``adaptenv gdata collect``: rows, resume), its scorer (``gdata train``, checkpoints) and
the generator itself (``adapt --generator learned``)."""

from __future__ import annotations

import gzip
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from adaptenv.adapt.gdata import (
    ROWS,
    SCHEMA,
    CollectConfig,
    Dataset,
    collect,
    house_sha256,
    iter_rows,
    load_rows,
    run_settings,
)
from adaptenv.adapt.generators import GenerationContext, make_generator
from adaptenv.adapt.generators.edit_features import FEATURE_NAMES
from adaptenv.adapt.generators.learned import (
    OBJECTIVES,
    LearnedGenerator,
    load_scorer,
    shipped_path,
)
from adaptenv.adapt.objectives import OBJECTIVE_KINDS
from adaptenv.adapt.plausibility import audit
from adaptenv.adapt.validation import EditValidator, validate_scene
from adaptenv.agents.houses import load_house_set
from adaptenv.agents.policy import ExpertPolicy
from adaptenv.agents.rollout import draw_episode, rollout
from adaptenv.cli import app
from adaptenv.errors import ConfigError

runner = CliRunner()
CFG = CollectConfig(tasks=1, candidates=6, episodes=1, seed=3)


@pytest.fixture(scope="module")
def tiny():
    return load_house_set("preset:tiny")


def _pairs(hs, n):
    return [(h, {"spec": "preset:tiny", "name": w.name, "index": i, "sha256": house_sha256(h)})
            for i, (h, w) in enumerate(zip(hs.houses[:n], hs.worlds[:n], strict=True))]


@pytest.fixture(scope="module")
def collected(tiny, tmp_path_factory):
    out = tmp_path_factory.mktemp("gdata")
    counts = collect(_pairs(tiny, 2), ExpertPolicy(), CFG, out)
    return out, counts


def test_rows_follow_the_documented_schema(collected, tiny):
    out, counts = collected
    rows = load_rows(out)
    assert counts["houses"] == 2 and counts["rows"] == len(rows) == 2 * CFG.candidates
    for r in rows:
        assert r["schema"] == SCHEMA and r["house"]["spec"] == "preset:tiny"
        assert set(r) >= {"house", "task", "candidate", "episode", "policy", "analysis", "edit", "placement",
                          "accepted", "problems", "plausibility", "plausible", "expert_success", "effect", "features"}
        assert len(r["features"]) == len(FEATURE_NAMES)
        assert r["edit"]["generator"] in ("builtin", "random") and -100 <= r["edit"]["dx_units"] <= 100
        if r["effect"] is not None:  # measured only when validation accepted it and the expert still solves it
            assert r["accepted"] and r["expert_success"] and r["effect"]["episodes"] == CFG.episodes
            assert r["effect"]["spl_drop"] == pytest.approx(r["effect"]["spl_before"] - r["effect"]["spl_after"])
        if not r["accepted"]:
            assert r["effect"] is None
        # the route objectives go with every candidate the expert still solves, before and after the edit
        assert (r["objectives"] is not None) == bool(r["expert_success"])
        if r["objectives"] is not None:
            assert set(r["objectives"]["after"]) == set(OBJECTIVE_KINDS)
    befores = {}
    for r in rows:
        if r["objectives"] is not None:
            befores.setdefault((r["house"]["name"], r["task"]), []).append(r["objectives"]["before"])
    assert befores and all(all(b == v[0] for b in v) for v in befores.values())
    moved = [r for r in rows if r["objectives"] is not None and r["objectives"]["after"] != r["objectives"]["before"]]
    assert moved, "no measured edit changed any route objective"
    assert any(r["effect"] is not None for r in rows) and any(not r["accepted"] for r in rows)
    # the house reference rebuilds the house exactly
    ref = rows[0]["house"]
    assert house_sha256(tiny.houses[[w.name for w in tiny.worlds].index(ref["name"])]) == ref["sha256"]
    meta = json.loads((out / "meta.json").read_text())
    assert meta["features"] == list(FEATURE_NAMES) and meta["collect"]["candidates"] == CFG.candidates


def test_collection_resumes_and_drops_an_unfinished_house(collected, tiny, tmp_path):
    out, _ = collected
    folder = tmp_path / "d"
    folder.mkdir()
    for name in (ROWS, "houses.jsonl", "meta.json"):
        (folder / name).write_bytes((out / name).read_bytes())
    lines = (folder / "houses.jsonl").read_text().splitlines()
    (folder / "houses.jsonl").write_text(lines[0] + "\n")  # the second house did not finish...
    with open(folder / ROWS, "ab") as f:  # ...and an append was cut short
        f.write(gzip.compress(b'{"torn": ')[:-6])
    ds = Dataset(folder)
    done = ds.start(run_settings(ExpertPolicy(), CFG))
    assert len(done) == 1
    kept = list(iter_rows(folder / ROWS))
    assert len(kept) == CFG.candidates and {r["house"]["name"] for r in kept} == {json.loads(lines[0])["key"].split("#")[1]}
    counts = collect(_pairs(tiny, 2), ExpertPolicy(), CFG, folder)  # finishes the second house only
    assert counts["houses"] == 2 and counts["rows"] == 2 * CFG.candidates
    assert load_rows(folder) == load_rows(out)  # the same rows as the uninterrupted run


def test_collection_with_other_settings_is_refused(collected, tiny):
    out, _ = collected
    with pytest.raises(ConfigError, match="other settings"):
        collect(_pairs(tiny, 1), ExpertPolicy(), CollectConfig(tasks=1, candidates=7, episodes=1, seed=3), out)


def test_collection_of_route_moves_only_and_a_folder_begun_before_the_setting(collected, tiny, tmp_path):
    out, _ = collected
    cfg = CollectConfig(tasks=1, candidates=6, episodes=0, seed=3, random_share=0.0)
    collect(_pairs(tiny, 1), ExpertPolicy(), cfg, tmp_path / "route")
    rows = load_rows(tmp_path / "route")
    assert rows and {r["edit"]["generator"] for r in rows} == {"builtin"}
    assert "random" in {r["edit"]["generator"] for r in load_rows(out)}  # the default draws half random moves
    folder = tmp_path / "old"  # a folder whose meta.json predates random_share continues with its default
    folder.mkdir()
    for name in (ROWS, "houses.jsonl"):
        (folder / name).write_bytes((out / name).read_bytes())
    meta = json.loads((out / "meta.json").read_text())
    del meta["collect"]["random_share"]
    (folder / "meta.json").write_text(json.dumps(meta))
    assert collect(_pairs(tiny, 2), ExpertPolicy(), CFG, folder)["houses"] == 2
    with pytest.raises(ConfigError, match="random_share"):
        collect(_pairs(tiny, 2), ExpertPolicy(), cfg, folder)


def test_train_writes_a_scorer_and_its_card(collected, tmp_path):
    out, _ = collected
    ckpt = tmp_path / "g.pt"
    result = runner.invoke(app, ["gdata", "train", str(out), "-o", str(ckpt), "--epochs", "3", "--heldin", "2"])
    assert result.exit_code == 0, result.output
    card = json.loads(ckpt.with_suffix(".json").read_text())
    assert card["data"]["rows"] == 2 * CFG.candidates and len(card["data"]["heldin_houses"]) == 1
    assert 1 <= card["selection"]["epoch"] <= 3
    scorer = load_scorer(ckpt)
    assert scorer.score(np.zeros((4, len(FEATURE_NAMES)), np.float32)).shape == (4,)


def test_objectives_target_trains_on_rows_without_agent_rollouts(tiny, tmp_path):
    out = tmp_path / "obj"
    cfg = CollectConfig(tasks=2, candidates=8, episodes=0, seed=3)
    collect(_pairs(tiny, 2), ExpertPolicy(), cfg, out)
    rows = load_rows(out)
    assert all(r["effect"] is None for r in rows) and any(r["objectives"] is not None for r in rows)
    ckpt = tmp_path / "g.pt"
    args = ["gdata", "train", str(out), "-o", str(ckpt), "--epochs", "3", "--heldin", "2"]
    result = runner.invoke(app, args)  # the agent target has nothing to learn from
    assert result.exit_code != 0 and "--episodes 1 or more" in str(result.exception) and not ckpt.exists()
    result = runner.invoke(app, [*args, "--target", "objectives"])
    assert result.exit_code == 0, result.output
    card = json.loads(ckpt.with_suffix(".json").read_text())
    assert card["config"]["target"] == "objectives" and "objective gain" in card["selection"]["metric"]
    scorer = load_scorer(ckpt)
    assert scorer.target == "objectives"
    assert scorer.outputs(np.zeros((3, len(FEATURE_NAMES)), np.float32)).shape == (3, 1 + len(OBJECTIVE_KINDS))
    house, ctx, analysis = _context(tiny)
    res = LearnedGenerator(scorer=scorer).generate(house, analysis, steps=2, context=ctx, rng=np.random.default_rng(1))
    assert res.applied and audit(house, res.house).total == 0
    result = runner.invoke(app, [*args, "--target", "regret"])
    assert result.exit_code != 0 and "--target" in str(result.exception)


def test_objective_labels_are_the_weighted_gains_of_the_first_step():
    from adaptenv.adapt.gtrain import objective_labels

    before = {"narrow_passage": 1.0, "lengthen_route": 4.0, "occlude_target": 0.5, "add_clutter": 0.1}
    after = {"narrow_passage": 0.5, "lengthen_route": 6.0, "occlude_target": 0.5, "add_clutter": 0.1}
    row = {"objectives": {"before": before, "after": after},
           "analysis": {"suggestions": {"lengthen_route": 0.9, "narrow_passage": 0.4}}}
    gains, weights = objective_labels(row)
    assert gains == pytest.approx([0.5, 0.5, 0.0, 0.0])  # clearance 0.5 m narrower; route 2 m longer of 4
    assert weights == pytest.approx([0.25 * 0.4, 1.0, 0.0, 0.0])  # the top suggestion at 1, the other by priority
    assert objective_labels({**row, "objectives": None}) is None


def test_shipped_scorer_loads_and_a_corrupt_one_is_refused_in_one_line(tmp_path):
    scorer = load_scorer()
    assert scorer.path == shipped_path() and scorer.meta["data"]["houses"] >= 2
    assert shipped_path().stat().st_size < 400_000
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(ConfigError) as err:
        load_scorer(bad)
    assert "\n" not in str(err.value) and "gdata train" in str(err.value)
    with pytest.raises(ConfigError, match="no such learned-G checkpoint"):
        make_generator("learned", checkpoint=tmp_path / "missing.pt")


def _context(tiny, policy=None):
    from adaptenv.adapt.analysis import analyze_trajectory

    house, world = tiny.houses[0], tiny.worlds[0]
    ep = draw_episode(world, np.random.default_rng(0))
    ctx = GenerationContext(episode=ep, trajectory=rollout(world, ep, ExpertPolicy()), policy=policy, render=False)
    return house, ctx, analyze_trajectory(ctx.trajectory, world)


def test_learned_g_edits_pass_validation_and_the_audit_deterministically(tiny):
    house, ctx, analysis = _context(tiny)
    ep = ctx.episode
    gen = LearnedGenerator()
    runs = [gen.generate(house, analysis, steps=2, context=ctx, rng=np.random.default_rng(5)) for _ in range(2)]
    a, b = runs
    assert [s.edit for s in a.steps] == [s.edit for s in b.steps]
    assert a.applied, [s.reason for s in a.steps]
    assert all(e.accepted and e.changed and e.source == "learned" for e in a.applied)
    assert validate_scene(a.house, episode_targets=[ep.target_type], start=ep.start[:2], original=house) == []
    assert audit(house, a.house).total == 0


def test_lazy_fit_fits_only_the_moves_whose_turn_comes_and_its_edits_pass_the_audit(tiny, monkeypatch):
    import adaptenv.adapt.generators.builtin as builtin
    import adaptenv.adapt.generators.learned as learned

    calls = {"builtin": 0, "learned": 0}

    def counting(where, fit):
        def wrapped(*a, **k):
            calls[where] += 1
            return fit(*a, **k)
        return wrapped

    monkeypatch.setattr(builtin, "fit_rules", counting("builtin", builtin.fit_rules))
    monkeypatch.setattr(learned, "fit_rules", counting("learned", learned.fit_rules))
    house, ctx, analysis = _context(tiny)
    ep = ctx.episode
    gen = LearnedGenerator(lazy_fit=True)
    runs = [gen.generate(house, analysis, steps=2, context=ctx, rng=np.random.default_rng(5)) for _ in range(2)]
    assert [s.edit for s in runs[0].steps] == [s.edit for s in runs[1].steps]
    assert runs[0].applied, [s.reason for s in runs[0].steps]
    assert calls["builtin"] == 0 and 0 < calls["learned"] < 2 * sum(s.candidates for s in runs[0].steps) * 2
    assert validate_scene(runs[0].house, episode_targets=[ep.target_type], start=ep.start[:2], original=house) == []
    assert audit(house, runs[0].house).total == 0
    calls["builtin"] = 0
    LearnedGenerator().generate(house, analysis, steps=1, context=ctx, rng=np.random.default_rng(5))
    assert calls["builtin"] >= 1  # the default fits every route move before scoring


def test_candidate_pool_takes_the_requested_share_of_random_moves(tiny):
    from adaptenv.adapt.generators.edit_features import enumerate_candidates
    from adaptenv.adapt.objectives import RouteSpec
    from adaptenv.sim.world import compile_world

    house, ctx, _ = _context(tiny)
    ep = ctx.episode
    v = EditValidator(house, episode_targets=[ep.target_type], start=ep.start[:2])
    world, route = compile_world(v.house, "c"), RouteSpec.from_episode(ep.target_type, ep.start, ctx.trajectory)
    kinds = {share: [c.kind for c in enumerate_candidates(v, world, route, np.random.default_rng(0), 16,
                                                          random_share=share)] for share in (0.0, 0.5, 1.0)}
    assert set(kinds[1.0]) == {"random"} and len(kinds[1.0]) == 16
    assert kinds[0.5].count("random") >= 8 > kinds[0.0].count("random")
    with pytest.raises(ConfigError, match="random_share"):
        LearnedGenerator(random_share=1.5)


def test_each_candidates_features_are_its_own(tiny):
    """Features computed for a whole pool give each candidate the row it gets alone (the pool's arrays line up)."""
    from adaptenv.adapt.generators.edit_features import (
        Scene,
        candidate_features,
        enumerate_candidates,
    )
    from adaptenv.adapt.objectives import RouteSpec
    from adaptenv.sim.world import compile_world

    house, ctx, _ = _context(tiny)
    ep = ctx.episode
    v = EditValidator(house, episode_targets=[ep.target_type], start=ep.start[:2])
    world, route = compile_world(v.house, "c"), RouteSpec.from_episode(ep.target_type, ep.start, ctx.trajectory)
    scene = Scene.of(v, world, route)
    cands = enumerate_candidates(v, world, route, np.random.default_rng(1), 16, scene=scene)
    pool = candidate_features(v, scene, cands, None)
    assert pool.shape == (16, len(FEATURE_NAMES)) and len({c.kind for c in cands}) >= 2
    for n, c in enumerate(cands):
        assert np.array_equal(pool[n], candidate_features(v, scene, [c], None)[0])
    assert candidate_features(v, scene, [], None).shape == (0, len(FEATURE_NAMES))


def test_a_g_ranked_by_agent_drops_edits_each_object_at_most_once(tiny, collected, tmp_path):
    ckpt = tmp_path / "agent.pt"  # an agent-target scorer: a second move of an object could undo its first
    result = runner.invoke(app, ["gdata", "train", str(collected[0]), "-o", str(ckpt), "--epochs", "2", "--heldin", "2"])
    assert result.exit_code == 0, result.output
    house, ctx, analysis = _context(tiny)
    gen = LearnedGenerator(checkpoint=ckpt, objectives=0)  # one pass: ranked by the scorer alone
    assert gen.scorer.target == "agent" and not gen.repeat
    res = gen.generate(house, analysis, steps=4, context=ctx, rng=np.random.default_rng(2))
    moved = [e.object_id for e in res.applied]
    assert len(moved) >= 2 and len(set(moved)) == len(moved)
    # ranked by route-objective gains (the shipped scorer, or measured), an object may be moved again
    assert LearnedGenerator().repeat and LearnedGenerator(checkpoint=ckpt, objectives=2).repeat


def test_learned_g_with_checks_makes_the_edit_the_agent_fails_on(tiny, monkeypatch):
    from types import SimpleNamespace

    import adaptenv.adapt.generators.learned as learned

    shown = []

    def fake_runs(worlds, episodes, policy):  # the agent fails only in the second world it is shown
        shown.append(worlds)
        return [[SimpleNamespace(metrics=SimpleNamespace(success=w != 1, spl=0.5), steps=[0] * 7) for _ in episodes]
                for w in range(len(worlds))]

    monkeypatch.setattr(learned, "run_in_worlds", fake_runs)
    house, ctx, analysis = _context(tiny, ExpertPolicy())
    plain = LearnedGenerator(objectives=0).generate(house, analysis, steps=1, context=ctx, rng=np.random.default_rng(2))
    checked = LearnedGenerator(checks=3).generate(house, analysis, steps=1, context=ctx, rng=np.random.default_rng(2))
    step = checked.steps[0]
    assert len(shown) == 1 and len(shown[0]) == step.checked == 3
    assert step.check_steps == 3 * ctx.rollout_episodes * 7 and "hardest for the agent" in step.reason
    assert plain.steps[0].checked == 0 and plain.applied[0].object_id != checked.applied[0].object_id
    with pytest.raises(ConfigError, match="checks 99"):
        LearnedGenerator(checks=99)


def test_learned_g_with_objectives_makes_the_edit_with_the_largest_objective_gain(tiny, monkeypatch):
    import adaptenv.adapt.generators.learned as learned
    from adaptenv.adapt.objectives import ObjectiveValues

    calls = []

    def fake_measure(world, route):  # the scene first, then each passed edit; only the second passed edit is harder
        calls.append(world)
        hard = len(calls) == 3
        return ObjectiveValues(narrow_passage=0.5 if hard else 1.0, lengthen_route=8.0 if hard else 5.0,
                               occlude_target=0.2 if hard else 0.5, add_clutter=0.4 if hard else 0.1)

    def no_rollout(*a, **k):
        raise AssertionError("objectives must not roll the agent out")

    monkeypatch.setattr(learned, "measure", fake_measure)
    monkeypatch.setattr(learned, "run_in_worlds", no_rollout)
    house, ctx, analysis = _context(tiny, ExpertPolicy())
    assert analysis.suggestions
    plain = LearnedGenerator(objectives=0).generate(house, analysis, steps=1, context=ctx, rng=np.random.default_rng(2))
    calls.clear()
    chosen = LearnedGenerator(objectives=3).generate(house, analysis, steps=1, context=ctx,
                                                     rng=np.random.default_rng(2))
    assert len(calls) == 4 and "largest objective gain of the 3" in chosen.steps[0].reason
    assert chosen.steps[0].attempts > plain.steps[0].attempts  # the second that passed, not the first
    assert LearnedGenerator().objectives == OBJECTIVES and LearnedGenerator(checks=2).objectives == 0
    with pytest.raises(ConfigError, match="at most one"):
        LearnedGenerator(checks=2, objectives=2)
    with pytest.raises(ConfigError, match="objectives 99"):
        LearnedGenerator(objectives=99)


def test_adapt_with_the_learned_generator_end_to_end(tiny, tmp_path):
    from adaptenv.scene.house import save_house

    path = save_house(tiny.houses[1], tmp_path / "h.json")
    out = tmp_path / "out"
    result = runner.invoke(app, ["adapt", str(path), "--generator", "learned", "--policy", "expert", "--steps", "2",
                                 "--seed", "1", "-o", str(out)])
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["generator"] == "learned" and summary["valid"] and summary["edits_applied"] >= 1
    assert sum(summary["plausibility"].values()) == 0


def test_adapt_learned_checks_rolls_the_policy_out_on_k_edits(tiny, tmp_path, monkeypatch):
    import adaptenv.adapt.generators.learned as learned
    from adaptenv.scene.house import save_house

    shown = []
    real = learned.run_in_worlds

    def spy(worlds, episodes, policy):
        shown.append(len(worlds))
        return real(worlds, episodes, policy)

    monkeypatch.setattr(learned, "run_in_worlds", spy)
    path = save_house(tiny.houses[1], tmp_path / "h.json")
    args = ["adapt", str(path), "--policy", "expert", "--steps", "2", "--seed", "1"]
    result = runner.invoke(app, [*args, "--generator", "learned", "--learned-checks", "2", "-o", str(tmp_path / "a")])
    assert result.exit_code == 0, result.output
    assert shown and set(shown) == {2}
    result = runner.invoke(app, [*args, "--learned-checks", "2", "-o", str(tmp_path / "b")])
    assert result.exit_code != 0 and "--learned-checks" in str(result.exception) and not (tmp_path / "b").exists()


def test_adapt_and_the_loop_rank_edits_with_a_scorer_file_given(tiny, tmp_path):
    import shutil

    from adaptenv.curriculum.jobs import make_fg
    from adaptenv.curriculum.methods import LoopConfig
    from adaptenv.scene.house import save_house

    path = save_house(tiny.houses[1], tmp_path / "h.json")
    mine, bad = tmp_path / "mine.pt", tmp_path / "bad.pt"
    shutil.copyfile(shipped_path(), mine)
    bad.write_bytes(b"not a checkpoint")
    args = ["adapt", str(path), "--policy", "expert", "--steps", "1", "--seed", "1"]
    result = runner.invoke(app, [*args, "--generator", "learned", "--learned-scorer", str(mine), "-o", str(tmp_path / "a")])
    assert result.exit_code == 0, result.output
    assert json.loads((tmp_path / "a" / "summary.json").read_text())["learned_scorer"] == str(mine)
    result = runner.invoke(app, [*args, "--generator", "learned", "--learned-scorer", str(bad), "-o", str(tmp_path / "b")])
    assert isinstance(result.exception, ConfigError) and "\n" not in str(result.exception)
    assert str(bad) in str(result.exception) and not (tmp_path / "b").exists()
    result = runner.invoke(app, [*args, "--learned-scorer", str(mine), "-o", str(tmp_path / "c")])
    assert isinstance(result.exception, ConfigError) and "--learned-scorer" in str(result.exception)
    _, g = make_fg("learned", {}, learned_scorer=str(mine))
    assert g.scorer.path == mine and make_fg("learned", {})[1].scorer.path == shipped_path()
    LoopConfig(method="ours-learned", learned_scorer=str(mine)).check()
    with pytest.raises(ConfigError, match="not a readable torch checkpoint"):
        LoopConfig(method="ours-learned", learned_scorer=str(bad)).check()
    with pytest.raises(ConfigError, match="learned_scorer applies to ours-learned"):
        LoopConfig(method="ours", learned_scorer=str(mine)).check()


def test_collect_refuses_held_out_houses(tmp_path):
    result = runner.invoke(app, ["gdata", "collect", "--houses", "suite:large", "-o", str(tmp_path / "x")])
    assert isinstance(result.exception, ConfigError) and "not training data" in str(result.exception)


def test_collect_command_takes_the_share_of_random_moves(tmp_path):
    from adaptenv.scene.house import save_house
    from adaptenv.scene.procedural.presets import generate_preset

    # tiny_0001: the built-in G has 4 route moves a person believes there (random moves fill what it lacks)
    house = save_house(generate_preset("tiny")[1][1], tmp_path / "tiny_0001.json")
    args = ["gdata", "collect", "--houses", str(house), "--limit", "1", "--tasks", "1", "--candidates", "4",
            "--episodes", "0", "--policy", "expert", "-o", str(tmp_path / "route")]
    result = runner.invoke(app, [*args, "--random-share", "0"])
    assert result.exit_code == 0, result.output
    assert json.loads((tmp_path / "route" / "meta.json").read_text())["collect"]["random_share"] == 0.0
    assert {r["edit"]["generator"] for r in load_rows(tmp_path / "route")} == {"builtin"}
    result = runner.invoke(app, [*args[:-1], str(tmp_path / "bad"), "--random-share", "1.5"])
    assert result.exit_code == 2 and "--random-share" in result.output and not (tmp_path / "bad").exists()


def test_chosen_drop_scores_the_edit_the_g_would_make():
    from adaptenv.adapt.gtrain import Arrays, chosen_drop

    # two tasks; in task 0 the best-scored candidate is unusable, so the G makes the second-best one
    a = Arrays(x=np.zeros((5, 1), np.float32), usable=np.array([0, 1, 1, 1, 1], np.float32),
               drops=np.array([[1, 1], [0, 0.2], [0, 0.1], [0, 0.3], [0, -0.1]], np.float32),
               measured=np.ones(5, np.float32), weights=np.ones((5, 2), np.float32), group=np.array([0, 0, 0, 1, 1]),
               heldin=np.ones(5, bool))
    got = chosen_drop(np.array([9.0, 2.0, 1.0, 0.0, 5.0]), a, a.heldin)
    assert got["groups"] == 2
    assert got["chosen"] == pytest.approx((0.2 - 0.1) / 2) and got["best"] == pytest.approx((0.2 + 0.3) / 2)
    assert got["random"] == pytest.approx((0.15 + 0.1) / 2)
