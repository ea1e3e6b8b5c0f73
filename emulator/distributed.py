"""Dask execution of dataset units (:mod:`emulator.datasetrun`): a local cluster or an existing one.

``scheduler``:

* ``local``: a :class:`dask.distributed.LocalCluster` on this machine, localhost only, one
  single-threaded worker process per core (``n_workers`` overrides), no dashboard;
* ``tcp://HOST:PORT``: the scheduler of an existing cluster (``dask scheduler`` and
  ``dask worker tcp://HOST:PORT`` started by the user); the workers must run the same
  exposim and see the recordings and the output folder under the same paths.

Every unit is one task (:func:`emulator.datasetrun.run_unit`), submitted with
``retries`` (a unit that raises is run again) and ``pure=False``; a worker that dies
mid-task makes the scheduler run the task again on another worker (up to its
``distributed.scheduler.allowed-failures``, which :func:`local_client` sets to ``retries``).
A unit writes its run folder under a staging name and renames it when complete, so a lost
attempt leaves no rows behind and a repeated one writes nothing twice.  Nothing here prints.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Mapping
from contextlib import contextmanager
from pathlib import Path

from emulator.errors import ExposimError

__all__ = ["SchedulerError", "default_workers", "local_client", "connect", "open_client", "run_units"]


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


def run_units(
    client,
    units: list,
    out_dir: str | os.PathLike,
    options: Mapping,
    *,
    retries: int = 2,
    progress: Callable[[int, int], None] | None = None,
    fault_marker: str | None = None,
) -> tuple[list[dict], list[dict]]:
    """Run units as tasks of ``client``; returns (records of the units that finished, errors of those that failed)."""
    from dask.distributed import as_completed

    from emulator.datasetrun import run_unit

    out = str(Path(out_dir).resolve())
    records: list[dict] = []
    errors: list[dict] = []
    futures = {}
    for unit in units:
        fut = client.submit(run_unit, unit, out, dict(options), fault_marker=fault_marker, retries=int(retries),
                            pure=False, key=f"exposim-unit-{unit.key}-{os.urandom(4).hex()}")
        futures[fut] = unit
    for i, fut in enumerate(as_completed(list(futures)), 1):
        unit = futures[fut]
        try:
            records.append(fut.result())
        except Exception as exc:  # an ExposimError of a bad sequence, KilledWorker, a crash: in the unit's row
            errors.append({"unit": unit.key, "error": f"{type(exc).__name__}: {exc}"})
        if progress is not None:
            progress(i, len(units))
    return records, errors
