"""One way to run many independent jobs (rollouts, evaluation, generation): in process, a pool, or Ray.

Every executor has the same contract, so a command can switch with ``--executor``:

- ``map(fn, items, desc=None) -> list`` returns ``[fn(x) for x in items]``: same order, same values.
  The executor adds no randomness; an item must carry its own seed.
- For the ``process`` and ``ray`` kinds ``fn`` must be picklable by reference: a top-level function
  of an importable module (no lambda, no closure, nothing defined in ``__main__`` of a script run
  without an ``if __name__ == "__main__"`` guard). Items and results are pickled too.
- An exception raised by ``fn`` in a worker is raised again in the caller with its original type
  and message (the first failing item in order, as a plain loop would); the worker's traceback
  is chained as the cause.
- Workers run with one numba/OpenMP/BLAS/torch thread each (:data:`THREAD_ENV`), so N workers use
  N cores and never oversubscribe the machine.

The local pool uses the ``spawn`` start method: workers are fresh interpreters, so no lock or
thread of torch's and numba's OpenMP/TBB pools held by the parent is inherited (``fork`` after
those pools start can deadlock), and it behaves the same on Linux, macOS and Windows. Spawning
costs about a second per worker (imports, numba cache loading), paid once: keep one executor open
for a whole run instead of creating one per call.

Example:
    >>> from adaptenv.curriculum.executor import make_executor
    >>> with make_executor("process", workers=2) as ex:  # doctest: +SKIP
    ...     lengths = ex.map(run_one_episode, [(house_id, seed) for seed in range(8)])
"""

from __future__ import annotations

import concurrent.futures as cf
import functools
import multiprocessing
import os
import pickle
import sys
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Literal, Protocol, Self, TypeVar, runtime_checkable

import typer

from adaptenv.errors import AdaptenvError, ConfigError
from adaptenv.progress import ProgressBar

T = TypeVar("T")
R = TypeVar("R")

ExecutorKind = Literal["inprocess", "process", "ray"]
KINDS: tuple[str, ...] = ("inprocess", "process", "ray")

#: Environment of every worker: one thread per library, so N workers keep to N cores.
THREAD_ENV: dict[str, str] = {
    "NUMBA_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "VECLIB_MAXIMUM_THREADS": "1",
    "NUMEXPR_NUM_THREADS": "1",
}

#: Chunks per worker when the chunk size is automatic: small enough to balance uneven items,
#: large enough that tiny items do not pay one round trip each.
CHUNKS_PER_WORKER = 8

RAY_EXTRA_HINT = "pip install 'adaptenv[ray]'"


class ExecutorError(AdaptenvError):
    """The executor itself failed (a worker process died, Ray is missing or unreachable)."""


@runtime_checkable
class Executor(Protocol):
    """Runs ``fn`` over items, in order, possibly in parallel; see the module docstring for the contract."""

    @property
    def workers(self) -> int:
        """How many items can run at the same time."""
        ...

    def map(self, fn: Callable[[T], R], items: Iterable[T], *, desc: str | None = None) -> list[R]:
        """``[fn(x) for x in items]``, computed by the workers; a rich progress bar when ``desc`` is set."""
        ...

    def close(self) -> None:
        """Release the workers (idempotent)."""
        ...

    def __enter__(self) -> Self: ...

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None: ...


# --------------------------------------------------------------------------- worker side


def limit_threads() -> None:
    """Apply :data:`THREAD_ENV` in this process and cap torch/numba threads if they are already loaded."""
    os.environ.update(THREAD_ENV)
    torch = sys.modules.get("torch")
    if torch is not None and torch.get_num_threads() != 1:
        torch.set_num_threads(1)
    numba = sys.modules.get("numba")
    if numba is not None and numba.get_num_threads() != 1:
        numba.set_num_threads(1)


def _run_chunk(fn: Callable[[Any], Any], chunk: Sequence[Any]) -> list[Any]:
    """Worker body: apply ``fn`` to one chunk of items (threads capped first)."""
    limit_threads()
    return [fn(x) for x in chunk]


# --------------------------------------------------------------------------- helpers


def chunk_size(n_items: int, workers: int, chunksize: int | None = None) -> int:
    """Items per task: ``chunksize`` if given, else about CHUNKS_PER_WORKER tasks per worker."""
    if chunksize is not None:
        return max(1, int(chunksize))
    return max(1, n_items // (workers * CHUNKS_PER_WORKER))


def split(items: Sequence[T], size: int) -> list[Sequence[T]]:
    """Consecutive chunks of ``size`` items (the last may be shorter)."""
    return [items[i:i + size] for i in range(0, len(items), size)]


def check_picklable(fn: Callable[..., Any], kind: str) -> None:
    """Fail early, in one sentence, when ``fn`` cannot be sent to a worker process."""
    try:
        pickle.dumps(fn)
    except Exception as exc:
        name = getattr(fn, "__qualname__", repr(fn))
        raise ConfigError(f"executor {kind}: cannot send {name} to a worker ({exc}); pass a top-level "
                          "function of an importable module (no lambda or closure), or use --executor inprocess") from exc


class _Base:
    """Context-manager plumbing shared by the executors."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:  # pragma: no cover - overridden
        """Release the workers (idempotent)."""


# --------------------------------------------------------------------------- executors


class InProcessExecutor(_Base):
    """Runs items one after the other in the calling process (the default; any callable works)."""

    @property
    def workers(self) -> int:
        return 1

    def map(self, fn: Callable[[T], R], items: Iterable[T], *, desc: str | None = None) -> list[R]:
        """``[fn(x) for x in items]`` with an optional progress bar."""
        items = list(items)
        out: list[R] = []
        with ProgressBar(desc, len(items)) as bar:
            for x in items:
                out.append(fn(x))
                bar.advance()
        return out

    def close(self) -> None:
        """Nothing to release."""

    def __repr__(self) -> str:
        return "InProcessExecutor()"


class ProcessExecutor(_Base):
    """A local pool of ``workers`` spawned processes (``concurrent.futures``), started on first use.

    Args:
        workers: number of worker processes (default: the machine's CPU count).
        chunksize: items per task; None picks about CHUNKS_PER_WORKER tasks per worker.
        start_method: ``spawn`` (default, see the module docstring) or ``forkserver``.
    """

    def __init__(self, workers: int | None = None, *, chunksize: int | None = None,
                 start_method: Literal["spawn", "forkserver"] = "spawn"):
        self._workers = _check_workers(workers if workers is not None else (os.cpu_count() or 1), "process")
        self._chunksize = chunksize
        self._start_method = start_method
        self._pool: cf.ProcessPoolExecutor | None = None

    @property
    def workers(self) -> int:
        return self._workers

    def _ensure(self) -> cf.ProcessPoolExecutor:
        if self._pool is None:
            ctx = multiprocessing.get_context(self._start_method)
            self._pool = cf.ProcessPoolExecutor(max_workers=self._workers, mp_context=ctx, initializer=limit_threads)
        return self._pool

    def map(self, fn: Callable[[T], R], items: Iterable[T], *, desc: str | None = None) -> list[R]:
        """``[fn(x) for x in items]`` computed by the pool, in order."""
        items = list(items)
        if not items:
            return []
        check_picklable(fn, "process")
        pool = self._ensure()
        chunks = split(items, chunk_size(len(items), self._workers, self._chunksize))
        with ProgressBar(desc, len(items)) as bar:
            futures = []
            for chunk in chunks:
                fut = pool.submit(_run_chunk, fn, chunk)
                fut.add_done_callback(functools.partial(_advance_when_done, bar, len(chunk)))
                futures.append(fut)
            try:
                return _collect(futures)
            except ExecutorError:
                self._pool = None  # broken: the next map starts a fresh pool
                pool.shutdown(wait=False, cancel_futures=True)
                raise

    def close(self) -> None:
        """Stop the worker processes (pending items are cancelled)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def __repr__(self) -> str:
        return f"ProcessExecutor(workers={self._workers}, start_method={self._start_method!r})"


def _advance_when_done(bar: ProgressBar, n: int, fut: cf.Future) -> None:
    """Done-callback of a chunk future: move the bar unless the chunk was cancelled."""
    if not fut.cancelled():
        bar.advance(n)


def _collect(futures: list[cf.Future]) -> list[Any]:
    """Results of chunk futures in order; the first failure (in order) cancels the rest and is re-raised."""
    out: list[Any] = []
    try:
        for fut in futures:
            out.extend(fut.result())
    except BrokenProcessPool as exc:
        raise ExecutorError(f"a worker process died ({exc}); it may have run out of memory or crashed in "
                            "native code; rerun with --executor inprocess to see the error") from exc
    except BaseException:
        for fut in futures:
            fut.cancel()
        raise
    return out


#: Environment of a local Ray instance: loopback addresses only, no usage reporting.
RAY_LOCAL_ENV: dict[str, str] = {
    "RAY_USAGE_STATS_ENABLED": "0",
    # Ray's switch for single-machine use (its default on macOS and Windows): every Ray process
    # binds and advertises 127.0.0.1 instead of the machine's network address.
    "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0",
}


def _loopback_only() -> dict[str, Any]:
    """Make the next ``ray.init`` start a 127.0.0.1-only instance; returns what to restore afterwards."""
    saved: dict[str, Any] = {"env": {k: os.environ.get(k) for k in RAY_LOCAL_ENV}}
    os.environ.update(RAY_LOCAL_ENV)  # inherited by the Ray processes this driver starts
    constants = sys.modules.get("ray._private.ray_constants")
    if constants is not None and hasattr(constants, "ENABLE_RAY_CLUSTER"):  # read once, at ray import
        saved["ENABLE_RAY_CLUSTER"] = constants.ENABLE_RAY_CLUSTER
        constants.ENABLE_RAY_CLUSTER = False
    return saved


def _restore_loopback(saved: dict[str, Any]) -> None:
    """Put back the environment and Ray constant changed by :func:`_loopback_only`."""
    for key, value in saved["env"].items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value
    constants = sys.modules.get("ray._private.ray_constants")
    if constants is not None and "ENABLE_RAY_CLUSTER" in saved:
        constants.ENABLE_RAY_CLUSTER = saved["ENABLE_RAY_CLUSTER"]


def _import_ray() -> Any:
    """Import ray, or fail naming the pip extra."""
    try:
        import ray
    except ImportError as exc:
        raise ExecutorError(f"--executor ray needs the ray package, which is not installed; run: {RAY_EXTRA_HINT}") from exc
    return ray


class RayExecutor(_Base):
    """Runs chunks of items as Ray tasks, on a local Ray instance or an existing cluster.

    Without ``address`` a private local instance (``num_cpus=workers``, no dashboard, bound to
    127.0.0.1, usage statistics off) is started on first use and shut down by :meth:`close`.
    With ``address`` (``ray://host:10001`` or ``host:6379``) it connects to that cluster and only
    disconnects on close. If Ray is already initialized in this process it is reused and left
    running. Workers get :data:`THREAD_ENV` through the job's runtime environment.

    Args:
        workers: CPUs of the local instance, and the parallelism used to size chunks (default:
            the machine's CPU count; with ``address``, the cluster's CPUs when connected).
        address: a Ray cluster to connect to, or None for a local instance.
        chunksize: items per task; None picks about CHUNKS_PER_WORKER tasks per worker.
    """

    def __init__(self, workers: int | None = None, address: str | None = None, *, chunksize: int | None = None):
        self._requested = None if workers is None else _check_workers(workers, "ray")
        self._address = address
        self._chunksize = chunksize
        self._ray: Any = None
        self._remote: Any = None
        self._owns = False
        self._saved: dict[str, Any] | None = None

    @property
    def workers(self) -> int:
        if self._requested is not None:
            return self._requested
        if self._ray is not None:
            return max(1, int(self._ray.cluster_resources().get("CPU", 1)))
        return os.cpu_count() or 1

    def _ensure(self) -> Any:
        if self._ray is not None:
            return self._ray
        ray = _import_ray()
        if not ray.is_initialized():
            import logging

            common = {"include_dashboard": False, "log_to_driver": False, "logging_level": logging.WARNING,
                      "runtime_env": {"env_vars": dict(THREAD_ENV)}}
            try:
                if self._address is None:
                    self._saved = _loopback_only()
                    ray.init(address="local", num_cpus=self.workers, **common)
                else:
                    ray.init(address=self._address, **common)
            except Exception as exc:
                self._restore()
                where = self._address or "a local instance"
                raise ExecutorError(f"could not start Ray on {where} ({exc}); check --address, or use "
                                    "--executor process") from exc
            self._owns = True
        self._ray = ray
        self._remote = ray.remote(num_cpus=1)(_run_chunk)
        return ray

    def map(self, fn: Callable[[T], R], items: Iterable[T], *, desc: str | None = None) -> list[R]:
        """``[fn(x) for x in items]`` computed as Ray tasks, gathered in order with ``ray.get``.

        All tasks run to the end before a worker error is raised (the process pool cancels the
        items not yet started instead).
        """
        items = list(items)
        if not items:
            return []
        check_picklable(fn, "ray")
        ray = self._ensure()
        chunks = split(items, chunk_size(len(items), self.workers, self._chunksize))
        fn_ref = ray.put(fn)
        refs = [self._remote.remote(fn_ref, chunk) for chunk in chunks]
        sizes = {ref: len(chunk) for ref, chunk in zip(refs, chunks, strict=True)}
        pending = list(refs)
        with ProgressBar(desc, len(items)) as bar:
            try:
                while pending:
                    done, pending = ray.wait(pending, num_returns=1)
                    bar.advance(sizes[done[0]])
            except BaseException:
                for ref in pending:  # interrupted: stop the tasks that have not finished
                    ray.cancel(ref)
                raise
        # Every task has finished here (cancelling finished tasks can crash Ray's task manager).
        out: list[Any] = []
        for ref in refs:
            try:
                out.extend(ray.get(ref))
            except ray.exceptions.RayTaskError as exc:
                cause = getattr(exc, "cause", None)
                if isinstance(cause, BaseException):
                    raise cause from exc
                raise
        return out

    def close(self) -> None:
        """Shut down the Ray instance this executor started (or disconnect from the cluster)."""
        if self._ray is not None and self._owns:
            self._ray.shutdown()
        self._restore()
        self._ray = None
        self._remote = None
        self._owns = False

    def _restore(self) -> None:
        """Undo :func:`_loopback_only` (environment and Ray constant) once the local instance is gone."""
        if self._saved is not None:
            _restore_loopback(self._saved)
            self._saved = None

    def __repr__(self) -> str:
        return f"RayExecutor(workers={self._requested}, address={self._address!r})"


# --------------------------------------------------------------------------- construction and CLI


def _check_workers(workers: int, kind: str) -> int:
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError(f"--workers: expected a positive integer for --executor {kind}, got {workers!r}")
    return workers


def check_executor(kind: str, workers: int | None = None, address: str | None = None) -> None:
    """Raise one ConfigError when ``--executor/--workers/--address`` do not go together (see :func:`make_executor`);
    commands call it before any work."""
    if kind not in KINDS:
        raise ConfigError(f"--executor: expected one of {', '.join(KINDS)}, got {kind!r}")
    if address is not None and kind != "ray":
        raise ConfigError(f"--address is only used by --executor ray, got --executor {kind}; drop --address "
                          "or add --executor ray")
    if kind == "inprocess" and workers is not None and _check_workers(workers, kind) != 1:
        raise ConfigError(f"--workers {workers} needs --executor process or ray; inprocess runs one item at a time")


def make_executor(kind: ExecutorKind = "inprocess", workers: int | None = None,
                  address: str | None = None, *, chunksize: int | None = None) -> Executor:
    """Build the executor the ``--executor/--workers/--address`` options ask for.

    ``workers`` defaults to 1 in process and to the CPU count for ``process``; ``address`` is only
    meaningful for ``ray``; ``chunksize`` (items per task) is ``process``'s and ``ray``'s.

    Raises:
        ConfigError: for an unknown kind, a non-positive worker count, ``--workers`` above 1 with
            ``inprocess``, or ``--address`` without ``ray``.
    """
    check_executor(kind, workers, address)
    if kind == "inprocess":
        return InProcessExecutor()
    if kind == "process":
        return ProcessExecutor(workers, chunksize=chunksize)
    return RayExecutor(workers, address, chunksize=chunksize)


EXECUTOR_OPTION = typer.Option("inprocess", "--executor",
                               help="Where jobs run: inprocess (one at a time), process (local pool), ray.")
WORKERS_OPTION = typer.Option(None, "--workers", min=1,
                              help="Parallel workers for --executor process|ray (default: the CPU count).")
ADDRESS_OPTION = typer.Option(None, "--address", metavar="ADDRESS",
                              help="Ray cluster to connect to (default: start a local Ray instance).")


@dataclass(frozen=True)
class ExecutorOptions:
    """The executor a command was asked for; build it with :meth:`make` inside the command.

    Use the three option constants as parameter defaults, then combine them:

    Example:
        >>> def evaluate(executor: ExecutorKind = EXECUTOR_OPTION,  # doctest: +SKIP
        ...              workers: int | None = WORKERS_OPTION, address: str | None = ADDRESS_OPTION):
        ...     with ExecutorOptions(executor, workers, address).make() as ex:
        ...         results = ex.map(run_one, items, desc="evaluating")
    """

    kind: ExecutorKind = "inprocess"
    """inprocess, process or ray."""
    workers: int | None = None
    """Parallel workers (None: 1 in process, the CPU count otherwise)."""
    address: str | None = None
    """Ray cluster address (None: a local Ray instance)."""

    def check(self) -> ExecutorOptions:
        """Return self, or raise one ConfigError when the options do not go together (before any work)."""
        check_executor(self.kind, self.workers, self.address)
        return self

    def make(self) -> Executor:
        """The executor (see :func:`make_executor`)."""
        return make_executor(self.kind, self.workers, self.address)


__all__ = [
    "ADDRESS_OPTION", "EXECUTOR_OPTION", "KINDS", "THREAD_ENV", "WORKERS_OPTION", "Executor", "ExecutorError",
    "ExecutorKind", "ExecutorOptions", "InProcessExecutor", "ProcessExecutor", "RayExecutor", "check_executor",
    "make_executor",
]
