"""Numbers, checkpoints, trajectories, asset tables and run folders as a hostile user writes them.

Each case goes through the real CLI and ends in exit code 1 and exactly one line on stderr that names the flag,
file or field, with no traceback, before any work where it can be checked first; the silent-nonsense cases
(a trajectory off its house, NaN weights, a 20,000-object render) are refused or bounded.
"""

from __future__ import annotations

import json
import shutil
import sys
from dataclasses import asdict
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from adaptenv.cli import app, main
from adaptenv.errors import AdaptenvError

HOUSE = str(Path(__file__).parent / "data" / "procthor-10k-train-1.json")
TINY = ["--houses", "preset:tiny", "--num-envs", "4", "--rollout-steps", "16", "--chunk-len", "8",
        "--batch-chunks", "2", "--updates-per-iter", "1", "--buffer-frames", "64", "--calibrate-episodes", "0",
        "--eval-every", "0", "--final-eval-episodes", "0", "--threads", "1", "--no-tensorboard", "--no-progress"]
"""`adaptenv train` settings of a one-block (64-frame) run."""
TINY_NET = ["--hidden", "32", "--feature-dim", "32"]


class WorkStarted(Exception):
    """Raised by a stand-in for the expensive part of a command: the command got past its checks."""


def refuse_work(*args, **kwargs):
    raise WorkStarted


def one_line(monkeypatch, capsys, *args) -> str:
    """Run ``adaptenv ARGS`` as the console does; assert exit 1 and one error line on stderr; return it."""
    monkeypatch.setattr(sys, "argv", ["adaptenv", *map(str, args)])
    with pytest.raises(SystemExit) as exit_info:
        main()
    err = capsys.readouterr().err
    assert exit_info.value.code == 1, err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in err, err
    return lines[0]


def refused(*args) -> str:
    """Run ``adaptenv ARGS`` in-process; assert it ended in one adaptenv error of one line; return the message."""
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert isinstance(result.exception, AdaptenvError), (result.exception, result.output)
    text = str(result.exception)
    assert "\n" not in text and "Traceback" not in text
    return text


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    """Default outputs (runs/...) land in the test's folder."""
    monkeypatch.chdir(tmp_path)


# -- numbers on the command line ------------------------------------------------------------------

NUMBERS = [
    (["evaluate", "--houses", "preset:tiny", "--seed", "-1"], "--seed -1"),
    (["evaluate", "--houses", "preset:tiny", "-s", str(2**64 + 1)], f"--seed {2**64 + 1}"),
    (["rollout", HOUSE, "--seed", "-1", "-o", "t.json"], "--seed -1"),
    (["train", "--houses", "preset:tiny", "--seed", "-1"], "--seed -1"),
    (["ppo", "--houses", "preset:tiny", "--seed", str(2**32)], f"--seed {2**32}"),
    (["adapt", HOUSE, "--seed", "-1", "-o", "a"], "--seed -1"),
    (["memory-check", "--houses", "preset:tiny", "-s", "-1"], "--seed -1"),
    (["loop", "--seed", "-1", "-o", "l"], "--seed -1"),
    (["demo", "--seed", "-1", "-o", "d"], "--seed -1"),
    (["houses", "generate", "--n", "1", "--seed", "-1", "-o", "h"], "--seed -1"),
    (["evaluate", "--houses", "preset:tiny", "-n", "99999999999999999999"], "--episodes 99999999999999999999"),
    (["memory-check", "--houses", "preset:tiny", "-n", "0"], "--episodes 0"),
    (["loop", "--heldout-episodes", "99999999999999999999", "-o", "l"], "--heldout-episodes 99999999999999999999"),
    (["train", "--houses", "preset:tiny", "--num-envs", "0"], "--num-envs 0"),
    (["train", "--houses", "preset:tiny", "--learning-rate", "nan"], "--learning-rate nan"),
    (["train", "--houses", "preset:tiny", "--learning-rate", "inf"], "--learning-rate inf"),
    (["train", "--houses", "preset:tiny", "--learning-rate", "-0.1"], "--learning-rate -0.1"),
    (["train", "--houses", "preset:tiny", "--max-grad-norm", "-1"], "--max-grad-norm -1.0"),
    (["train", "--houses", "preset:tiny", "--threads", "-1"], "--threads -1"),
    (["train", "--houses", "preset:tiny", "--hidden", "100000000"], "--hidden 100000000"),
    (["train", "--houses", "preset:tiny", "--beta-end", "nan"], "--beta-end nan"),
    (["ppo", "--houses", "preset:tiny", "--gamma", "inf"], "--gamma inf"),
    (["ppo", "--houses", "preset:tiny", "--ent-coef", "-1"], "--ent-coef -1.0"),
    (["evaluate", "--houses", "preset:tiny", "--min-geodesic", "inf"], "--min-geodesic inf"),
    (["loop", "--finetune-lr", "inf", "-o", "l"], "--finetune-lr inf"),
    (["loop", "--finetune-min-start", "inf", "-o", "l"], "--finetune-min-start inf"),
    (["experiment", "--final-episodes", "99999999999999999999", "-o", "x"], "--final-episodes 99999999999999999999"),
]


@pytest.mark.parametrize("args, names", NUMBERS, ids=[" ".join(a[:1] + a[-2:]) for a, _ in NUMBERS])
def test_a_number_out_of_range_is_one_line_before_any_work(args, names, monkeypatch, capsys, tmp_path):
    line = one_line(monkeypatch, capsys, *args)
    assert f"error: {names}:" in line
    assert list(tmp_path.iterdir()) == []


# -- policy checkpoints -----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def checkpoint_doc(tmp_path_factory) -> dict:
    """A small policy checkpoint's dictionary (network 32 wide)."""
    from adaptenv.agents.checkpoint import save_checkpoint
    from adaptenv.agents.network import NavNet, NetConfig

    torch.manual_seed(0)
    path = save_checkpoint(tmp_path_factory.mktemp("ckpt") / "p.pt", NavNet(NetConfig(hidden=32, feature_dim=32)))
    return torch.load(path, weights_only=True)


def _set_config(key, value):
    return lambda doc: doc["net_config"].__setitem__(key, value)


def _set_weight(key, fn):
    return lambda doc: doc["state_dict"].__setitem__(key, fn(doc["state_dict"][key]))


CHECKPOINTS = [
    ("192-TB-network", _set_config("hidden", 3_000_000_000), "net_config.hidden is 3000000000, outside 1 .. 4096"),
    ("more-rays", _set_config("n_rays", 64), "net_config.n_rays is 64, this simulator's observation needs 32"),
    ("text-width", _set_config("feature_dim", "32"), "net_config.feature_dim '32' is not a whole number"),
    ("unknown-field", _set_config("evil", 1), "net_config holds evil"),
    ("wider-config", _set_config("hidden", 64), "weight gru.weight_ih has shape (96, 32), its net_config's network needs"),
    ("nan-weight", _set_weight("head.0.weight", lambda t: t.fill_(float("nan"))), "weight head.0.weight holds NaN"),
    ("inf-weight", _set_weight("gru.bias_hh", lambda t: t.fill_(float("inf"))), "weight gru.bias_hh holds NaN"),
    ("missing-weight", lambda doc: doc["state_dict"].pop("head.2.bias"), "head.2.bias missing or unknown"),
    ("bad-threshold", lambda doc: doc["meta"].__setitem__("end_threshold", "high"), "meta.end_threshold 'high'"),
]


@pytest.mark.parametrize("edit, text", [c[1:] for c in CHECKPOINTS], ids=[c[0] for c in CHECKPOINTS])
def test_a_tampered_checkpoint_is_refused_before_its_network_is_built(edit, text, checkpoint_doc, tmp_path, monkeypatch,
                                                                      capsys):
    import copy

    import adaptenv.agents.evaluate as evaluate_module

    monkeypatch.setattr(evaluate_module, "evaluate", refuse_work)
    doc = copy.deepcopy(checkpoint_doc)
    edit(doc)
    torch.save(doc, tmp_path / "bad.pt")
    line = one_line(monkeypatch, capsys, "evaluate", "--policy", tmp_path / "bad.pt", "--houses", "preset:tiny",
                    "-n", "1", "-o", tmp_path / "ev")
    assert line.startswith(f"error: {tmp_path / 'bad.pt'}: ") and text in line


# -- training that diverges, and the card of a narrower --init ---------------------------------------

def test_training_that_makes_weights_nan_stops_in_one_line_and_keeps_the_last_finite_checkpoint(tmp_path, monkeypatch,
                                                                                             capsys):
    import adaptenv.agents.train as train_module

    real, calls = train_module.sequence_logits, []

    def nan_from_the_second_update(*args, **kwargs):
        calls.append(1)
        logits = real(*args, **kwargs)
        return logits * float("nan") if len(calls) > 1 else logits

    monkeypatch.setattr(train_module, "sequence_logits", nan_from_the_second_update)
    out = tmp_path / "p.pt"
    line = one_line(monkeypatch, capsys, "train", *TINY, *TINY_NET, "--frames", "128", "--save-every", "1",
                    "-o", out, "--run-dir", tmp_path / "run")
    assert "training diverged after 128 frames" in line and f"the last finite checkpoint, {out} (1 updates)" in line
    from adaptenv.agents.checkpoint import load_checkpoint

    kept = load_checkpoint(out)  # finite, or it would not load
    assert kept.meta["frames"] == 64


def test_train_init_of_a_narrower_network_writes_its_real_width_in_the_card(checkpoint_doc, tmp_path):
    torch.save(checkpoint_doc, tmp_path / "narrow.pt")
    result = CliRunner().invoke(app, ["train", *TINY, "--frames", "64", "--init", str(tmp_path / "narrow.pt"),
                                      "-o", str(tmp_path / "p.pt"), "--run-dir", str(tmp_path / "run")])
    assert result.exit_code == 0, result.output
    card = json.loads((tmp_path / "p.json").read_text())
    assert card["config"]["hidden"] == 32 and card["net_config"]["hidden"] == 32
    assert card["config"]["feature_dim"] == 32


# -- trajectories against their house -------------------------------------------------------------

@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> dict:
    """An expert's episode in the real house, as JSON."""
    path = tmp_path_factory.mktemp("traj") / "t.json"
    result = CliRunner().invoke(app, ["rollout", HOUSE, "--policy", "expert", "-o", str(path)])
    assert result.exit_code == 0, result.output
    return json.loads(path.read_text())


def _poses_shifted(doc):
    """Every pose 500 m to the east: an episode that follows itself, off the house's floor."""
    for pose in [doc["start"], doc["final_pose"], *(s["pose"] for s in doc["steps"])]:
        pose["x"] += 500.0


TRAJECTORIES = [
    ("500-m-outside", _poses_shifted, "start stands at", "off the house's floor"),
    ("no-steps", lambda d: d.update(steps=[]), "at steps: the episode has no steps", ""),
    ("nan-step", lambda d: d["steps"][2]["pose"].update(x=float("nan")), "at steps[2].pose.x: nan is not a finite", ""),
    ("unknown-action", lambda d: d["steps"][1].update(action="fly"), "at steps[1].action: unknown action 'fly'", ""),
    ("inf-target", lambda d: d["target_positions"][0].__setitem__(0, float("inf")), "at target_positions[0]: inf", ""),
]
READERS = [["analyze", HOUSE, "{t}"], ["render", HOUSE, "-t", "{t}", "-o", "{tmp}/map.png"],
           ["adapt", HOUSE, "--trajectory", "{t}", "-o", "{tmp}/adapted"]]


@pytest.mark.parametrize("command", READERS, ids=[c[0] for c in READERS])
@pytest.mark.parametrize("edit, text, more", [c[1:] for c in TRAJECTORIES], ids=[c[0] for c in TRAJECTORIES])
def test_an_impossible_trajectory_is_refused_by_every_reader(command, edit, text, more, recorded, tmp_path, monkeypatch,
                                                             capsys):
    import copy

    doc = copy.deepcopy(recorded)
    edit(doc)
    traj = tmp_path / "bad.json"
    traj.write_text(json.dumps(doc))
    line = one_line(monkeypatch, capsys, *(a.format(t=traj, tmp=tmp_path) for a in command))
    assert line.startswith(f"error: {traj}: ") and text in line and more in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.json"]


def test_the_untampered_trajectory_is_read(recorded, tmp_path):
    (tmp_path / "t.json").write_text(json.dumps(recorded))
    result = CliRunner().invoke(app, ["analyze", HOUSE, str(tmp_path / "t.json")])
    assert result.exit_code == 0 and "Outcome: success" in result.output, result.output


# -- bounded work: labels of a house with very many objects -----------------------------------------

def _crowded_house(n: int, path: Path) -> Path:
    """A valid one-room house holding ``n`` garbage cans in a grid (0.6 m apart)."""
    from adaptenv.scene.house import save_house
    from tests.sim import helpers as H

    side = int(n ** 0.5) + 1
    objs = [H.Obj(H.LOW_TARGET, 1.0 + 0.6 * (k % side), 1.0 + 0.6 * (k // side)) for k in range(n)]
    return save_house(H.one_room((2.0 + 0.6 * side, 2.0 + 0.6 * side), objects=objs, agent=(0.5, 0.5, 0.0)), path)


def test_a_house_with_more_objects_than_get_labels_renders_without_them_and_says_so(tmp_path):
    from adaptenv.render.labels import LABEL_LIMIT

    house = _crowded_house(LABEL_LIMIT + 1, tmp_path / "crowded.json")
    result = CliRunner().invoke(app, ["render", str(house), "-o", str(tmp_path / "map.png")])
    assert result.exit_code == 0, result.output
    said = " ".join(result.output.split())
    assert f"{LABEL_LIMIT + 1} floor objects, more than the {LABEL_LIMIT} that get id labels" in said
    assert (tmp_path / "map.png").stat().st_size > 0


def test_labels_below_the_limit_are_all_placed():
    from adaptenv.render.labels import LABEL_LIMIT
    from adaptenv.render.topdown import render_map
    from adaptenv.scene.house import load_house

    house = load_house(HOUSE)
    placed = render_map(house).labels
    assert len(placed) == len({lab.text for lab in placed}) > 0 and len(placed) <= LABEL_LIMIT


@pytest.mark.slow
def test_a_valid_house_with_20000_objects_renders_in_seconds(tmp_path):
    house = _crowded_house(20_000, tmp_path / "huge.json")
    result = CliRunner().invoke(app, ["render", str(house), "-o", str(tmp_path / "map.png")])
    assert result.exit_code == 0, result.output
    assert "20,000 floor objects" in " ".join(result.output.split())


# -- asset tables from objathor ------------------------------------------------------------------------

def _box(x, y, z):
    return {"thor_metadata": {"assetMetadata": {"boundingBox": {"x": x, "y": y, "z": z}}}}


@pytest.mark.parametrize("doc", [
    [1, 2, 3], "text", None, {"uid": 5},
    {"a": {"thor_metadata": [1, 2], "category": "chair"}},
    {"a": {"thor_metadata": {"assetMetadata": "box"}, "synset": "chair.n.01"}},
    {"a": {**_box(float("nan"), 1, 1), "category": "chair"}},
], ids=["list", "string", "null", "uid-number", "metadata-list", "asset-metadata-text", "nan-only"])
def test_an_annotation_file_of_another_shape_is_one_line(doc, tmp_path, monkeypatch, capsys):
    path = tmp_path / "ann.json"
    path.write_text(json.dumps(doc))
    line = one_line(monkeypatch, capsys, "assets", "from-objathor", path, "-o", tmp_path / "table.json")
    assert line.startswith(f"error: {path}: ")
    assert not (tmp_path / "table.json").exists()


def test_nan_and_infinite_sizes_are_left_out_of_the_table(tmp_path):
    doc = {"nan": {**_box(float("nan"), 1, 1), "category": "chair"},
           "inf": {**_box(float("inf"), 1, 1), "category": "sofa"},
           "huge": {**_box(1e300, 1, 1), "category": "sofa"},
           "ok": {"width": 50, "height": 80, "depth": 40, "category": "chair"}}
    (tmp_path / "ann.json").write_text(json.dumps(doc))
    result = CliRunner().invoke(app, ["assets", "from-objathor", str(tmp_path / "ann.json"), "-o",
                                      str(tmp_path / "table.json"), "--json"])
    assert result.exit_code == 0, result.output
    text = (tmp_path / "table.json").read_text()
    assert sorted(json.loads(text)["assets"]) == ["ok"] and "NaN" not in text and "Infinity" not in text
    assert json.loads(result.output)["skipped_no_size"] == 3


# -- loop --resume ------------------------------------------------------------------------------------

LOOP = ["loop", "--houses", "preset:tiny", "--heldout", "tiny=preset:tiny", "-T", "2", "--method", "none",
        "--finetune-algo", "ppo"]


@pytest.fixture(scope="module")
def loop_run(tmp_path_factory) -> tuple[Path, Path]:
    """A finished one-iteration PPO loop run (the policy file, the run folder) whose saved settings are those of
    ``LOOP`` with that policy, so ``LOOP --resume`` continues it at iteration 2."""
    from adaptenv.agents.checkpoint import save_checkpoint
    from adaptenv.agents.network import NavNet, NetConfig
    from adaptenv.curriculum.loop import LoopConfig, run_loop
    from adaptenv.curriculum.records import STATE
    from adaptenv.files import MANIFEST

    root = tmp_path_factory.mktemp("loop")
    torch.manual_seed(0)
    policy = save_checkpoint(root / "tiny.pt", NavNet(NetConfig(hidden=32, feature_dim=32)))
    small = dict(method="none", policy=str(policy), houses="preset:tiny", heldout={"tiny": "preset:tiny"},
                 finetune_algo="ppo")
    run_loop(LoopConfig(**small, iterations=1, scenes_per_iteration=1, finetune_frames=256, finetune_envs=2,
                        heldout_episodes=2, gallery=0, score_rollouts=1, finetune_max_steps=20), root / "run")
    state = json.loads((root / "run" / STATE).read_text())
    state["config"] = asdict(LoopConfig(**small, iterations=2))  # as the command line below says
    (root / "run" / STATE).write_text(json.dumps(state))
    (root / "run" / MANIFEST).write_text(json.dumps({"folder": "loop", "files": {}}))  # as adaptenv loop leaves it
    return policy, root / "run"


def _corrupt(name: str, data: bytes):
    def edit(run: Path) -> None:
        (run / name).write_bytes(data)
    return edit


def _foreign_learner(run: Path) -> None:
    shutil.copy(run / "iter_0001" / "policy.pt", run / "iter_0001" / "learner.pt")


def _misfit_learner(run: Path) -> None:
    learner = torch.load(run / "iter_0001" / "learner.pt", weights_only=True)
    learner["value"]["0.weight"] = torch.zeros(128, 7)
    torch.save(learner, run / "iter_0001" / "learner.pt")


def _state(**changes):
    def edit(run: Path) -> None:
        doc = json.loads((run / "state.json").read_text())
        doc["state"].update(changes)
        (run / "state.json").write_text(json.dumps(doc))
    return edit


RESUMES = [
    ("corrupt-learner", _corrupt("iter_0001/learner.pt", b"not a torch file"), "iter_0001/learner.pt: not a learner"),
    ("foreign-learner", _foreign_learner, "iter_0001/learner.pt: not a learner state (expected"),
    ("misfit-learner", _misfit_learner, "iter_0001/learner.pt: it does not fit this policy's network"),
    ("corrupt-iterations", _corrupt("iterations.jsonl", b'{"iteration": "one"}\n'),
     "iterations.jsonl: line 1 is not an iteration record the loop wrote (at iteration:"),
    ("corrupt-policy", _corrupt("iter_0001/policy.pt", b"PK\x03\x04 junk"), "iter_0001/policy.pt: not a readable torch"),
    ("iteration-beyond", _state(iteration=7), "state.json: state.iteration 7 lies outside 0 .. 2"),
    ("iteration-without-record", _state(iteration=2), "state.iteration 2 but"),
    ("negative-steps", _state(env_steps=-5), "state.json: state.env_steps is negative (-5)"),
    ("state-of-wrong-type", _state(pool="tiny_0000"), "state.json: state.pool"),
]


@pytest.mark.parametrize("edit, text", [c[1:] for c in RESUMES], ids=[c[0] for c in RESUMES])
def test_loop_resume_refuses_damaged_files_before_any_work(edit, text, loop_run, tmp_path, monkeypatch, capsys):
    import adaptenv.curriculum.loop as loop_module

    monkeypatch.setattr(loop_module, "rollout_scenes", refuse_work)
    policy, run = loop_run
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    edit(copy)
    line = one_line(monkeypatch, capsys, *LOOP, "--policy", policy, "-o", copy, "--resume")
    assert f"{copy}/" in line and text in line


def test_loop_resume_of_the_undamaged_run_gets_to_work(loop_run, tmp_path, monkeypatch):
    import adaptenv.curriculum.loop as loop_module

    monkeypatch.setattr(loop_module, "rollout_scenes", refuse_work)
    policy, run = loop_run
    shutil.copytree(run, tmp_path / "run")
    result = CliRunner().invoke(app, [*LOOP, "--policy", str(policy), "-o", str(tmp_path / "run"), "--resume"])
    assert isinstance(result.exception, WorkStarted), result.output


# -- an experiment whose ours-llm run failed --------------------------------------------------------

def test_a_failed_run_is_marked_in_the_summary_not_a_row(tmp_path, monkeypatch):
    import adaptenv.curriculum.experiment as experiment
    from adaptenv.curriculum.records import IterationRecord, SetMetrics, write_iterations
    from adaptenv.errors import RunsFailed

    def record(t: int) -> IterationRecord:
        m = SetMetrics(success=0.5, spl=0.4, collisions=1.0, episodes=4)
        return IterationRecord(iteration=t, env_steps=100 * t, grad_updates=t, edits=0, heldout={"tiny": m})

    def fake_loop(cfg, folder, **kwargs):
        Path(folder).mkdir(parents=True, exist_ok=True)
        done = 0 if cfg.method == "ours-llm" else cfg.iterations  # ours-llm fails after iteration 0
        write_iterations(Path(folder), [record(t) for t in range(done + 1)])
        if cfg.method == "ours-llm":
            raise AdaptenvError("the LLM server at http://127.0.0.1:9/v1 refused the connection")
        return [record(t) for t in range(done + 1)]

    monkeypatch.setattr(experiment, "run_loop", fake_loop)
    config = tmp_path / "exp.json"
    config.write_text(json.dumps({"methods": ["none", "ours-llm"], "seeds": [0], "reference": "none",
                                  "loop": {"iterations": 2, "houses": "preset:tiny", "heldout": {"tiny": "preset:tiny"},
                                           "llm": {"base_url": "http://127.0.0.1:9/v1", "model": "m"}}}))
    result = CliRunner().invoke(app, ["experiment", "--config", str(config), "-o", str(tmp_path / "exp")])
    assert isinstance(result.exception, RunsFailed), result.output
    summary = json.loads((tmp_path / "exp" / "summary.json").read_text())
    assert list(summary["methods"]) == ["none"]
    assert summary["unfinished_runs"] == {"ours-llm seed 0": "0 of 2 iterations"}
    md = (tmp_path / "exp" / "summary.md").read_text()
    assert "| ours-llm |" not in md and "ours-llm seed 0 (0 of 2 iterations)" in md
    assert "FAILED ours-llm seed 0: the LLM server" in md
