"""One task runner (:func:`run_tasks`: serial, threads or Dask, one error policy) and the Dask clients.

``scheduler`` (see :func:`open_client`):

* ``local``: a :class:`dask.distributed.LocalCluster` on this machine, localhost only, one
  single-threaded worker process per core (``n_workers`` overrides), no dashboard, worker
  scratch space in a temporary folder removed on exit;
* ``tcp://HOST:PORT`` or ``tls://HOST:PORT``: the scheduler of an existing cluster
  (``dask scheduler`` and ``dask worker ADDRESS`` started by the user; TLS certificates come
  from Dask's own configuration, ``distributed.comm.tls``); the workers must run the same
  exposim and see the recordings and the output folder under the same paths;
* a scheduler file (``scheduler_file=PATH``, what ``dask scheduler --scheduler-file PATH``
  and dask-jobqueue write);
* a :class:`distributed.Client` the caller made (a ``dask_jobqueue.SLURMCluster``'s), used
  as it is and left open.

:func:`resolve_scheduler` picks one for the command line: ``--scheduler-file``, else
``--scheduler``, else ``$DASK_SCHEDULER_ADDRESS``, else the caller's default.

Every task (e.g. a dataset unit, :func:`emulator.orchestration.datasetrun.run_unit`) is submitted with
``retries`` (a task that raises is run again) and ``pure=False``; a worker that dies
mid-task makes the scheduler run the task again on another worker (up to its
``distributed.scheduler.allowed-failures``, which :func:`local_client` sets to ``retries``).
A unit writes its run folder under a staging name and renames it when complete, so a lost
attempt leaves no rows behind and a repeated one writes nothing twice.  Nothing here prints.
"""

from __future__ import annotations

import gc
import logging
import os
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import as_completed as as_completed_threads
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path

from emulator.errors import ExposimError
from emulator.extras import missing_modules, require

__all__ = ["SchedulerError", "ENV_ADDRESS", "SCHEDULER_HELP", "default_workers", "is_address", "is_client",
           "check_scheduler", "resolve_scheduler", "local_client", "connect", "open_client", "run_tasks", "Outcome"]


class SchedulerError(ExposimError):
    """A Dask scheduler that cannot be started or reached, or a unit that failed on it."""


#: The environment variable Dask's own clients read for the scheduler's address.
ENV_ADDRESS = "DASK_SCHEDULER_ADDRESS"
#: Address schemes of an existing scheduler.
SCHEMES = ("tcp://", "tls://")
#: ``--help`` of the command line's ``--scheduler``.
SCHEDULER_HELP = ("'serial', 'local' (a Dask LocalCluster on this machine), or the address of a running Dask "
                  f"scheduler (tcp://HOST:PORT or tls://HOST:PORT); default: ${ENV_ADDRESS} when set")


def is_address(spec) -> bool:
    """True for ``tcp://HOST:PORT`` or ``tls://HOST:PORT`` (a running scheduler's address).

    >>> is_address("tls://10.0.0.1:8786"), is_address("local"), is_address("http://x:1")
    (True, False, False)
    """
    if not isinstance(spec, str) or not spec.startswith(SCHEMES):
        return False
    host, _, port = spec.split("://", 1)[1].rpartition(":")
    return bool(host) and port.isdigit()


def is_client(obj) -> bool:
    """True for a :class:`distributed.Client` (checked without importing Dask)."""
    return any(c.__name__ == "Client" and c.__module__.startswith("distributed") for c in type(obj).__mro__)


def check_scheduler(spec, *, serial_ok: bool = True):
    """``spec`` when it names a scheduler this module can use, else :class:`SchedulerError`."""
    if is_client(spec) or spec == "local" or is_address(spec) or (serial_ok and spec == "serial"):
        return spec
    raise SchedulerError(f"unknown scheduler {spec!r}; use serial, local, tcp://HOST:PORT or tls://HOST:PORT "
                         "(or --scheduler-file PATH)")


def resolve_scheduler(scheduler: str | None, scheduler_file=None, *, default: str = "local",
                      environ: Mapping[str, str] | None = None) -> tuple[str, str | None]:
    """(scheduler, scheduler file) from the command line: the file, else ``scheduler``, else ``$DASK_SCHEDULER_ADDRESS``.

    The file's scheduler is returned as ``"file"``.  ``default`` applies when nothing is
    given; ``local`` falls back to ``serial`` when the ``dask`` extra is not installed.

    >>> resolve_scheduler(None, environ={"DASK_SCHEDULER_ADDRESS": "tls://h:8786"})
    ('tls://h:8786', None)
    >>> resolve_scheduler("serial", environ={"DASK_SCHEDULER_ADDRESS": "tcp://h:8786"})
    ('serial', None)
    """
    environ = os.environ if environ is None else environ
    if scheduler_file is not None:
        if scheduler not in (None, "file"):
            raise SchedulerError(f"give --scheduler {scheduler} or --scheduler-file {scheduler_file}, not both")
        path = Path(scheduler_file)
        if not path.is_file():
            raise SchedulerError(f"{path}: no such scheduler file (written by dask scheduler --scheduler-file)")
        return "file", str(path)
    if scheduler is not None:
        return check_scheduler(scheduler), None
    env = environ.get(ENV_ADDRESS, "").strip()
    if env:
        if not is_address(env):
            raise SchedulerError(f"${ENV_ADDRESS}={env!r} is not tcp://HOST:PORT or tls://HOST:PORT")
        return env, None
    if default == "local":
        if missing_modules("dask"):
            return "serial", None
    return check_scheduler(default), None


def default_workers() -> int:
    """Worker processes of a local cluster: the CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


@contextmanager
def local_client(n_workers: int | None = None, *, allowed_failures: int = 3):
    """A client of a fresh ``LocalCluster`` (processes, one thread each, localhost, no dashboard).

    The scheduler's HTTP server (health checks only, no dashboard) listens on a free
    localhost port, so a busy 8787 gives no warning; the workers' scratch space (spill
    files and their locks) lives in a temporary folder removed when the cluster closes.
    The scheduler never removes a silent worker (no ``worker-ttl``): its workers are this
    machine's processes, so a silence means the machine was suspended or the job paused
    (``SIGSTOP``), not a lost host. Dask's default of 5 minutes killed a walk's worker after
    such a pause, and three pauses failed the walk (``KilledWorker``).
    """
    import tempfile

    require("dask", "a Dask scheduler")
    import dask
    from dask.distributed import Client, LocalCluster

    n = int(n_workers or default_workers())
    if n < 1:
        raise SchedulerError(f"n_workers must be >= 1, got {n_workers!r}")
    # An unclosed Client left for the garbage collector closes itself in __del__, which takes the loop runner's
    # lock; collected inside the thread LocalCluster starts, it waits on the lock the starting thread holds
    # (seen once: a test process hung there). Collected here, before any lock is taken.
    gc.collect()
    with tempfile.TemporaryDirectory(prefix="exposim-dask-") as scratch, \
            dask.config.set({"distributed.scheduler.allowed-failures": int(allowed_failures),
                             "distributed.scheduler.worker-ttl": None,
                             "distributed.worker.daemon": False, "temporary-directory": scratch}):
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, local_directory=scratch,
                               scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
                               silence_logs=logging.CRITICAL)  # task errors come back through the futures
        try:
            with Client(cluster) as client:
                yield client
        finally:
            cluster.close()


@contextmanager
def connect(address: str | None = None, *, scheduler_file: str | None = None, timeout_s: float = 10.0):
    """A client of an existing scheduler (``tcp://`` or ``tls://`` address, or a scheduler file).

    :class:`SchedulerError` if it cannot be reached or has no worker.
    """
    require("dask", "a Dask scheduler")
    from dask.distributed import Client

    where = address if scheduler_file is None else f"scheduler file {scheduler_file}"
    # A Client whose start failed (e.g. a tls:// address without certificates) keeps its loop runner registered
    # until it is collected; a new Client would share that stopped loop and fail an assertion in distributed
    # (seen once under load, in test_a_tls_address_is_tried_and_named_when_unreachable). Collected here first.
    gc.collect()
    try:
        if scheduler_file is not None:
            client = Client(scheduler_file=str(scheduler_file), timeout=f"{timeout_s}s")
        else:
            client = Client(address, timeout=f"{timeout_s}s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise SchedulerError(f"{where}: cannot reach the Dask scheduler ({exc})") from None
    except TypeError as exc:  # tls:// without certificates: distributed asks for an ssl_context
        if "ssl_context" not in str(exc):
            raise
        gc.collect()  # the half-started Client, before anyone starts another
        raise SchedulerError(f"{where}: a tls:// scheduler needs TLS certificates in Dask's configuration "
                             "(distributed.comm.tls.ca-file and distributed.comm.tls.client.cert/key, e.g. in "
                             "~/.config/dask/distributed.yaml or DASK_DISTRIBUTED__COMM__TLS__CA_FILE)") from None
    try:
        if not client.scheduler_info().get("workers"):
            client.wait_for_workers(1, timeout=timeout_s)
        yield client
    except TimeoutError:
        raise SchedulerError(f"{where}: the Dask scheduler has no worker (start one: dask worker "
                             f"{address or '--scheduler-file ' + str(scheduler_file)})") from None
    finally:
        client.close()


def open_client(scheduler, *, scheduler_file: str | None = None, n_workers: int | None = None, retries: int = 2):
    """A client context for ``local``, a ``tcp://``/``tls://`` address, a scheduler file, or a given Client.

    A :class:`distributed.Client` passed as ``scheduler`` is used as it is and not closed.
    """
    if scheduler_file is not None and scheduler in (None, "file"):
        return connect(scheduler_file=scheduler_file)
    if is_client(scheduler):
        return nullcontext(scheduler)
    if scheduler == "local":
        return local_client(n_workers, allowed_failures=max(int(retries), 0) + 1)
    if is_address(scheduler):
        return connect(scheduler)
    check_scheduler(scheduler, serial_ok=False)
    raise SchedulerError(f"scheduler {scheduler!r} runs in this process; no client to open")


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
