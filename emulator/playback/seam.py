"""The one place a method's ``next_exposure`` is called: :func:`call_method`.

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

__all__ = ["MethodAnswer", "call_method", "guard_exposure", "clamp"]


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
    """Ask ``method`` for its next exposure after it saw ``raw`` taken at ``exposure_ms``.

    Raises :class:`MethodFailed` when the method does (a plugin's error or bad result) or
    when the call took longer than ``timeout_s`` seconds (the call completes; no thread is
    killed).  Otherwise returns the guarded, clamped :class:`MethodAnswer`.
    """
    before = getattr(method, "guard_count", 0)
    t0 = time.perf_counter()
    proposed = isolated_call(method, raw, exposure_ms)  # isolated (emulator.autoexposure.isolation)
    elapsed = time.perf_counter() - t0
    if timeout_s is not None and elapsed > timeout_s:
        raise MethodFailed(f"took {elapsed:.3g} s in next_exposure, over the limit of {timeout_s:g} s")
    proposed, next_ms, bad = guard_exposure(proposed, exposure_ms, range_ms)
    guarded = bad or getattr(method, "guard_count", 0) > before
    unclamped = exposure_ms if bad else proposed
    return MethodAnswer(proposed, next_ms, bool(guarded), next_ms != unclamped, elapsed)
