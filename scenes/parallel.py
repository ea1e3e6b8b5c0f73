"""Renders of a walk as independent tasks on Dask (``--scheduler local|tcp://HOST:PORT``).

Every frame of ``exposim render`` is one :func:`scenes.render` call.  With a scheduler,
each call runs as a Dask task with exactly the arguments the serial loop would use: the
client resolves the Mitsuba variant, the denoiser (``$EXPOSIM_DENOISE`` included) and the
render cache folder first, so a worker writes the same cache entries (same key, same
bytes) and returns the same image.  The client receives the images in frame order and
writes the outputs itself, so the output folder is byte-identical to a serial render.

``local`` starts a :class:`dask.distributed.LocalCluster` of worker processes (one thread
each: Mitsuba and OIDN already use every core of a worker); ``tcp://HOST:PORT`` connects to
a running scheduler (``dask scheduler`` on one machine, ``dask worker tcp://HOST:8786`` on
each worker, every worker with this package installed and, for cache hits across
machines, the cache folder on a shared file system).  Dask is imported only when a
scheduler is named.
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Iterable, Iterator

import numpy as np

from scenes.errors import RenderError

__all__ = ["SCHEDULER_HELP", "check_scheduler", "dask_client", "render_many"]

#: ``--help`` text of the scheduler option (``exposim render``).
SCHEDULER_HELP = ("render the frames as Dask tasks: 'local' (a local cluster of worker processes) or "
                  "tcp://HOST:PORT (a running 'dask scheduler'); same cache entries and same output bytes "
                  "as the default serial render")

_TCP = re.compile(r"^(tcp|tls)://[A-Za-z0-9_.\-\[\]:]+:\d{1,5}$")


def check_scheduler(spec: str | None) -> str | None:
    """``None`` (serial), ``"local"`` or ``"tcp://HOST:PORT"``; anything else raises :class:`RenderError`."""
    if spec is None:
        return None
    spec = str(spec).strip()
    if spec == "local" or _TCP.match(spec):
        return spec
    raise RenderError(f"--scheduler must be 'local' or tcp://HOST:PORT, got {spec!r} (tls://HOST:PORT also works)")


@contextlib.contextmanager
def dask_client(spec: str, *, n_workers: int | None = None):
    """A connected :class:`dask.distributed.Client` for ``spec`` (closed, with its local cluster, on exit).

    The client is :func:`emulator.orchestration.distributed.open_client`'s, the one way exposim opens a Dask
    client (the same local cluster settings and address handling as dataset runs).

    Raises
    ------
    RenderError
        Bad ``spec``, or the scheduler cannot be reached.
    """
    spec = check_scheduler(spec)
    if spec is None:
        raise RenderError("dask_client needs a scheduler ('local' or tcp://HOST:PORT)")
    from emulator.orchestration.distributed import SchedulerError, open_client

    with contextlib.ExitStack() as stack:
        try:
            client = stack.enter_context(open_client(spec, n_workers=n_workers))
        except SchedulerError as exc:
            raise RenderError(f"cannot reach the Dask scheduler at {spec}: {exc}") from None
        yield client


def _render_task(kwargs: dict) -> np.ndarray:
    from scenes.render import render

    return render(**kwargs)


def render_many(jobs: Iterable[dict], *, scheduler: str | None = None, client=None,
                progress=None) -> Iterator[np.ndarray]:
    """The images of :func:`scenes.render` ``(**job)`` for every job, in job order.

    Parameters
    ----------
    jobs : iterable of dict
        Keyword arguments of :func:`scenes.render`, each complete (scene, pose, size,
        spp, seed, fov, an explicit ``cache_dir``, ``variant`` and ``denoise``), so a
        worker decides nothing the client did not.
    scheduler : str, optional
        None: render here, one after the other; ``"local"`` or ``"tcp://HOST:PORT"``:
        one Dask task per job (see :func:`dask_client`).
    client : dask.distributed.Client, optional
        An open client to use instead of ``scheduler``.
    progress : callable, optional
        Called with 1 after each image is available.

    Yields
    ------
    numpy.ndarray
        float32 (H, W, 3), byte-identical to the serial render of the job.
    """
    jobs = list(jobs)
    tick = progress or (lambda n=1: None)
    if client is None and check_scheduler(scheduler) is None:
        for kw in jobs:
            image = _render_task(kw)
            tick(1)
            yield image
        return
    with contextlib.ExitStack() as stack:
        if client is None:
            client = stack.enter_context(dask_client(scheduler))
        futures = client.map(_render_task, jobs, pure=False)
        try:
            for i, fut in enumerate(futures):
                image = fut.result()
                futures[i] = None  # let the worker forget it
                tick(1)
                yield image
        finally:
            client.cancel([f for f in futures if f is not None])
