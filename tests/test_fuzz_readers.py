"""Property-based fuzzing of every reader of user data beyond the house parser (tests/scene/test_fuzz.py).

House datasets, trajectories checked against their house, AI2-THOR logs, asset tables (``--assets`` and
objathor annotations), config files (experiment, LLM, loop resume state, iteration log, level buffer) and
policy checkpoints: a valid document, mutated (keys dropped, wrong types, NaN, infinity, huge numbers, other
nesting) or cut and garbled as bytes, either loads or raises adaptenv's own error in one short line, never any
other exception. The example count comes from the hypothesis profile (tests/conftest.py): ``ci`` runs 100
examples per property, ``ADAPTENV_FUZZ_PROFILE=long`` 10,000.
"""

from __future__ import annotations

import functools
import gzip
import io
import json
import math
from dataclasses import asdict
from pathlib import Path
from typing import Any

import hypothesis.strategies as st
import pytest
import torch
from hypothesis import HealthCheck, given, settings

from adaptenv.errors import AdaptenvError, HouseError
from adaptenv.scene.house import House
from adaptenv.scene.procedural.presets import generate_preset
from adaptenv.sim.trajectory import Trajectory
from tests.conftest import REAL_HOUSE
from tests.scene.test_fuzz import JSON, ODD_NUMBERS, mutate, trajectory_document

FUZZ = settings(suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture])
"""The profile's example count and determinism; these properties write files, so they may be slow."""


@pytest.fixture(scope="module")
def scratch(tmp_path_factory) -> Path:
    """One folder for the files every example writes (and overwrites)."""
    return tmp_path_factory.mktemp("fuzz_readers")


def garble(data: st.DataObject, raw: bytes) -> bytes:
    """``raw`` cut short, with bytes flipped, inserted or gzip-wrapped (a copy gone wrong)."""
    op = data.draw(st.sampled_from(["truncate", "flip", "insert", "gzip", "gzip-truncated"]), label="garble")
    if op == "gzip":
        return gzip.compress(raw)
    if op == "gzip-truncated":
        packed = gzip.compress(raw)
        return packed[: data.draw(st.integers(0, len(packed) - 1), label="cut")]
    at = data.draw(st.integers(0, max(len(raw) - 1, 0)), label="at")
    if op == "truncate":
        return raw[:at]
    if op == "flip":
        return raw[:at] + bytes([raw[at] ^ data.draw(st.integers(1, 255), label="xor")]) + raw[at + 1:] if raw else raw
    return raw[:at] + data.draw(st.binary(min_size=1, max_size=8), label="bytes") + raw[at:]


def document_or_bytes(data: st.DataObject, doc: Any) -> bytes:
    """The file of ``doc`` after a JSON mutation, or as garbled bytes, or a random JSON document."""
    kind = data.draw(st.sampled_from(["mutated", "garbled", "random"]), label="kind")
    if kind == "mutated":
        return json.dumps(mutate(data, doc)).encode()
    if kind == "garbled":
        return garble(data, json.dumps(doc).encode())
    return json.dumps(data.draw(JSON, label="document")).encode()


def assert_one_short_line(message: str) -> None:
    """A message a user can read: one line, no traceback, not a whole document."""
    assert "\n" not in message and "Traceback" not in message, message
    assert len(message) < 1000, message


def expect_user_error(load, *args, **kwargs) -> Any:
    """``load(*args)``'s result, or None after an AdaptenvError whose message is one short line."""
    try:
        return load(*args, **kwargs)
    except AdaptenvError as err:
        assert_one_short_line(str(err))
        return None


def all_finite(value: Any) -> bool:
    """Whether every number inside ``value`` (nested lists, tuples, dicts) is finite."""
    if isinstance(value, dict):
        return all(all_finite(v) for v in value.values())
    if isinstance(value, list | tuple):
        return all(all_finite(v) for v in value)
    return not isinstance(value, float) or math.isfinite(value)


# --- house datasets -----------------------------------------------------------------------------------------------

@functools.cache
def tiny_house_documents() -> tuple[dict[str, Any], ...]:
    """The preset tiny houses as JSON documents (a dataset's lines)."""
    return tuple(house.to_dict() for _, house in generate_preset("tiny"))


@FUZZ
@given(data=st.data())
def test_datasets_yield_houses_or_house_errors(data, scratch):
    from adaptenv.scene.dataset import dataset_houses, parse_dataset_spec

    lines = [json.dumps(d) for d in tiny_house_documents()[:2]]
    k = data.draw(st.integers(0, len(lines) - 1), label="line")
    if data.draw(st.booleans(), label="mutate a line?"):
        lines[k] = json.dumps(mutate(data, json.loads(lines[k])))
    raw = "\n".join(lines).encode()
    if data.draw(st.booleans(), label="garble the file?"):
        raw = garble(data, raw)
    path = scratch / "houses.jsonl"
    path.write_bytes(raw)
    spec = data.draw(st.sampled_from(["", ":0:1", ":1:2", ":0:5:2", ":3:9", ":1:0", ":x"]), label="slice")
    ds = expect_user_error(parse_dataset_spec, f"{path}{spec}")
    if ds is None:
        return
    items = expect_user_error(lambda: list(dataset_houses(ds)))
    for _, item in items or []:
        assert isinstance(item, House | HouseError)
        if isinstance(item, HouseError):
            assert_one_short_line(str(item))


# --- trajectories, checked against their house ----------------------------------------------------------------------

@functools.cache
def real_world():
    """The real house compiled once (a cached function, not a fixture: hypothesis would print it)."""
    from adaptenv.scene.house import load_house
    from adaptenv.sim.world import compile_world

    return compile_world(load_house(REAL_HOUSE, validate=False), REAL_HOUSE.stem)


@FUZZ
@given(data=st.data())
def test_trajectories_load_and_fit_their_house_or_raise_one_line(data, scratch):
    from adaptenv.cli._common import check_recorded_in

    path = scratch / "traj.json"
    path.write_bytes(document_or_bytes(data, trajectory_document()))
    traj = expect_user_error(Trajectory.load, path)
    if traj is None:
        return
    assert traj.problem() is None
    expect_user_error(check_recorded_in, traj, real_world(), path, REAL_HOUSE)


# --- AI2-THOR logs ----------------------------------------------------------------------------------------------------

def ai2thor_log_lines() -> list[Any]:
    """A header and five events of an agent walking along the real house's kitchen (AI2-THOR's metadata keys)."""
    def event(x: float, yaw: float, action: Any) -> dict[str, Any]:
        agent = {"name": "agent", "position": {"x": x, "y": 0.9009, "z": 2.5}, "rotation": {"x": 0.0, "y": yaw, "z": 0.0},
                 "cameraHorizon": 30.0, "isStanding": True}
        return {"action": action, "agent": agent, "lastActionSuccess": True}
    header = {"house": "procthor-10k-train-1", "target_type": "Fridge", "policy": "spoc", "seed": 3}
    return [header, event(10.0, 90.0, "TeleportFull"), event(10.25, 90.0, "MoveAhead"),
            event(10.25, 0.0, "RotateLeft"), event(10.25, 0.0, {"action": "RotateAgent", "degrees": 6}),
            event(10.25, 0.0, "Done")]


@FUZZ
@given(data=st.data())
def test_ai2thor_logs_convert_or_raise_one_line(data, scratch):
    from adaptenv.sim.ai2thor import convert_ai2thor_log

    lines = ai2thor_log_lines()
    kind = data.draw(st.sampled_from(["line", "log", "bytes"]), label="kind")
    if kind == "line":
        k = data.draw(st.integers(0, len(lines) - 1), label="line")
        lines[k] = mutate(data, lines[k])
    elif kind == "log":
        lines = mutate(data, lines)
    raw = ("\n".join(json.dumps(x) for x in lines) if isinstance(lines, list) else json.dumps(lines)).encode()
    if kind == "bytes":
        raw = garble(data, raw)
    path = scratch / "episode.jsonl"
    path.write_bytes(raw)
    conversion = expect_user_error(convert_ai2thor_log, path, real_world())
    if conversion is not None:
        assert conversion.trajectory.problem() is None


# --- asset tables -----------------------------------------------------------------------------------------------------

ASSET_TABLE = {"source": "my scans", "note": "sizes in meters", "assets": {
    "my_sofa": {"type": "Sofa", "size": [2.0, 0.8, 0.9], "split": "train"},
    "my_table": {"objectType": "DiningTable", "boundingBox": {"x": 1.2, "y": 0.75, "z": 0.8},
                 "footprint": [[-0.6, -0.4], [0.6, -0.4], [0.6, 0.4], [-0.6, 0.4]]},
}}


@FUZZ
@given(data=st.data())
def test_asset_tables_give_finite_rows_or_raise_one_line(data, scratch):
    from adaptenv.scene.assets import read_asset_table

    path = scratch / "assets.json"
    path.write_bytes(document_or_bytes(data, ASSET_TABLE))
    rows = expect_user_error(read_asset_table, path)
    for info in (rows or {}).values():
        assert all(math.isfinite(v) and v > 0 for v in info.size), info
        assert info.footprint is None or all_finite(info.footprint), info


ANNOTATIONS = {
    "0a1b": {"uid": "0a1b", "category": "sofa", "synset": "sofa.n.01", "split": "train",
             "thor_metadata": {"assetMetadata": {"boundingBox": {"min": {"x": -1.0, "y": 0.0, "z": -0.45},
                                                                 "max": {"x": 1.0, "y": 0.8, "z": 0.45}}}}},
    "2c3d": {"uid": "2c3d", "category": "armchair", "width": 80, "height": 90, "depth": 75},
    "4e5f": {"uid": "4e5f", "ref_category": "lamp", "size": [30, 30, 150]},
}


@FUZZ
@given(data=st.data())
def test_objathor_annotations_give_finite_rows_or_raise_one_line(data, scratch):
    from adaptenv.scene.objathor import read_annotations, table_from_annotations

    path = scratch / "annotations.json"
    path.write_bytes(document_or_bytes(data, ANNOTATIONS))
    annotations = expect_user_error(read_annotations, path)
    if annotations is None:
        return
    table = table_from_annotations(annotations)
    for row in table.assets.values():
        assert all(math.isfinite(v) and 0 < v <= 100 for v in row["size"]), row
    json.dumps(table.to_json(path.name), allow_nan=False)  # what `assets from-objathor` writes


# --- config files -----------------------------------------------------------------------------------------------------

EXPERIMENT = Path(__file__).parents[1] / "configs" / "experiment-small.json"
LLM_CONFIG = {"provider": "openai-compatible", "base_url": "http://127.0.0.1:9/v1", "model": "vlm",
              "api_key_env": "OPENAI_API_KEY"}


@FUZZ
@given(data=st.data())
def test_experiment_configs_load_or_raise_one_line(data, scratch):
    from adaptenv.curriculum.experiment import ExperimentConfig

    path = scratch / "experiment.json"
    doc = json.loads(EXPERIMENT.read_text())
    if data.draw(st.booleans(), label="with an llm section?"):
        doc["loop"]["llm"] = dict(LLM_CONFIG)
    path.write_bytes(document_or_bytes(data, doc))
    expect_user_error(ExperimentConfig.load, path)


@FUZZ
@given(data=st.data())
def test_llm_configs_load_or_raise_one_line(data, scratch):
    from adaptenv.adapt.llm import load_llm_config

    path = scratch / "llm.json"
    path.write_bytes(document_or_bytes(data, LLM_CONFIG))
    expect_user_error(load_llm_config, path)


@FUZZ
@given(data=st.data())
def test_loop_resume_files_are_checked_in_one_line(data, tmp_path_factory):
    from adaptenv.curriculum.buffer import LevelBufferState
    from adaptenv.curriculum.loop import STATE, LoopConfig, LoopState, _open_run

    run_dir = tmp_path_factory.mktemp("run")
    cfg = LoopConfig()
    buffer = LevelBufferState(("a", "b"), (0.5, 1.0), (0, 1), (None, "a"), 2).to_dict()
    state = {"config": asdict(cfg), "state": {**asdict(LoopState(pool=["a"], archive=["a", "b"])), "buffer": buffer}}
    run = {"method": "ours", "seed": 0, "config": {}, "command": "adaptenv loop", "skipped_houses": {}}
    which = data.draw(st.sampled_from([STATE, "run.json"]), label="file")
    (run_dir / STATE).write_bytes(document_or_bytes(data, state) if which == STATE else json.dumps(state).encode())
    (run_dir / "run.json").write_bytes(document_or_bytes(data, run) if which == "run.json" else json.dumps(run).encode())
    expect_user_error(_open_run, cfg, run_dir, True, "adaptenv loop --resume")


@FUZZ
@given(data=st.data())
def test_iteration_logs_read_or_raise_one_line(data, scratch):
    from adaptenv.curriculum.records import ITERATIONS, IterationRecord, read_iterations

    record = IterationRecord(iteration=0, env_steps=10, grad_updates=2, edits=1, wall_time_s=1.5,
                             stage_seconds={"rollouts": 0.5}).model_dump(mode="json")
    (scratch / ITERATIONS).write_bytes(json.dumps(record).encode() + b"\n" + document_or_bytes(data, record))
    expect_user_error(read_iterations, scratch)


@FUZZ
@given(data=st.data())
def test_level_buffer_states_parse_or_raise_one_line(data):
    from adaptenv.curriculum.buffer import LevelBufferState

    doc = LevelBufferState(("a", "b", "c"), (0.5, 1.0, 0.0), (0, 1, 2), (None, "a", "a"), 3).to_dict()
    text = document_or_bytes(data, doc).decode("utf-8", "replace")
    state = expect_user_error(LevelBufferState.from_json, text, "buffer.json")
    if state is not None:
        assert all_finite(state.scores)


# --- policy checkpoints -----------------------------------------------------------------------------------------------

@functools.cache
def checkpoint_bytes() -> bytes:
    """A tiny valid checkpoint (every width 1 or 2) written by the project's own save function."""
    import tempfile

    from adaptenv.agents.checkpoint import save_checkpoint
    from adaptenv.agents.network import NavNet, NetConfig

    torch.manual_seed(0)
    net = NavNet(NetConfig(class_dim=1, conv_channels=1, target_dim=1, action_dim=1, feature_dim=2, hidden=2))
    with tempfile.TemporaryDirectory() as tmp:
        path = save_checkpoint(Path(tmp) / "policy.pt", net, {"end_threshold": 0.5, "algo": "ppo"})
        return path.read_bytes()


TENSOR_EDITS = ["nan", "inf", "shape", "dtype", "scalar", "empty", "not a tensor"]


def edit_tensor(data: st.DataObject, t: torch.Tensor) -> Any:
    """``t`` with NaN or infinity, another shape or dtype, or replaced by a scalar, an empty tensor or a number."""
    op = data.draw(st.sampled_from(TENSOR_EDITS), label="tensor edit")
    if op in ("nan", "inf"):
        t = t.clone().reshape(-1)
        t[data.draw(st.integers(0, max(t.numel() - 1, 0)), label="index")] = math.nan if op == "nan" else -math.inf
        return t
    if op == "shape":
        return torch.zeros(tuple(data.draw(st.lists(st.integers(0, 3), max_size=3), label="shape")))
    if op == "dtype":
        return t.to(data.draw(st.sampled_from([torch.float16, torch.float64, torch.int64, torch.bool,
                                               torch.complex64]), label="dtype"))
    if op == "scalar":
        return torch.tensor(1.0)
    if op == "empty":
        return torch.empty(0)
    return data.draw(st.sampled_from(ODD_NUMBERS) | JSON, label="value")


def mutate_checkpoint(data: st.DataObject, doc: dict[str, Any]) -> Any:
    """The checkpoint dictionary with one field, config entry, meta entry or tensor edited or removed."""
    part = data.draw(st.sampled_from(["tensor", "net_config", "meta", "top", "state_dict"]), label="part")
    if part == "tensor":
        name = data.draw(st.sampled_from(sorted(doc["state_dict"])), label="weight")
        doc["state_dict"][name] = edit_tensor(data, doc["state_dict"][name])
    elif part == "state_dict":
        keys = sorted(doc["state_dict"])
        if data.draw(st.booleans(), label="drop?"):
            del doc["state_dict"][data.draw(st.sampled_from(keys), label="weight")]
        else:
            doc["state_dict"][data.draw(st.text(max_size=8), label="name")] = torch.zeros(2)
    elif part in ("net_config", "meta"):
        doc[part] = mutate(data, doc[part])
    else:
        key = data.draw(st.sampled_from(sorted(doc)), label="key")
        if data.draw(st.booleans(), label="drop?"):
            del doc[key]
        else:
            doc[key] = data.draw(st.sampled_from(ODD_NUMBERS) | JSON | st.just(torch.zeros(1)), label="value")
    return doc


@FUZZ
@given(data=st.data())
def test_checkpoints_load_finite_or_raise_one_line(data, scratch):
    from adaptenv.agents.checkpoint import load_checkpoint, non_finite_weight

    raw = checkpoint_bytes()
    if data.draw(st.booleans(), label="bytes?"):
        raw = garble(data, raw)
    else:
        doc = torch.load(io.BytesIO(raw), map_location="cpu", weights_only=True)
        buffer = io.BytesIO()
        torch.save(mutate_checkpoint(data, doc), buffer)
        raw = buffer.getvalue()
    path = scratch / "policy.pt"
    path.write_bytes(raw)
    ckpt = expect_user_error(load_checkpoint, path)
    if ckpt is not None:
        assert non_finite_weight(ckpt.net) is None
        assert 0.0 <= float(ckpt.meta.get("end_threshold", 0.5)) <= 1.0
        ckpt.policy()  # the network and its metadata make a policy
