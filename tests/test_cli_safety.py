"""Nothing a user types deletes their files, runs code from a file, or ends in a traceback.

Each case gets one line naming the file, field or flag and the fix, before any work where it can be checked
first. Unwritable paths are made by pointing under a regular file, which fails for root too.
"""

from __future__ import annotations

import sys
from dataclasses import asdict
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from adaptenv.cli import app, main
from adaptenv.errors import ConfigError

HOUSE = str(Path(__file__).parent / "data" / "procthor-10k-train-1.json")
TINY = dict(houses="preset:tiny", num_envs=4, rollout_steps=16, chunk_len=8, batch_chunks=2, updates_per_iter=1,
            buffer_frames=64, hidden=32, feature_dim=32, calibrate_episodes=0, eval_every=0, final_eval_episodes=0,
            threads=1, tensorboard=False, progress=False)
"""A training run of one 64-frame block: the settings, and below as `adaptenv train` options."""
TINY_TRAIN = ["train", *[a for k, v in TINY.items() for a in (
    [f"--{'' if v else 'no-'}{k.replace('_', '-')}"] if isinstance(v, bool) else [f"--{k.replace('_', '-')}", str(v)])]]


class WorkStarted(Exception):
    """Raised by a stand-in for the expensive part of a command: the command got past its checks."""


def refuse_work(*args, **kwargs):
    raise WorkStarted


def invoke(*args: str):
    return CliRunner().invoke(app, [str(a) for a in args])


def config_error(result) -> str:
    """The one-line ConfigError a command ended with (any other outcome fails the test)."""
    assert isinstance(result.exception, ConfigError), (result.exception, result.output)
    text = str(result.exception)
    assert "\n" not in text
    return text


# -- adaptenv demo ------------------------------------------------------------------------------

def test_demo_refuses_a_folder_it_did_not_write_and_deletes_nothing(tmp_path, monkeypatch):
    import adaptenv.scene.procedural as procedural

    monkeypatch.setattr(procedural, "generate_houses", refuse_work)
    mine = tmp_path / "mine"
    (mine / "sub").mkdir(parents=True)
    (mine / "sub" / "notes.txt").write_text("keep me")
    text = config_error(invoke("demo", "-o", mine))
    assert f"-o {mine}" in text and "new or empty folder" in text
    assert (mine / "sub" / "notes.txt").read_text() == "keep me"


def test_demo_replaces_only_its_own_outputs_in_its_own_folder(tmp_path):
    from adaptenv.cli.demo import MARKER, prepare_out

    out = tmp_path / "demo"
    with prepare_out(out):  # a new folder: what the demo writes there is marked as its own
        (out / "run" / "iter_0000").mkdir(parents=True)
        (out / "run" / "iter_0000" / "policy.pt").write_bytes(b"weights")
    assert (out / MARKER).is_file()
    (out / "mine.txt").write_text("keep me")
    with prepare_out(out):
        assert not (out / "run").exists() and (out / "mine.txt").read_text() == "keep me"


# -- adaptenv train --resume --------------------------------------------------------------------

class Payload:
    """Unpickling this runs code: it creates the file ``marker``."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def resume_args(tmp_path):
    return [*TINY_TRAIN, "--frames", "64", "-o", tmp_path / "p.pt", "--run-dir", tmp_path / "run", "--resume"]


def test_resume_never_runs_code_from_state_pt_and_writes_nothing(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text("the interrupted run's config")
    marker = tmp_path / "pwned"
    torch.save({"net": Payload(marker), "frames": 0}, run / "state.pt")
    text = config_error(invoke(*resume_args(tmp_path)))
    assert not marker.exists()
    assert f"{run / 'state.pt'}: not a resume state" in text and "without --resume" in text
    assert (run / "config.json").read_text() == "the interrupted run's config"


def test_resume_from_a_corrupt_state_is_one_line_before_anything_is_written(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text("the interrupted run's config")
    (run / "state.pt").write_bytes(b"\x80\x04 this is not a torch file")
    text = config_error(invoke(*resume_args(tmp_path)))
    assert str(run / "state.pt") in text
    assert (run / "config.json").read_text() == "the interrupted run's config"
    assert sorted(p.name for p in run.iterdir()) == ["config.json", "state.pt"]


def test_resume_names_the_folder_that_does_not_exist(tmp_path):
    text = config_error(invoke(*resume_args(tmp_path)))
    assert f"the run folder {tmp_path / 'run'} does not exist" in text
    assert not (tmp_path / "run").exists()


def test_resume_with_other_settings_names_each_field_that_differs(tmp_path):
    from adaptenv.agents.train import STATE_KEYS, TrainConfig

    run = tmp_path / "run"
    run.mkdir()
    saved = TrainConfig(**{**TINY, "hidden": 64, "seed": 3}, frames=32, output=str(tmp_path / "p.pt"),
                        run_dir=str(run))
    torch.save({**{k: 0 for k in STATE_KEYS}, "config": asdict(saved)}, run / "state.pt")
    text = config_error(invoke(*resume_args(tmp_path)))
    assert "settings: hidden (was 64, now 32), seed (was 3, now 0); pass the interrupted run's values" in text


def test_ctrl_c_during_train_says_how_to_resume(tmp_path, monkeypatch):
    from adaptenv.agents.train import SequenceBuffer

    def interrupt(self, block):
        raise KeyboardInterrupt

    monkeypatch.setattr(SequenceBuffer, "add", interrupt)
    res = invoke(*TINY_TRAIN, "--frames", "64", "-o", tmp_path / "p.pt", "--run-dir", tmp_path / "run")
    assert res.exit_code == 130
    line = " ".join(res.stderr.split())
    assert line.startswith(f"interrupted; the run is saved in {tmp_path / 'run'}, continue it with: adaptenv train")
    assert line.endswith("--resume") and f"--run-dir {tmp_path / 'run'}" in line
    assert (tmp_path / "run" / "state.pt").is_file()


def test_train_refuses_fewer_frames_than_one_block_and_says_when_it_rounds_up(tmp_path, monkeypatch):
    import adaptenv.agents.train as train_module

    monkeypatch.setattr(train_module, "train", refuse_work)
    text = config_error(invoke("train", "--houses", "preset:tiny", "--frames", "512", "-o", tmp_path / "p.pt"))
    assert "--frames 512" in text and "pass --frames 16384 or more" in text
    res = invoke("train", "--houses", "preset:tiny", "--frames", "20000", "-o", tmp_path / "p.pt")
    assert isinstance(res.exception, WorkStarted)
    assert "--frames 20000 trains 32,768 frames" in " ".join(res.output.split())


# -- adaptenv loop --resume ---------------------------------------------------------------------

LOOP = ["loop", "--houses", "preset:tiny", "--heldout", "tiny=preset:tiny", "--iterations", "1"]


def test_loop_resume_names_a_missing_run_folder(tmp_path, monkeypatch):
    import adaptenv.curriculum.loop as loop_module

    monkeypatch.setattr(loop_module, "run_loop", refuse_work)
    text = config_error(invoke(*LOOP, "-o", tmp_path / "nope", "--resume"))
    assert f"the run folder {tmp_path / 'nope'} does not exist" in text


def test_loop_passes_the_ppo_fine_tuning_flags(tmp_path, monkeypatch):
    import adaptenv.curriculum.loop as loop_module

    seen = []

    def capture(cfg, *args, **kwargs):  # the settings the loop would run with, then stop
        seen.append(cfg)
        raise KeyboardInterrupt

    monkeypatch.setattr(loop_module, "run_loop", capture)
    res = invoke(*LOOP, "-o", tmp_path / "r", "--finetune-algo", "ppo", "--finetune-freeze-encoder",
                 "--finetune-fresh-learner")
    assert res.exit_code == 130, res.output
    [cfg] = seen
    assert (cfg.finetune_algo, cfg.finetune_freeze_encoder, cfg.finetune_keep_learner) == ("ppo", True, False)


def test_ctrl_c_during_the_loop_says_how_to_resume(tmp_path, monkeypatch):
    import adaptenv.curriculum.loop as loop_module

    def interrupt(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(loop_module, "run_loop", interrupt)
    monkeypatch.setattr(sys, "argv", ["adaptenv", *LOOP, "-o", str(tmp_path / "r")])
    res = invoke(*LOOP, "-o", tmp_path / "r")
    assert res.exit_code == 130
    assert " ".join(res.stderr.split()).endswith(f"continue the run with: adaptenv {' '.join(LOOP)} -o "
                                                 f"{tmp_path / 'r'} --resume")


# -- adaptenv experiment -----------------------------------------------------------------------

def test_experiment_shows_the_finished_runs_then_names_the_failed_ones(tmp_path, monkeypatch):
    import adaptenv.curriculum.experiment as experiment
    from adaptenv.errors import RunsFailed

    def one_run_failed(cfg, out, **kwargs):
        out.mkdir(parents=True, exist_ok=True)  # the command made (and locked) it before any work
        (out / "summary.md").write_text("| method | success:tiny |\n| none | 0.5 |\n")
        raise RunsFailed("1 of 4 runs failed (dr seed 0: boom); the others are in OUT")

    monkeypatch.setattr(experiment, "run_experiment", one_run_failed)
    monkeypatch.setattr(experiment, "final_evaluation", refuse_work)  # not over a partial experiment
    config = Path(__file__).parents[1] / "configs" / "experiment-small.json"
    res = invoke("experiment", "--config", config, "-o", tmp_path / "exp", "--final-episodes", "8")
    assert isinstance(res.exception, RunsFailed) and "\n" not in str(res.exception)
    assert "| none | 0.5 |" in res.output and "experiment folder:" in res.output


# -- output paths that cannot be written --------------------------------------------------------

@pytest.mark.parametrize("command, flag", [
    (["houses", "generate", "--n", "1", "-o", "{bad}"], "-o"),
    (["rollout", HOUSE, "-o", "{bad}/traj.json"], "-o"),
    (["rollout", HOUSE, "-o", "{ok}/traj.json", "--render", "{bad}/map.png"], "--render"),
    (["render", HOUSE, "-o", "{bad}/map.png"], "-o"),
    (["report", "{ok}", "-o", "{bad}"], "-o"),
    (["adapt", HOUSE, "-o", "{bad}"], "-o"),
    ([*LOOP, "-o", "{bad}"], "-o"),
    (["demo", "-o", "{bad}"], "-o"),
    ([*TINY_TRAIN, "--frames", "64", "-o", "{bad}/p.pt"], "--output"),
    ([*TINY_TRAIN, "--frames", "64", "-o", "{ok}/p.pt", "--run-dir", "{bad}"], "--run-dir"),
    (["evaluate", "--houses", "preset:tiny", "-o", "{bad}"], "-o"),
    (["memory-check", "--houses", "preset:tiny", "-o", "{bad}"], "-o"),
], ids=["houses", "rollout", "rollout-render", "render", "report", "adapt", "loop", "demo", "train", "train-run-dir",
        "evaluate", "memory-check"])
def test_an_unwritable_output_is_refused_before_any_work(tmp_path, command, flag):
    a_file = tmp_path / "a_file"
    a_file.write_text("a regular file: nothing can be created under it, not even by root")
    bad = a_file / "out"
    args = [c.format(bad=bad, ok=tmp_path) for c in command]
    text = config_error(invoke(*args))
    assert text.startswith(f"{flag} {bad}") and f"{a_file} is a file, not a folder" in text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]


def test_a_file_system_error_past_the_checks_is_one_line_and_exit_1(tmp_path, monkeypatch, capsys):
    import adaptenv.render.topdown as topdown

    def denied(house, path, **kw):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(topdown, "render_to_file", denied)
    monkeypatch.setattr(sys, "argv", ["adaptenv", "render", HOUSE, "-o", str(tmp_path / "map.png")])
    with pytest.raises(SystemExit) as exit_info:
        main()
    assert exit_info.value.code == 1
    err = " ".join(capsys.readouterr().err.split())
    assert err.startswith(f"error: {tmp_path / 'map.png'}: Permission denied;") and "Traceback" not in err


def test_the_checks_accept_new_folders_refuse_a_folder_as_a_file_and_create_nothing(tmp_path):
    from adaptenv.cli._common import writable_file, writable_folder

    assert writable_folder(tmp_path / "new" / "deeper", "-o") == tmp_path / "new" / "deeper"
    (tmp_path / "d").mkdir()
    with pytest.raises(ConfigError, match="is a folder; pass a file name"):
        writable_file(tmp_path / "d", "-o")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d"]
