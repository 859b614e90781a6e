"""Executors: every kind returns exactly what a plain loop returns, in order, and re-raises worker errors.

Functions sent to workers must be importable top-level functions, and test modules are not
importable in a spawned worker (pytest's importlib mode), so the tests map stdlib functions
(``math.factorial``, ``int``, ``os.getenv``) and the benchmark's workload.
"""

from __future__ import annotations

import importlib.util
import math
import os
from pathlib import Path

import pytest

from adaptenv.curriculum.executor import (
    RAY_LOCAL_ENV,
    THREAD_ENV,
    Executor,
    ExecutorError,
    ExecutorOptions,
    InProcessExecutor,
    ProcessExecutor,
    RayExecutor,
    chunk_size,
    make_executor,
    split,
)
from adaptenv.errors import ConfigError
from tests.curriculum.loops import SHARES_RUNS

HAVE_RAY = importlib.util.find_spec("ray") is not None
NO_RAY = "ray is not installed (pip install 'adaptenv[ray]'); the Ray executor tests need it"

# CPU-bound and uneven on purpose: large items first, so later chunks tend to finish first.
ITEMS = [3000 - 10 * i for i in range(120)]
EXPECTED = [math.factorial(n) for n in ITEMS]


@pytest.fixture(scope="module")
def process_executor():
    with ProcessExecutor(workers=2) as ex:
        yield ex


@pytest.fixture(scope="module")
def ray_executor():
    if not HAVE_RAY:
        pytest.skip(NO_RAY)
    import ray

    assert not ray.is_initialized()
    env_before = {k: os.environ.get(k) for k in RAY_LOCAL_ENV}
    ex = RayExecutor(workers=2)  # a private local instance: num_cpus=2, bound to 127.0.0.1
    yield ex
    ex.close()
    assert not ray.is_initialized()  # the instance it started is shut down
    assert {k: os.environ.get(k) for k in RAY_LOCAL_ENV} == env_before  # and its settings undone


# --------------------------------------------------------------------------- construction


def test_make_executor_builds_each_kind_and_rejects_bad_options():
    assert isinstance(make_executor("inprocess"), InProcessExecutor)
    proc = make_executor("process", workers=3)
    assert isinstance(proc, ProcessExecutor) and proc.workers == 3
    ray_ex = make_executor("ray", workers=2, address="127.0.0.1:6379")
    assert isinstance(ray_ex, RayExecutor) and ray_ex.workers == 2  # nothing starts before the first map
    for ex in (make_executor("inprocess"), proc, ray_ex):
        assert isinstance(ex, Executor)
    assert isinstance(ExecutorOptions("process", 2).make(), ProcessExecutor)

    with pytest.raises(ConfigError, match="--executor"):
        make_executor("threads")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="--workers"):
        make_executor("process", workers=0)
    with pytest.raises(ConfigError, match="--workers 2 needs --executor process or ray"):
        make_executor("inprocess", workers=2)
    with pytest.raises(ConfigError, match="--address is only used by --executor ray"):
        make_executor("process", workers=2, address="127.0.0.1:6379")


def test_chunks_cover_every_item_once_in_order():
    items = list(range(103))
    for size in (1, 7, 103, 500):
        assert [x for c in split(items, size) for x in c] == items
    assert chunk_size(10, 2) == 1 and chunk_size(1600, 2) == 100 and chunk_size(1600, 2, chunksize=3) == 3


# --------------------------------------------------------------------------- results equal a plain loop


def test_inprocess_equals_a_plain_loop():
    with InProcessExecutor() as ex:
        assert ex.map(math.factorial, ITEMS, desc="factorials") == EXPECTED
        assert ex.map(lambda x: x + 1, [1, 2]) == [2, 3]  # any callable works in process
        assert ex.map(math.factorial, []) == []


def test_process_pool_equals_a_plain_loop(process_executor):
    assert process_executor.workers == 2
    assert process_executor.map(math.factorial, ITEMS) == EXPECTED
    assert process_executor.map(math.factorial, iter(ITEMS), desc="factorials") == EXPECTED  # any iterable
    assert process_executor.map(math.factorial, []) == []


def test_process_pool_with_one_item_per_task_keeps_the_order():
    with ProcessExecutor(workers=2, chunksize=1) as ex:
        assert ex.map(math.factorial, ITEMS[:30]) == EXPECTED[:30]


def test_process_workers_run_with_one_thread_per_library(process_executor):
    names = sorted(THREAD_ENV)
    assert process_executor.map(os.getenv, names) == [THREAD_ENV[n] for n in names]


# --------------------------------------------------------------------------- errors


def test_inprocess_exception_propagates():
    with pytest.raises(ValueError, match="invalid literal for int"):
        InProcessExecutor().map(int, ["1", "x"])


def test_process_worker_exception_is_re_raised_with_its_message_first_failure_in_order(process_executor):
    items = ["1", "bad-a", *(str(i) for i in range(40)), "bad-b"]
    with pytest.raises(ValueError) as info:
        process_executor.map(int, items)
    assert str(info.value) == "invalid literal for int() with base 10: 'bad-a'"
    assert process_executor.map(int, ["4", "5"]) == [4, 5]  # the pool survives a failed map


def test_process_rejects_functions_that_cannot_reach_a_worker(process_executor):
    with pytest.raises(ConfigError, match="top-level function"):
        process_executor.map(lambda x: x, [1])


def test_close_is_idempotent_and_the_pool_restarts_on_demand():
    ex = ProcessExecutor(workers=1)
    ex.close()
    assert ex.map(math.factorial, [5]) == [120]
    ex.close()
    ex.close()
    assert ex.map(math.factorial, [4]) == [24]
    ex.close()


# --------------------------------------------------------------------------- the project's workload


@pytest.mark.slow
def test_expert_episodes_in_worker_processes_equal_the_in_process_loop(process_executor):
    from adaptenv.bench.executor import expert_level

    work = [(11, 1), (12, 1), (13, 2)]
    assert process_executor.map(expert_level, work) == [expert_level(x) for x in work]


@pytest.mark.slow
def test_the_loops_evaluation_jobs_in_worker_processes_equal_the_in_process_loop(process_executor):
    from adaptenv.bench.executor import HELDOUT_CHUNK, heldout_chunk, heldout_items

    work = heldout_items(episodes=HELDOUT_CHUNK + 10)
    assert [(j.start, j.stop) for j in work] == [(0, HELDOUT_CHUNK), (HELDOUT_CHUNK, HELDOUT_CHUNK + 10)]
    local = [heldout_chunk(j) for j in work]
    assert process_executor.map(heldout_chunk, work) == local
    assert sum(len(c) for c in local) == HELDOUT_CHUNK + 10 and any(success for c in local for success, *_ in c)


# --------------------------------------------------------------------------- Ray (local instance)


@pytest.mark.slow
@pytest.mark.skipif(not HAVE_RAY, reason=NO_RAY)
def test_ray_equals_a_plain_loop_and_re_raises_worker_errors(ray_executor):
    assert ray_executor.map(math.factorial, ITEMS, desc="factorials") == EXPECTED
    assert ray_executor.map(math.factorial, []) == []
    names = sorted(THREAD_ENV)
    assert ray_executor.map(os.getenv, names) == [THREAD_ENV[n] for n in names]

    with pytest.raises(ValueError) as info:
        ray_executor.map(int, ["1", "bad-a", "2", "bad-b"])
    assert type(info.value) is ValueError
    assert str(info.value) == "invalid literal for int() with base 10: 'bad-a'"
    assert ray_executor.map(int, ["7"]) == [7]

    with pytest.raises(ConfigError, match="top-level function"):
        ray_executor.map(lambda x: x, [1])

    import ray

    nodes = ray.nodes()
    assert nodes and all(n["NodeManagerAddress"] == "127.0.0.1" for n in nodes)


def test_missing_ray_is_reported_with_the_pip_extra(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "ray", None)  # makes `import ray` fail as if not installed
    with pytest.raises(ExecutorError, match=r"pip install 'adaptenv\[ray\]'"):
        RayExecutor(workers=1).map(math.factorial, [3])


def test_a_dead_worker_is_reported_and_the_pool_restarts():
    with ProcessExecutor(workers=1) as ex:
        with pytest.raises(ExecutorError, match="worker process died"):
            ex.map(os._exit, [3])  # the worker exits without a result
        assert ex.map(math.factorial, [6]) == [720]


@pytest.mark.slow
@SHARES_RUNS
@pytest.mark.skipif(not HAVE_RAY, reason=NO_RAY)
def test_a_loop_on_ray_gives_the_in_process_records(ray_executor, tiny_policy, loop_run, tmp_path):
    from adaptenv.curriculum.loop import run_loop
    from tests.curriculum.loops import tiny_config

    cfg = tiny_config(tiny_policy, "ours", iterations=1)  # test_loop.py's same-seed test runs it in process too
    local, _ = loop_run(cfg)
    remote = run_loop(cfg, tmp_path / "ray", executor=ray_executor)
    strip = [r.model_dump(exclude={"wall_time_s", "stage_seconds"}) for r in remote]
    assert strip == [r.model_dump(exclude={"wall_time_s", "stage_seconds"}) for r in local]


def test_experiment_runs_go_to_the_workers_one_per_task(monkeypatch, tmp_path):
    """Runs are long: one per task keeps them in order, so a stopped experiment leaves whole seeds."""
    from typer.testing import CliRunner

    from adaptenv.cli import app

    asked = {}

    def refuse(*args, **kwargs):
        asked.update(kwargs)
        raise ConfigError("stop here")

    monkeypatch.setattr("adaptenv.curriculum.executor.make_executor", refuse)
    config = Path(__file__).resolve().parents[2] / "configs" / "experiment-small.json"
    res = CliRunner().invoke(app, ["experiment", "--config", str(config), "-o", str(tmp_path),
                                   "--executor", "process", "--workers", "2"])
    assert isinstance(res.exception, ConfigError) and str(res.exception) == "stop here"
    assert asked == {"chunksize": 1}
