"""The one closed loop: image provider -> AE method -> next exposure.

:func:`closed_loop` drives any :class:`ImageProvider`:

* :class:`emulator.playback.emulated.EmulatedProvider`: the brackets of a recording,
  emulated at each method's target (offline; :func:`emulator.playback.iter_run`);
* :class:`emulator.playback.live.LiveCycleProvider`: live shots once per bracket cycle;
* :class:`emulator.playback.live.LiveRateProvider`: live shots at a camera's frame rate
  (22 fps for BorealHDR), with an exposure latency, timestamped at mid-exposure.

Provider protocol (duck-typed)::

    provider.cameras         tuple of camera names; the first is the one methods read
    provider.latency_ticks   int >= 0: a proposal made at tick k is used from tick k + 1 + latency
    provider.ticks()         iterator of ticks; a tick has
        .index               int (the cycle, or the frame index)
        .missing             {camera: [exposure_ms, ...]} brackets missing in this tick
        .skipped             None, or why no method can run in this tick
        .shot(target_ms, want_right) -> Shot   (thread-safe; methods with the same
                                                target may share one image)

For each tick the loop hands every method that has not failed the shot at its current
exposure, asks it through :func:`emulator.playback.seam.call_method` (the one call site),
and records a :class:`MethodStep`.  A method that fails (raises
:class:`~emulator.autoexposure.registry.MethodFailed`, including a call over the time
limit) gets no step from that tick on and is named in :attr:`CycleStep.failed`.  Methods of
a tick run on ``config.jobs`` threads under one BLAS thread each (:mod:`emulator.pools`), so
results depend neither on ``jobs`` nor on the machine's cores.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from emulator.autoexposure.registry import MethodFailed
from emulator.playback.config import RunConfig
from emulator.playback.records import CycleStep, MethodStep, RunStats
from emulator.playback.seam import call_method
from emulator.pools import single_thread_pools

__all__ = ["Shot", "closed_loop"]


@dataclass
class Shot:
    """What a provider hands a method for one tick: its image(s) and what they are."""

    timestamp_ns: int
    exposure_ms: float  #: the exposure the image shows (the method's target)
    bracket_ms: float  #: the bracket it came from (live: the instant's bracket, or the exposure itself)
    ratio: float
    left: np.ndarray  #: the image the method reads (read-only)
    saturated_fraction: float
    valid_fraction: float
    bracket_saturated_fraction: float
    right: np.ndarray | None = None
    saturated_fraction_right: float | None = None
    valid_fraction_right: float | None = None
    missing_left_ms: tuple[float, ...] = ()
    missing_right_ms: tuple[float, ...] = ()


def closed_loop(
    provider,
    methods: Mapping[str, object],
    config: RunConfig,
    *,
    want_right: bool = False,
    keep_images: bool = False,
    on_step: Callable[[MethodStep], None] | None = None,
    stats: RunStats | None = None,
) -> Iterator[CycleStep]:
    """Run ``methods`` (name -> built method) in closed loop on ``provider``; yields a :class:`CycleStep` per tick.

    Every method starts at ``config.start_ms``; proposals are clamped to ``config.range_ms``;
    ``config.method_timeout_s`` limits each call.  ``want_right``: the provider also hands
    the second camera's image; ``keep_images``: the yielded steps keep the images (else they
    are dropped after ``on_step``, which is called in the worker right after each step).
    """
    stats = stats if stats is not None else RunStats()
    latency = int(getattr(provider, "latency_ticks", 0))
    if latency < 0:
        raise ValueError(f"latency_ticks must be >= 0, got {latency}")
    pending = {name: deque([config.start_ms] * (latency + 1)) for name in methods}
    failed: dict[str, str] = {}
    last_s: dict[str, float] = {}  # each method's last call, wall seconds (the pool's order)

    def step_one(name: str, tick) -> MethodStep | MethodFailed:
        target = pending[name][0]
        shot = tick.shot(target, want_right)
        try:
            answer = call_method(methods[name], shot.left, shot.exposure_ms, range_ms=config.range_ms,
                                 timeout_s=config.method_timeout_s)
        except MethodFailed as exc:
            return exc
        stats.add_method(name, answer.elapsed_s)
        last_s[name] = answer.elapsed_s
        st = MethodStep(
            method=name, cycle=tick.index, timestamp_ns=int(shot.timestamp_ns), target_ms=float(shot.exposure_ms),
            bracket_ms=float(shot.bracket_ms), ratio=float(shot.ratio), saturated_fraction=shot.saturated_fraction,
            valid_fraction=shot.valid_fraction, next_ms=answer.next_ms, proposed_ms=answer.proposed_ms,
            guarded=answer.guarded, clamped=answer.clamped,
            bracket_saturated_fraction=shot.bracket_saturated_fraction,
            saturated_fraction_right=shot.saturated_fraction_right, valid_fraction_right=shot.valid_fraction_right,
            missing_left_ms=tuple(shot.missing_left_ms), missing_right_ms=tuple(shot.missing_right_ms),
            left=shot.left, right=shot.right if want_right else None,
        )
        if on_step is not None:
            on_step(st)
        if not keep_images:
            st.left = st.right = None
        return st

    pool = ThreadPoolExecutor(max_workers=config.jobs, thread_name_prefix="exposim-run") if config.jobs > 1 else None
    start = time.perf_counter()
    try:
        for tick in provider.ticks():
            if tick.skipped:
                stats.cycles += 1
                yield CycleStep(tick.index, {}, tick.missing, skipped=tick.skipped)
                continue
            names = [name for name in methods if name not in failed]
            with single_thread_pools(user_api="blas"):  # results independent of the machine's cores
                if pool is None:
                    results = [step_one(name, tick) for name in names]
                else:
                    # longest first (by each method's last call): the slow methods start at once and
                    # the cheap ones fill the other threads, so the tick ends sooner; results by name
                    order = sorted(names, key=lambda name: -last_s.get(name, 0.0))
                    futures = {name: pool.submit(step_one, name, tick) for name in order}
                    results = [futures[name].result() for name in names]
            now_failed = {}
            steps = {}
            for name, st in zip(names, results):
                if isinstance(st, MethodFailed):
                    now_failed[name] = f"failed: {st} at cycle {tick.index}"
                else:
                    pending[name].popleft()
                    pending[name].append(st.next_ms)
                    steps[name] = st
            failed.update(now_failed)
            stats.cycles += 1
            stats.wall_s = time.perf_counter() - start
            if stats.startup_s is None:
                stats.startup_s = stats.wall_s
            yield CycleStep(tick.index, steps, tick.missing, failed=now_failed)
    finally:
        stats.wall_s = time.perf_counter() - start
        if pool is not None:
            pool.shutdown(wait=True)
