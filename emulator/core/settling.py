"""Whether an AE method's exposure has settled by the end of a run, or is still trending.

A short clip (the BorealHDR data_sample holds 11 recorder cycles) can end while some methods are
still climbing towards their operating point; their figures then describe a transient, not the
method.  :func:`still_trending` says so per method, from the exposure of each recorder cycle.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["still_trending", "trending_methods", "TREND_STEPS", "TREND_MIN_CHANGE_FRACTION"]

#: The last steps (recorder cycles) looked at: all in one direction means still trending.
TREND_STEPS = 3
#: Least relative change of the exposure over those steps that counts as a trend (0.05: 5 %).
TREND_MIN_CHANGE_FRACTION = 0.05


def still_trending(exposure_ms, steps: int = TREND_STEPS,
                   min_change_fraction: float = TREND_MIN_CHANGE_FRACTION) -> dict | None:
    """The trend at the end of a method's exposure series, or None where it has settled.

    Parameters
    ----------
    exposure_ms : array_like
        (N,) exposure of each recorder cycle, ms, in time order (non-finite values are left out).
    steps : int
        How many last steps are looked at (>= 1).
    min_change_fraction : float
        Least relative change over those steps, ``|t_end / t_start - 1|``.

    Returns
    -------
    dict or None
        ``{"direction": "rising"|"falling", "change_fraction": float, "steps": int}`` when each of the
        last ``steps`` steps moves the same way and together they change the exposure by at least
        ``min_change_fraction``; None otherwise, or when the series has fewer than ``steps + 1`` values
        (too short to tell).
    """
    t = np.asarray(exposure_ms, dtype=np.float64).ravel()
    t = t[np.isfinite(t) & (t > 0)]
    if int(steps) < 1 or t.size < int(steps) + 1:
        return None
    tail = t[-(int(steps) + 1):]
    d = np.diff(tail)
    if not (np.all(d > 0) or np.all(d < 0)):
        return None
    change = float(tail[-1] / tail[0] - 1.0)
    if not math.isfinite(change) or abs(change) < min_change_fraction:
        return None
    return {"direction": "rising" if change > 0 else "falling", "change_fraction": change, "steps": int(steps)}


def trending_methods(series: dict) -> dict:
    """:func:`still_trending` of each method's series (``{name: exposure_ms per recorder cycle}``), the
    methods that settled left out."""
    out = {}
    for name, values in series.items():
        trend = still_trending(values)
        if trend is not None:
            out[name] = trend
    return out
