"""One task runner (:func:`run_tasks`: serial, threads or Dask, one error policy) and the Dask clients.

``scheduler``:

* ``local``: a :class:`dask.distributed.LocalCluster` on this machine, localhost only, one
  single-threaded worker process per core (``n_workers`` overrides), no dashboard;
* ``tcp://HOST:PORT``: the scheduler of an existing cluster (``dask scheduler`` and
  ``dask worker tcp://HOST:PORT`` started by the user); the workers must run the same
  exposim and see the recordings and the output folder under the same paths.

Every task (e.g. a dataset unit, :func:`emulator.datasetrun.run_unit`) is submitted with
``retries`` (a task that raises is run again) and ``pure=False``; a worker that dies
mid-task makes the scheduler run the task again on another worker (up to its
``distributed.scheduler.allowed-failures``, which :func:`local_client` sets to ``retries``).
A unit writes its run folder under a staging name and renames it when complete, so a lost
attempt leaves no rows behind and a repeated one writes nothing twice.  Nothing here prints.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import as_completed as as_completed_threads
from contextlib import contextmanager
from dataclasses import dataclass

from emulator.errors import ExposimError

__all__ = ["SchedulerError", "default_workers", "local_client", "connect", "open_client", "run_tasks", "Outcome"]


class SchedulerError(ExposimError):
    """A Dask scheduler that cannot be started or reached, or a unit that failed on it."""


def default_workers() -> int:
    """Worker processes of a local cluster: the CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


@contextmanager
def local_client(n_workers: int | None = None, *, allowed_failures: int = 3):
    """A client of a fresh ``LocalCluster`` (processes, one thread each, localhost, no dashboard)."""
    import dask
    from dask.distributed import Client, LocalCluster

    n = int(n_workers or default_workers())
    if n < 1:
        raise SchedulerError(f"n_workers must be >= 1, got {n_workers!r}")
    with dask.config.set({"distributed.scheduler.allowed-failures": int(allowed_failures),
                          "distributed.worker.daemon": False}):
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, silence_logs=logging.CRITICAL)  # task errors come back through the futures
        try:
            with Client(cluster) as client:
                yield client
        finally:
            cluster.close()


@contextmanager
def connect(address: str, *, timeout_s: float = 10.0):
    """A client of an existing scheduler at ``tcp://HOST:PORT``; :class:`SchedulerError` if unreachable."""
    from dask.distributed import Client

    try:
        client = Client(address, timeout=f"{timeout_s}s")
    except (OSError, TimeoutError) as exc:
        raise SchedulerError(f"{address}: cannot reach the Dask scheduler ({exc})") from None
    try:
        if not client.scheduler_info().get("workers"):
            client.wait_for_workers(1, timeout=timeout_s)
        yield client
    except TimeoutError:
        raise SchedulerError(f"{address}: the Dask scheduler has no worker (start one: dask worker {address})") from None
    finally:
        client.close()


def open_client(scheduler: str, *, n_workers: int | None = None, retries: int = 2):
    """A client context for ``local`` (a fresh LocalCluster) or ``tcp://HOST:PORT`` (an existing scheduler)."""
    if scheduler == "local":
        return local_client(n_workers, allowed_failures=max(int(retries), 0) + 1)
    if str(scheduler).startswith("tcp://"):
        return connect(scheduler)
    raise SchedulerError(f"unknown scheduler {scheduler!r}; use serial, local or tcp://HOST:PORT")


@dataclass
class Outcome:
    """One task's outcome: its result, or its error as ``"Type: message"`` (never both)."""

    key: str
    result: object = None
    error: str | None = None


def _error_text(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


def _guarded(fn: Callable, args: tuple, key: str) -> Outcome:
    try:
        return Outcome(key, fn(*args))
    except Exception as exc:  # any failure of a task is its row; KeyboardInterrupt still stops the run
        return Outcome(key, error=_error_text(exc))


def run_tasks(
    fn: Callable,
    arg_tuples: Sequence[tuple],
    *,
    client=None,
    threads: int = 1,
    retries: int = 2,
    progress: Callable[[int, int], None] | None = None,
    keys: Sequence[str] | None = None,
) -> list[Outcome]:
    """Run ``fn(*args)`` for every tuple of ``arg_tuples``: serially, on threads, or as Dask tasks.

    One error policy on every path: a task that raises any :class:`Exception` becomes an
    :class:`Outcome` with ``error`` (``"Type: message"``), the others go on, nothing aborts
    silently; on Dask a failed task is first retried ``retries`` times (a worker that dies
    mid-task is rescheduled by the scheduler), in this process it is not (a task that
    fails here fails the same way again).  ``fn`` must be a pure function of its
    arguments that writes only its own outputs, so the bytes written are the same on
    every path.  Returns the outcomes in the order of ``arg_tuples``; ``progress(done,
    total)`` after each task.  ``keys`` name the tasks (default: their index).
    """
    arg_tuples = [tuple(a) for a in arg_tuples]
    keys = [str(i) for i in range(len(arg_tuples))] if keys is None else [str(k) for k in keys]
    if len(keys) != len(arg_tuples):
        raise ValueError("keys and arg_tuples differ in length")
    total = len(arg_tuples)
    outcomes: dict[int, Outcome] = {}

    def done(i: int, outcome: Outcome) -> None:
        outcomes[i] = outcome
        if progress is not None:
            progress(len(outcomes), total)

    if client is not None:
        from dask.distributed import as_completed

        futures = {}
        for i, (args, key) in enumerate(zip(arg_tuples, keys)):
            fut = client.submit(fn, *args, retries=int(retries), pure=False,
                                key=f"exposim-task-{key}-{os.urandom(4).hex()}")
            futures[fut] = i
        for fut in as_completed(list(futures)):
            i = futures[fut]
            try:
                done(i, Outcome(keys[i], fut.result()))
            except Exception as exc:  # the task's own error, KilledWorker, a lost connection: in its row
                done(i, Outcome(keys[i], error=_error_text(exc)))
    elif int(threads) > 1:
        with ThreadPoolExecutor(max_workers=int(threads), thread_name_prefix="exposim-task") as pool:
            futures = {pool.submit(_guarded, fn, args, key): i for i, (args, key) in enumerate(zip(arg_tuples, keys))}
            for fut in as_completed_threads(futures):
                done(futures[fut], fut.result())
    else:
        for i, (args, key) in enumerate(zip(arg_tuples, keys)):
            done(i, _guarded(fn, args, key))
    return [outcomes[i] for i in range(total)]
