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
    provider.ticks_ahead     int >= 0, optional (default 0): how far a method may run ahead of
                             the oldest unfinished tick (its ticks' shot() must then be safe to
                             call on several ticks at once)
    provider.ticks()         iterator of ticks; a tick has
        .index               int (the cycle, or the frame index)
        .missing             {camera: [exposure_ms, ...]} brackets missing in this tick
        .skipped             None, or why no method can run in this tick
        .shot(target_ms, want_right) -> Shot   (thread-safe; methods with the same
                                                target may share one image)
        .split_shot(target_ms, want_right)     optional: (shot, rest), the shot without the second
                                                camera's part and rest() that adds it; a method in a
                                                worker then computes while rest() runs

For each tick the loop hands every method that has not failed the shot at its current
exposure, asks it through :func:`emulator.playback.seam.call_method` (the one call site),
and records a :class:`MethodStep`.  A method that fails (raises
:class:`~emulator.autoexposure.registry.MethodFailed`, including a call over the time
limit) gets no step from that tick on and is named in :attr:`CycleStep.failed`.  A method
is a handle (:class:`~emulator.playback.seam.MethodHandle`) that keeps its own time limit: a
:class:`~emulator.playback.workers.MethodWorker` (what :func:`~emulator.playback.prepare_run`
builds by default) computes in its own process, which ends with the loop; a plain method is
called inline (:class:`~emulator.playback.seam.InlineMethod`, ``config.method_timeout_s`` checked after the call).  Methods
are asked from ``config.jobs`` threads (so that many workers compute at once), under one
BLAS thread each (:mod:`emulator.pools`); with
more than one job a method may run up to ``provider.ticks_ahead`` ticks (default 0) ahead of
the oldest tick not yet yielded instead of waiting for the slowest method at every tick.
Ticks are yielded in order either way, so results depend neither on ``jobs`` nor on the
machine's cores.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import dataclass

import numpy as np

from emulator.autoexposure.registry import MethodFailed
from emulator.playback.config import RunConfig
from emulator.playback.records import CycleStep, MethodStep, RunStats
from emulator.playback.seam import as_handle, call_method, stop_methods
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
    native: object = None  #: native rate: the frame's source and warp (:class:`~emulator.playback.native.NativeInfo`)


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
    # every method as a handle that keeps its own limit (a worker's, or an inline call checked after it returns)
    methods = {name: as_handle(m, config.method_timeout_s) for name, m in methods.items()}
    latency = int(getattr(provider, "latency_ticks", 0))
    if latency < 0:
        raise ValueError(f"latency_ticks must be >= 0, got {latency}")
    pending = {name: deque([config.start_ms] * (latency + 1)) for name in methods}
    failed: dict[str, str] = {}
    last_s: dict[str, float] = {}  # each method's last call, wall seconds (the pool's order)

    def step_one(name: str, tick) -> MethodStep | MethodFailed:
        method = methods[name]
        shot = method.shot(tick, pending[name][0], want_right)  # a worker computes while the shot is finished
        try:  # the handle keeps its limit (a worker's interrupts; inline, it is checked after the call)
            answer = call_method(method, shot.left, shot.exposure_ms, range_ms=config.range_ms)
        except MethodFailed as exc:
            return exc
        stats.add_method(name, answer.elapsed_s)
        last_s[name] = answer.elapsed_s
        # this method's next proposal; only its own next step reads it, and that step starts after this one
        pending[name].popleft()
        pending[name].append(answer.next_ms)
        st = MethodStep(
            method=name, cycle=tick.index, timestamp_ns=int(shot.timestamp_ns), target_ms=float(shot.exposure_ms),
            bracket_ms=float(shot.bracket_ms), ratio=float(shot.ratio), saturated_fraction=shot.saturated_fraction,
            valid_fraction=shot.valid_fraction, next_ms=answer.next_ms, proposed_ms=answer.proposed_ms,
            guarded=answer.guarded, clamped=answer.clamped,
            bracket_saturated_fraction=shot.bracket_saturated_fraction,
            saturated_fraction_right=shot.saturated_fraction_right, valid_fraction_right=shot.valid_fraction_right,
            missing_left_ms=tuple(shot.missing_left_ms), missing_right_ms=tuple(shot.missing_right_ms),
            left=shot.left, right=shot.right if want_right else None, native=shot.native,
        )
        if on_step is not None:
            on_step(st)
        if not keep_images:
            st.left = st.right = None
        return st

    try:
        if config.jobs <= 1:
            yield from _serial_ticks(provider, methods, step_one, failed, stats)
        else:
            yield from _pipelined_ticks(provider, methods, step_one, failed, last_s, stats, config.jobs,
                                        abort=lambda: stop_methods(methods, kill_only=True))
    finally:
        stop_methods(methods)  # the worker processes end with the loop (emulator.playback.workers)


def _advance(failed: dict, names, results, index: int):
    """Record one tick's results (in ``names`` order): its steps and the methods that failed in it."""
    now_failed = {}
    steps = {}
    for name, st in zip(names, results):
        if isinstance(st, MethodFailed):
            now_failed[name] = f"failed: {st} at cycle {index}"
        else:
            steps[name] = st
    failed.update(now_failed)
    return steps, now_failed


def _serial_ticks(provider, methods, step_one, failed, stats) -> Iterator[CycleStep]:
    """One job: every method of a tick in turn, tick after tick."""
    start = time.perf_counter()
    try:
        for tick in provider.ticks():
            if tick.skipped:
                stats.cycles += 1
                yield CycleStep(tick.index, {}, tick.missing, skipped=tick.skipped)
                continue
            names = [name for name in methods if name not in failed]
            with single_thread_pools(user_api="blas"):  # results independent of the machine's cores
                results = [step_one(name, tick) for name in names]
            steps, now_failed = _advance(failed, names, results, tick.index)
            stats.cycles += 1
            stats.wall_s = time.perf_counter() - start
            if stats.startup_s is None:
                stats.startup_s = stats.wall_s
            yield CycleStep(tick.index, steps, tick.missing, failed=now_failed)
    finally:
        stats.wall_s = time.perf_counter() - start


class _Schedule:
    """The state of :func:`_pipelined_ticks`: the ticks read so far, each method's next tick, the steps done
    and in flight, and the oldest tick not yet yielded."""

    def __init__(self, provider, methods, failed: dict, last_s: dict, stats: RunStats, jobs: int) -> None:
        self.ahead = max(0, int(getattr(provider, "ticks_ahead", 0)))
        self.methods, self.failed, self.last_s, self.stats, self.jobs = methods, failed, last_s, stats, jobs
        self.order = {name: i for i, name in enumerate(methods)}
        self.source = iter(provider.ticks())
        self.ticks: list = []  # by position; None once yielded
        self.exhausted = False
        self.position = {name: 0 for name in methods}  # each method's next tick
        self.stopped: set[str] = set()  # failed or raised: no further ticks
        self.results: dict[int, dict] = {}  # position -> {name: MethodStep | MethodFailed | BaseException}
        self.waiting: set[str] = set()  # methods whose next tick is beyond the window
        self.ready: set[str] = set()
        self.inflight: dict = {}
        self.oldest = 0

    def tick_at(self, p: int):
        """The tick at position ``p`` (read from the provider as needed), None past the last one."""
        while len(self.ticks) <= p and not self.exhausted:
            try:
                self.ticks.append(next(self.source))
            except StopIteration:
                self.exhausted = True
        return self.ticks[p] if p < len(self.ticks) else None

    def place(self, name: str) -> None:
        """Move ``name`` past skipped ticks and put it in ``ready`` or ``waiting`` (or nowhere: done)."""
        while True:
            tick = self.tick_at(self.position[name])
            if tick is None:
                return
            if not tick.skipped:
                break
            self.position[name] += 1
        (self.ready if self.position[name] <= self.oldest + self.ahead else self.waiting).add(name)

    def complete(self, p: int) -> bool:
        """Every method is done with tick ``p`` (or stopped)."""
        return all(name in self.stopped or self.position[name] > p for name in self.methods)

    def finish_oldest(self, tick, start: float) -> CycleStep:
        """The oldest tick's :class:`CycleStep` (every method done with it), the window moved on by one;
        raises the first method's exception other than :class:`MethodFailed`, as one job would."""
        res = self.results.pop(self.oldest, {})
        errors = [res[name] for name in self.methods if isinstance(res.get(name), BaseException)
                  and not isinstance(res[name], MethodFailed)]
        if errors:
            raise errors[0]
        self.stats.cycles += 1
        if tick.skipped:
            cs = CycleStep(tick.index, {}, tick.missing, skipped=tick.skipped)
        else:
            names = [name for name in self.methods if name in res]
            steps, now_failed = _advance(self.failed, names, [res[n] for n in names], tick.index)
            self.stats.wall_s = time.perf_counter() - start
            if self.stats.startup_s is None:
                self.stats.startup_s = self.stats.wall_s
            cs = CycleStep(tick.index, steps, tick.missing, failed=now_failed)
        self.ticks[self.oldest] = None  # its images are freed once the consumer drops the step
        self.oldest += 1
        for name in [n for n in self.waiting if self.position[n] <= self.oldest + self.ahead]:
            self.waiting.discard(name)
            self.ready.add(name)
        return cs

    def dispatch(self, pool: ThreadPoolExecutor, step_one) -> None:
        """Submit ready steps up to ``jobs`` in flight: oldest tick first, then the slowest method (its last call)."""
        while self.ready and len(self.inflight) < self.jobs:
            name = min(self.ready, key=lambda n: (self.position[n], -self.last_s.get(n, 0.0), self.order[n]))
            self.ready.discard(name)
            p = self.position[name]
            self.inflight[pool.submit(step_one, name, self.ticks[p])] = (name, p)
        if not self.inflight:  # pragma: no cover - a scheduling bug, not a user error
            raise RuntimeError(f"closed loop stalled at tick {self.oldest}")

    def collect(self, done) -> None:
        """Record the finished steps ``done`` (futures) and place their methods on their next tick."""
        for fut in done:
            name, p = self.inflight.pop(fut)
            exc = fut.exception()
            st = exc if exc is not None else fut.result()
            self.results.setdefault(p, {})[name] = st
            self.position[name] = p + 1
            if isinstance(st, BaseException):
                self.stopped.add(name)
            else:
                self.place(name)


def _pipelined_ticks(provider, methods, step_one, failed, last_s, stats, jobs: int,
                     abort=None) -> Iterator[CycleStep]:
    """``jobs`` threads; each method goes on to its next tick as soon as its own step is done.

    Methods are independent closed loops that share only the provider's images, so a method
    need not wait for the slowest one at every tick: it may run up to
    ``provider.ticks_ahead`` ticks ahead of the oldest tick not yet yielded (0: every tick
    is a barrier, as a provider whose ticks must be visited in order needs).  Ticks are still
    yielded in order, each once all its methods are done, and a method's steps are the same
    whatever the schedule (its inputs depend only on its own proposals), so the results are
    those of one job.  Ready steps are dispatched oldest tick first, then the slowest method
    first (by its last call), so the slow methods start at once and the cheap ones fill the
    other threads, including the tail of a tick.  An exception other than
    :class:`MethodFailed` is raised when its tick would be yielded (the first method's, in
    method order), as one job raises it.  The bookkeeping is :class:`_Schedule`'s.
    """
    schedule = _Schedule(provider, methods, failed, last_s, stats, jobs)
    pool = ThreadPoolExecutor(max_workers=jobs, thread_name_prefix="exposim-run")
    start = time.perf_counter()
    try:
        with single_thread_pools(user_api="blas"):  # results independent of the machine's cores
            for name in methods:
                schedule.place(name)
            while True:
                tick = schedule.tick_at(schedule.oldest)
                while tick is not None and schedule.complete(schedule.oldest):
                    yield schedule.finish_oldest(tick, start)
                    tick = schedule.tick_at(schedule.oldest)
                if tick is None:
                    return
                schedule.dispatch(pool, step_one)
                done, _ = wait(schedule.inflight, return_when=FIRST_COMPLETED)
                schedule.collect(done)
    except BaseException:  # Ctrl-C, an error, or the consumer stopped: calls in flight end with their workers
        if abort is not None:
            abort()
        raise
    finally:
        stats.wall_s = time.perf_counter() - start
        pool.shutdown(wait=True, cancel_futures=True)
