"""The closed loop: every method runs under the budget, records are written, a killed run resumes exactly."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from adaptenv.curriculum.loop import METHODS, LoopConfig, finetune_config, run_loop
from adaptenv.curriculum.records import STATE, read_iterations
from adaptenv.errors import ConfigError
from tests.curriculum.loops import SHARES_RUNS, figures, tiny_config

ROOMY = ("ours", "ours-randomscene", "ours-nof", "ours-dr", "ours-learned")
"""Methods checked with a buffer no level is evicted from, so every scored and adapted scene is in it."""


def method_config(policy: Path, method: str) -> LoopConfig:
    """The two-iteration run of ``method`` that several tests read (the loop_run fixture runs it once)."""
    return tiny_config(policy, method, **({"buffer_capacity": 16} if method in ROOMY else {}))


def test_config_errors_name_the_field():
    with pytest.raises(ConfigError, match="method 'nope' is unknown"):
        LoopConfig(method="nope").check()
    with pytest.raises(ConfigError, match="ours-llm needs an llm section"):
        LoopConfig(method="ours-llm").check()
    with pytest.raises(ConfigError, match="iterations must be at least 1"):
        LoopConfig(iterations=0).check()
    with pytest.raises(ConfigError, match="finetune_teacher 'oracle' is unknown"):
        LoopConfig(finetune_teacher="oracle").check()
    with pytest.raises(ConfigError, match="finetune_beta"):
        LoopConfig(finetune_beta=1.5).check()
    with pytest.raises(ConfigError, match="finetune_max_steps"):
        LoopConfig(finetune_max_steps=0).check()


def test_the_fine_tuning_recipe_carries_the_loop_settings():
    cfg = LoopConfig(finetune_algo="dagger", finetune_frames=4096, finetune_envs=16, finetune_lr=3e-4, finetune_teacher="explorer",
                     finetune_min_start=6.0, finetune_beta=0.5, finetune_max_steps=600).check()
    ft = finetune_config(cfg, end_threshold=0.7)
    assert (ft.frames, ft.num_envs, ft.learning_rate, ft.teacher, ft.end_threshold, ft.min_start_distance,
            ft.beta, ft.max_episode_steps) == (4096, 16, 3e-4, "explorer", 0.7, 6.0, 0.5, 600)
    with pytest.raises(ConfigError, match="finetune_min_start"):
        LoopConfig(finetune_min_start=-1.0).check()


@pytest.mark.slow
@pytest.mark.parametrize("method", [pytest.param(m, marks=SHARES_RUNS) if m in ("ours", "dr", "accel") else m
                                    for m in METHODS if m not in ("ours-llm", "dr-matched")])
def test_every_method_runs_and_counts_its_budget(method, tiny_policy, loop_run):
    cfg = method_config(tiny_policy, method)
    records, run = loop_run(cfg)
    assert [r.iteration for r in records] == [0, 1, 2]
    assert records[0].env_steps == 0 and records[0].heldout["tiny"].episodes == 3
    # identical gradient updates and fine-tuning frames across methods; steps only grow
    assert records[2].grad_updates == 2 * records[1].grad_updates > 0
    assert records[1].env_steps > cfg.finetune_frames and records[2].env_steps > records[1].env_steps
    if method in ("random", "accel") or method.startswith("ours"):
        assert records[2].edits > 0
    else:
        assert records[2].edits == 0
    assert read_iterations(run) == records
    for r in records[1:]:  # where the time went, for docs/BENCHMARKS.md
        assert set(r.stage_seconds) == {"rollouts", "scenes", "finetune", "evaluate"}
        assert 0 < sum(r.stage_seconds.values()) <= r.wall_time_s + 0.05
    scenes = json.loads((run / "iter_0002" / "scenes.json").read_text())
    assert scenes["trained_on"], "every iteration fine-tunes on some scenes"
    heldout = run / "iter_0002" / "heldout" / "tiny"
    houses = (heldout / "houses.csv").read_text().splitlines()
    assert houses[0].startswith("house,episodes,success") and len(houses) > 1, "per-house held-out table for the report"
    failed = json.loads((heldout / "summary.json").read_text())["success"] < 1.0
    assert (heldout / "failures.png").is_file() == failed, "failed held-out episodes are drawn for the report"
    if method in ("plr", "accel"):
        assert any(x.startswith("dr") for x in scenes["rolled_out"]), "fresh houses are scored each iteration"
        state = json.loads((run / STATE).read_text())["state"]
        buffered = set(state["buffer"]["level_ids"])
        assert set(scenes["trained_on"]) <= buffered, "robust PLR/ACCEL train on replayed buffer levels only"
    if method == "sfl":
        fresh = [x for x in scenes["rolled_out"] if x.startswith("dr")]
        assert len(fresh) == cfg.sfl_candidates * cfg.scenes_per_iteration, "sfl scores its candidates"
        new = [x for x in scenes["trained_on"] if x in fresh]
        assert len(new) == cfg.scenes_per_iteration, "and trains on the most learnable of them"
    if method == "ours-dr":
        fresh = [x for x in scenes["rolled_out"] if x.startswith("dr")]
        assert fresh and set(fresh) <= set(scenes["trained_on"]), "ours-dr trains on every fresh house, as dr does"
    if method in ("ours", "ours-randomscene", "ours-nof", "ours-dr"):
        state = json.loads((run / STATE).read_text())["state"]
        assert any(x.startswith("dr") for x in scenes["rolled_out"]), "fresh houses are scored each iteration"
        assert set(scenes["rolled_out"]) <= set(state["buffer"]["level_ids"]), "scored scenes go into the buffer"
        assert scenes["replayed"] and set(scenes["replayed"]) <= set(state["buffer"]["level_ids"]), \
            "adapted scenes come from the buffer"
        trained = {t: json.loads((run / f"iter_{t:04d}" / "scenes.json").read_text())["trained_on"]
                   for t in (1, 2)}  # G may find no plausible edit in a given iteration's scenes
        assert any(f"~t{t:02d}" in x for t in trained for x in trained[t]), "fine-tuning uses the iteration's children"
        assert any(p is not None for p in state["buffer"]["parent_ids"]), "children are scored into the buffer"
    if method.startswith("ours"):
        item = records[1].gallery[0]
        for rel in (item.before_png, item.after_png, item.analysis_json, item.edits_json):
            assert (run / rel).is_file()


@pytest.mark.slow
@pytest.mark.parametrize("method", ["ours", "plr", "accel"])
def test_an_unseeded_buffer_never_holds_the_training_scenes(method, tiny_policy, tmp_path):
    cfg = tiny_config(tiny_policy, method, seed_buffer=False, buffer_capacity=16)
    run_loop(cfg, tmp_path / method)
    state = json.loads((tmp_path / method / STATE).read_text())["state"]
    training = set(state["pool"])
    buffered = set(state["buffer"]["level_ids"])
    assert buffered and not buffered & training, "the buffer holds generated scenes only"
    assert all(x.split("~")[0].startswith("dr") for x in buffered), "fresh houses and their children"
    for t in (1, 2):
        scenes = json.loads((tmp_path / method / f"iter_{t:04d}" / "scenes.json").read_text())
        assert not set(scenes["rolled_out"]) & training and not set(scenes["trained_on"]) & training


def test_loop_config_refuses_ppo_settings_that_do_not_apply():
    with pytest.raises(ConfigError, match="finetune_algo"):
        LoopConfig(finetune_algo="sac").check()
    with pytest.raises(ConfigError, match="ppo only"):
        LoopConfig(finetune_algo="dagger", finetune_kl_coef=0.3).check()
    with pytest.raises(ConfigError, match="finetune_bc_coef apply to ppo only"):
        LoopConfig(finetune_algo="dagger", finetune_freeze_encoder=True).check()
    with pytest.raises(ConfigError, match="finetune_bc_coef apply to ppo only"):
        LoopConfig(finetune_algo="dagger", finetune_bc_coef=0.1).check()
    LoopConfig(finetune_algo="dagger").check()  # ppo's settings at their defaults (the default algo's) or off
    LoopConfig(finetune_algo="dagger", finetune_kl_coef=0.0, finetune_explore_bonus=0.0).check()
    LoopConfig(finetune_kl_coef=0.3, finetune_freeze_encoder=True, finetune_bc_coef=0.1).check()
    with pytest.raises(ConfigError, match="finetune_beta and finetune_teacher apply to dagger"):
        LoopConfig(finetune_teacher="map-explorer").check()  # the default algo is ppo, which would ignore it
    with pytest.raises(ConfigError, match="set finetune_algo to dagger"):
        LoopConfig(finetune_beta=0.5).check()
    LoopConfig(finetune_teacher="map-explorer", finetune_bc_coef=0.1).check()
    with pytest.raises(ConfigError, match="finetune_precision must be one of auto, fp32, bf16"):
        LoopConfig(finetune_algo="ppo", finetune_precision="fp16").check()
    with pytest.raises(ConfigError, match="level_score"):
        LoopConfig(level_score="novelty").check()
    cfg = finetune_config(LoopConfig(finetune_algo="ppo", finetune_kl_coef=0.3, finetune_explore_bonus=0.002,
                                     finetune_max_steps=600, finetune_freeze_encoder=True,
                                     finetune_precision="bf16", finetune_bc_coef=0.1,
                                     finetune_teacher="map-explorer"), end_threshold=0.7)
    assert (cfg.algo, cfg.kl_coef, cfg.explore_bonus, cfg.max_episode_steps, cfg.freeze_encoder, cfg.precision,
            cfg.bc_coef, cfg.teacher) == ("ppo", 0.3, 0.002, 600, True, "bf16", 0.1, "map-explorer")


@pytest.mark.slow
def test_the_loop_fine_tunes_by_anchored_ppo(tiny_policy, tmp_path, monkeypatch):
    from adaptenv.agents import ppo, train

    cards = []
    real = ppo.train_ppo

    def spy(pc, **kw):
        result = real(pc, **kw)
        cards.append(result.card)
        return result

    monkeypatch.setattr(ppo, "train_ppo", spy)
    monkeypatch.setattr(train, "train_ppo", spy)  # the loop fine-tunes through agents.train
    # a budget under one full rollout: one PPO iteration of 16 agents x 32 steps (the fresh critic's warm-up)
    cfg = tiny_config(tiny_policy, "dr", iterations=1, finetune_algo="ppo", finetune_frames=16 * 32,
                      finetune_kl_coef=0.3, finetune_explore_bonus=0.002, finetune_max_steps=600,
                      finetune_freeze_encoder=True)
    records = run_loop(cfg, tmp_path / "ppo")
    assert records[1].grad_updates > 0 and records[1].env_steps >= cfg.finetune_frames
    [card] = cards
    assert card["algo"] == "ppo" and card["torch_threads"] == 1
    assert card["frames"] == cfg.finetune_frames and card["config"]["rollout_steps"] == 32
    assert {k: card["config"][k] for k in ("kl_coef", "explore_bonus", "max_episode_steps", "freeze_encoder")} == \
        {"kl_coef": 0.3, "explore_bonus": 0.002, "max_episode_steps": 600, "freeze_encoder": True}


@pytest.mark.slow
@pytest.mark.parametrize("keep", [True, False])
def test_ppo_fine_tuning_continues_its_critic_across_iterations(tiny_policy, tmp_path, monkeypatch, keep):
    import torch

    from adaptenv.agents import ppo, train
    from adaptenv.curriculum.loop import LEARNER_FILE

    given, real = [], ppo.train_ppo

    def spy(pc, **kw):
        given.append((kw.get("learner"), pc.value_warmup_iters))
        return real(pc, **kw)

    monkeypatch.setattr(ppo, "train_ppo", spy)
    monkeypatch.setattr(train, "train_ppo", spy)  # the loop fine-tunes through agents.train
    cfg = tiny_config(tiny_policy, "dr", iterations=2, finetune_algo="ppo", finetune_frames=2 * 16 * 128,
                      finetune_kl_coef=0.3, finetune_keep_learner=keep)
    run_loop(cfg, tmp_path / "r")
    saved = [tmp_path / "r" / f"iter_{t:04d}" / LEARNER_FILE for t in (1, 2)]
    assert [p.is_file() for p in saved] == [keep, keep]
    assert given[0] == (None, 1), "the first iteration starts a fresh critic with a value warm-up"
    if keep:
        first = torch.load(saved[0], weights_only=True)
        assert given[1][1] == 0 and all(torch.equal(v, given[1][0]["value"][k]) for k, v in first["value"].items())
    else:
        assert given[1] == (None, 1)


@pytest.mark.slow
@SHARES_RUNS
def test_dr_matched_spends_the_environment_steps_of_the_run_it_matches(tiny_policy, loop_run, tmp_path):
    ours, ours_run = loop_run(method_config(tiny_policy, "ours"))
    cfg = tiny_config(tiny_policy, "dr-matched", iterations=2, match_run=str(ours_run))
    matched = run_loop(cfg, tmp_path / "matched")
    plain, _ = loop_run(method_config(tiny_policy, "dr"))
    block = cfg.finetune_envs * 32  # fine-tuning collects whole blocks of agents x rollout steps
    assert ours[2].env_steps > plain[2].env_steps, "ours spends steps beyond fine-tuning (diagnosis, G's checks)"
    for t in (1, 2):
        assert abs(matched[t].env_steps - ours[t].env_steps) < block, "equal environment steps, iteration by iteration"
    assert matched[2].grad_updates > plain[2].grad_updates, "the extra steps become extra fine-tuning"


def test_dr_matched_needs_the_run_it_matches(tmp_path):
    from adaptenv.curriculum.experiment import ExperimentConfig
    from adaptenv.curriculum.methods import matched_steps

    with pytest.raises(ConfigError, match="match_run"):
        LoopConfig(method="dr-matched").check()
    with pytest.raises(ConfigError, match="no such run folder"):
        matched_steps(tmp_path / "missing", 1)
    (tmp_path / "empty").mkdir()
    with pytest.raises(ConfigError, match="iteration 1 did not finish"):
        matched_steps(tmp_path / "empty", 1, wait_s=0.0)
    with pytest.raises(ConfigError, match="list ours before dr-matched"):
        ExperimentConfig(methods=["dr-matched", "ours"], seeds=[0]).check()
    cfg = ExperimentConfig(methods=["ours", "dr-matched"], seeds=[3])
    assert cfg.check().loop_config("dr-matched", 3, tmp_path).match_run == str(tmp_path / "ours" / "seed_3")


@pytest.mark.slow
def test_ours_edits_already_edited_scenes_again(tiny_policy, tmp_path):
    """Edits compound across iterations, as ACCEL's do: a child in the buffer is picked and edited into a grandchild."""
    cfg = tiny_config(tiny_policy, "ours", iterations=2, seed_buffer=False, buffer_capacity=4)
    run_loop(cfg, tmp_path)
    second = json.loads((tmp_path / "iter_0002" / "scenes.json").read_text())
    edited_again = [x for x in second["replayed"] if "~t01" in x]
    assert edited_again, "seed 0 picks an iteration-1 child at t=2"
    grandchildren = [c for c, p in second["parents"].items() if p in edited_again]
    assert grandchildren and set(grandchildren) & set(second["trained_on"]), "its child is trained on"
    assert all(p in second["replayed"] for p in second["parents"].values()), "every child names its parent"


@SHARES_RUNS
def test_same_seed_same_results(tiny_policy, loop_run, tmp_path):
    """A fresh run repeats the shared one (which other tests' runs came before): what loop_run relies on."""
    cfg = tiny_config(tiny_policy, "ours", iterations=1)
    a, _ = loop_run(cfg)
    b = run_loop(cfg, tmp_path / "b")
    assert figures(a) == figures(b)


@pytest.mark.slow
@SHARES_RUNS
@pytest.mark.parametrize("method", ["ours", "accel"])
def test_a_process_pool_gives_the_same_results_as_in_process(method, tiny_policy, loop_run, tmp_path):
    from adaptenv.curriculum.executor import make_executor

    cfg = tiny_config(tiny_policy, method)  # a buffer of 4 evicts levels; accel's run is test_every_method's
    local, local_run = loop_run(cfg)
    with make_executor("process", workers=2) as ex:
        pooled = run_loop(cfg, tmp_path / "pool", executor=ex)
    assert figures(pooled) == figures(local)
    assert records_scenes(tmp_path / "pool") == records_scenes(local_run)


def records_scenes(run: Path) -> list[tuple[str, str]]:
    """Every scene file of a run with its content, so generation in workers is compared too."""
    return [(p.name, p.read_text()) for p in sorted((run / "scenes").glob("*.json"))]


def test_refuses_a_non_empty_folder_without_resume(tiny_policy, tmp_path):
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "something").write_text("1")
    with pytest.raises(ConfigError, match="not empty"):
        run_loop(tiny_config(tiny_policy, "none"), tmp_path / "x")


def test_resume_takes_fields_added_since_the_run_as_defaults_and_refuses_other_changes(tiny_policy, tmp_path):
    cfg = tiny_config(tiny_policy, "none", iterations=1)
    first = run_loop(cfg, tmp_path / "r")
    state = json.loads((tmp_path / "r" / STATE).read_text())
    del state["config"]["relocate_targets"]  # as written before the field existed
    (tmp_path / "r" / STATE).write_text(json.dumps(state))
    assert figures(run_loop(cfg, tmp_path / "r", resume=True)) == figures(first)
    with pytest.raises(ConfigError, match=r"other settings than the interrupted run: relocate_targets \(was False, now True\)"):
        run_loop(tiny_config(tiny_policy, "none", iterations=1, relocate_targets=True), tmp_path / "r", resume=True)


def test_a_run_matched_in_a_moved_experiment_folder_resumes(tiny_policy, tmp_path):
    # dr-matched's match_run is OUT/<method>/seed_<seed>: a packed copy elsewhere names the same run
    run_loop(tiny_config(tiny_policy, "none", iterations=1, match_run="/old/exp/ours/seed_0"), tmp_path / "r")
    moved = tiny_config(tiny_policy, "none", iterations=1, match_run=str(tmp_path / "copy" / "ours" / "seed_0"))
    assert len(run_loop(moved, tmp_path / "r", resume=True)) == 2
    with pytest.raises(ConfigError, match=r"match_run \(was '/old/exp/ours/seed_0'"):
        run_loop(tiny_config(tiny_policy, "none", iterations=1, match_run="/old/exp/ours/seed_1"), tmp_path / "r",
                 resume=True)


def test_focus_training_saves_the_aimed_target_type_of_each_adapted_scene(tiny_policy, tmp_path):
    from adaptenv.curriculum.records import TASKS, SceneStore

    run_loop(tiny_config(tiny_policy, "ours-dr", iterations=1, focus_training=True), tmp_path / "r")
    tasks = sorted((tmp_path / "r" / "scenes" / TASKS).glob("*.json"))
    assert tasks, "an adapted scene records its task"
    store = SceneStore(tmp_path / "r" / "scenes")
    for p in tasks:
        world = store.world(p.stem)
        assert len(world.task_targets) == 1 and world.task_targets[0] in world.object_types
        before = tmp_path / "r" / "iter_0001" / "gallery" / p.stem / "trajectory_before.json"
        if before.is_file():  # the worst diagnosed episode, whose route G's edits aimed at
            assert json.loads(before.read_text())["target_type"] == world.task_targets[0]
    assert all("rooms" in json.loads(p.read_text()) for p in (tmp_path / "r" / "scenes").glob("*.json")), \
        "the scenes folder holds only houses (usable as --houses)"


@pytest.mark.slow
@SHARES_RUNS
def test_a_killed_run_resumes_to_the_same_results(tiny_policy, loop_run, tmp_path):
    """Kill a run (SIGKILL) right after its first iteration is checkpointed, resume it, compare."""
    cfg = tiny_config(tiny_policy, "ours")  # its buffer evicts levels, so the resumed buffer must too
    reference, _ = loop_run(cfg)

    killed = tmp_path / "killed"
    script = ("import sys, json; from adaptenv.curriculum.loop import LoopConfig, run_loop; "
              "run_loop(LoopConfig(**json.loads(sys.argv[1])), sys.argv[2])")
    from dataclasses import asdict

    proc = subprocess.Popen([sys.executable, "-c", script, json.dumps(asdict(cfg)), str(killed)],
                            env={**os.environ, "PYTHONHASHSEED": "0"})
    deadline = time.monotonic() + 600
    try:
        while time.monotonic() < deadline:
            state = killed / STATE
            if state.is_file() and json.loads(state.read_text())["state"]["iteration"] >= 1:
                break
            if proc.poll() is not None:
                pytest.fail("the run ended before it could be killed")
            time.sleep(0.05)
        else:
            pytest.fail("the run did not finish its first iteration in time")
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait(timeout=60)
    assert json.loads((killed / STATE).read_text())["state"]["iteration"] < cfg.iterations
    resumed = run_loop(cfg, killed, resume=True)
    assert figures(resumed) == figures(reference)


def test_door_edits_reach_the_failure_mode_generator(tiny_policy, tmp_path, monkeypatch):
    from adaptenv.curriculum import jobs

    seen, make_fg = [], jobs.make_fg

    def recording(kind, llm, **kw):
        analyzer, generator = make_fg(kind, llm, **kw)
        seen.append((kind, getattr(generator, "door_edits", None)))
        return analyzer, generator

    monkeypatch.setattr(jobs, "make_fg", recording)
    run_loop(tiny_config(tiny_policy, "ours-dr", iterations=1, door_edits=True), tmp_path / "r")
    assert seen and all(s == ("failure-modes", True) for s in seen)


def test_evaluation_jobs_refill_their_slots_and_change_no_episode():
    """A job's finished slots take its next episodes; every episode ends as it does in a batch of its own chunk."""
    from adaptenv.agents.evaluate import run_episodes, sample_episodes
    from adaptenv.agents.registry import resolve_policy
    from adaptenv.curriculum.jobs import EVAL_BATCH, EvalJob, heldout_set, run_eval
    from adaptenv.curriculum.loop import PolicyWeights

    policy = resolve_policy("pretrained")
    n = 2 * EVAL_BATCH + 7
    results, _ = run_eval(EvalJob(PolicyWeights.of(policy), "preset:tiny", 3, 0, n))
    worlds = heldout_set("preset:tiny").worlds
    eps = sample_episodes(worlds, n, 3)
    alone = [r for a in range(0, n, EVAL_BATCH)
             for r in run_episodes(worlds, eps[a:a + EVAL_BATCH], policy, batch=EVAL_BATCH)[0]]
    assert [(r.success, r.steps, r.spl, r.collisions) for r in results] == \
        [(r.success, r.steps, r.spl, r.collisions) for r in alone]


def test_run_json_records_the_precision_used_and_an_fp32_run_resumes_under_auto(tiny_policy, tmp_path, monkeypatch):
    from adaptenv.agents import network

    monkeypatch.setattr(network, "auto_precision", lambda: "fp32")  # an AVX2-only CPU
    cfg = tiny_config(tiny_policy, "none", iterations=1, finetune_precision="fp32")
    first = run_loop(cfg, tmp_path / "r")
    assert json.loads((tmp_path / "r" / "run.json").read_text())["finetune_precision"] == "fp32"
    auto = tiny_config(tiny_policy, "none", iterations=1)  # the default, auto: the same steps on this CPU
    assert auto.finetune_precision == "auto"
    assert figures(run_loop(auto, tmp_path / "r", resume=True)) == figures(first)
    with pytest.raises(ConfigError, match=r"finetune_precision \(was 'fp32', now 'bf16'\)"):
        run_loop(tiny_config(tiny_policy, "none", iterations=1, finetune_precision="bf16"), tmp_path / "r", resume=True)


def test_every_iteration_says_what_g_made_and_why_fewer(tiny_policy, tmp_path):
    lines: list[str] = []
    run_loop(tiny_config(tiny_policy, "ours", iterations=1, edit_steps=2), tmp_path / "r", progress=lines.append)
    [made] = [x for x in lines if x.startswith("t=1: G made")]
    scenes = json.loads((tmp_path / "r" / "iter_0001" / "scenes.json").read_text())
    assert made.startswith(f"t=1: {scenes['generation']} (") and made.endswith(" s)")
    assert scenes["edits_requested"] == 4 and f"G made {scenes['edits_this_iteration']} of 4 edits" in made
    assert scenes["edits_this_iteration"] > 0, "the failure-mode G edits whether or not F finds a failure"
    if scenes["edits_this_iteration"] < 4:
        assert "fewer because: " in made
    lines.clear()
    run_loop(tiny_config(tiny_policy, "none", iterations=1), tmp_path / "n", progress=lines.append)
    assert any(x.startswith("t=1: none makes no edits") for x in lines)
