"""The one place a method's ``next_exposure`` is called: :func:`call_method`, on a :class:`MethodHandle`.

A run's methods come to the closed loop as handles that keep their own time limit: a
:class:`~emulator.playback.workers.MethodWorker` (its process, stopped past the limit) or an
:class:`InlineMethod` (in the run's process, the limit checked after the call returns).  The loop
asks every handle the same way (:meth:`MethodHandle.shot`, then :func:`call_method`); a plain
method given to the loop is made an :class:`InlineMethod` (:func:`as_handle`).

Every closed loop (emulated brackets, live shots at the cycle rate or at the camera's own
frame rate) asks its methods through here, so the guard (a non-finite or non-positive
answer keeps the exposure just used), the clamp to the configured range, the wall-time
limit and the method's failure (:class:`~emulator.autoexposure.registry.MethodFailed`)
are handled once.  Keep it the single call site: isolation of a method (read-only inputs,
numpy error state, working directory, stdout; :mod:`emulator.autoexposure.isolation`) wraps
this call.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

from emulator.autoexposure.isolation import call_method as isolated_call
from emulator.autoexposure.registry import MethodFailed

__all__ = ["MethodAnswer", "MethodHandle", "InlineMethod", "as_handle", "stop_methods", "call_method",
           "guard_exposure", "clamp"]


class MethodHandle:
    """A method as the closed loop calls it; it enforces its own time limit.

    :meth:`shot` takes the tick's shot at the method's target (a worker starts computing on the
    first camera's image while the rest of the shot is made); :meth:`propose` returns the method's
    answer for an image, isolated (:mod:`emulator.autoexposure.isolation`), or raises
    :class:`MethodFailed`; :meth:`kill` and :meth:`close` stop what the handle started (nothing inline).
    """

    def shot(self, tick, target_ms: float, want_right: bool):
        return tick.shot(target_ms, want_right)

    def propose(self, raw, exposure_ms: float):  # pragma: no cover - every handle defines it
        raise NotImplementedError

    @property
    def guard_count(self) -> int:
        return 0

    def kill(self) -> None:
        """Stop the method's computing now (a handle in the run's process has nothing to stop)."""

    def close(self) -> None:
        """Release what the handle holds (a handle in the run's process holds nothing)."""


class InlineMethod(MethodHandle):
    """A method called in the run's process; a call longer than ``limit_s`` fails it once it returns
    (nothing interrupts it).  Other attributes are the method's own."""

    def __init__(self, method, limit_s: float | None = None) -> None:
        self.method = method
        self.limit_s = None if limit_s is None else float(limit_s)

    def __getattr__(self, name: str):
        if name == "method":  # not set yet (a copy being made): no method to ask
            raise AttributeError(name)
        return getattr(self.method, name)

    def propose(self, raw, exposure_ms: float):
        t0 = time.perf_counter()
        proposed = isolated_call(self.method, raw, exposure_ms)  # isolated (emulator.autoexposure.isolation)
        elapsed = time.perf_counter() - t0
        if self.limit_s is not None and elapsed > self.limit_s:
            raise MethodFailed(f"took {elapsed:.3g} s in next_exposure, over the limit of {self.limit_s:g} s")
        return proposed

    @property
    def guard_count(self) -> int:
        return getattr(self.method, "guard_count", 0)

    def config(self) -> dict:
        config = getattr(self.method, "config", None)
        return config() if config is not None else {}

    def reset(self) -> None:
        reset = getattr(self.method, "reset", None)
        if reset is not None:
            reset()


def as_handle(method, limit_s: float | None = None) -> MethodHandle:
    """``method`` as a handle: itself when it is one, else an :class:`InlineMethod` with ``limit_s``."""
    return method if isinstance(method, MethodHandle) else InlineMethod(method, limit_s)


def stop_methods(methods, *, kill_only: bool = False) -> None:
    """Stop every handle among ``methods`` (``kill_only``: its computing now, keeping what calls still
    returning read); plain methods are left alone."""
    for m in list(methods.values()):
        if isinstance(m, MethodHandle):
            m.kill() if kill_only else m.close()


@dataclass(frozen=True)
class MethodAnswer:
    """What the loop makes of one call: the proposal, the exposure it leads to, and flags."""

    proposed_ms: float  #: the method's answer as a float (NaN when it is not a number)
    next_ms: float  #: the next exposure: the proposal (or the fallback when guarded), clamped
    guarded: bool  #: the answer was replaced (not finite, not positive) or the method guarded itself
    clamped: bool  #: the clamp changed the value
    elapsed_s: float  #: wall time of the call


def clamp(value: float, range_ms) -> float:
    lo, hi = range_ms
    return min(max(value, lo), hi)


def guard_exposure(proposed, fallback_ms: float, range_ms) -> tuple[float, float, bool]:
    """What the loop makes of a method's answer: ``(proposed, next_ms, guarded)``.

    ``proposed`` as a float (NaN if it is not a number); a non-finite or non-positive answer
    is replaced by ``fallback_ms`` (the exposure just used) and ``guarded`` is True; the
    result is clamped to ``range_ms`` (compare ``next_ms`` with ``proposed`` to see a clamp).
    """
    try:
        proposed = float(proposed)
    except (TypeError, ValueError):
        proposed = math.nan
    bad = not (math.isfinite(proposed) and proposed > 0)
    return proposed, clamp(fallback_ms if bad else proposed, range_ms), bad


def call_method(method, raw, exposure_ms: float, *, range_ms, timeout_s: float | None = None) -> MethodAnswer:
    """Ask ``method`` (a :class:`MethodHandle`, or a plain method run inline with the limit ``timeout_s``)
    for its next exposure after it saw ``raw`` taken at ``exposure_ms``.

    Raises :class:`MethodFailed` when the method does (a plugin's error or bad result) or
    when the call passed the handle's limit (a worker is stopped; inline, the call completes
    and no thread is killed).  Otherwise returns the guarded, clamped :class:`MethodAnswer`.
    """
    handle = as_handle(method, timeout_s)
    before = handle.guard_count
    t0 = time.perf_counter()
    proposed = handle.propose(raw, exposure_ms)
    elapsed = time.perf_counter() - t0
    proposed, next_ms, bad = guard_exposure(proposed, exposure_ms, range_ms)
    guarded = bad or handle.guard_count > before
    unclamped = exposure_ms if bad else proposed
    return MethodAnswer(proposed, next_ms, bool(guarded), next_ms != unclamped, elapsed)
