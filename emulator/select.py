"""Bracket selectors: which captured bracket to emulate a target exposure from.

``higher_no_sat`` is the paper's HigherNoSat (section III-A); ``closest`` picks the nearest
bracket in log-exposure; ``reference_rule`` reproduces the published reference code's rule
(higher bracket unless its saturation exceeds the lower one's).  All take a mapping
``exposure_ms -> raw image`` or ``exposure_ms -> saturated fraction`` (float in [0, 1]),
and both clip ends (pixels at or below black, at or above white) count as saturated.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

import numpy as np

from emulator.emulate import check_exposure
from emulator.errors import ExposimError

__all__ = ["saturated_fraction", "higher_no_sat", "closest", "reference_rule", "select", "SELECTORS", "bounding"]

#: HigherNoSat takes the higher bracket while its saturated fraction is below this.
SATURATION_THRESHOLD = 0.01
#: Relative tolerance under which a target "equals" a bracket exposure.
EQUAL_RTOL = 1e-9


def saturated_fraction(raw: np.ndarray, *, white_level: int, black_level: int) -> float:
    """Fraction of pixels at or below ``black_level`` or at or above ``white_level``."""
    raw = np.asarray(raw)
    if raw.size == 0:
        raise ExposimError("saturated_fraction: empty image")
    n = np.count_nonzero(raw >= white_level) + np.count_nonzero(raw <= black_level)
    return float(n) / raw.size


def _fraction(value, *, white_level: int, black_level: int) -> float:
    if isinstance(value, np.ndarray) and value.ndim >= 1:
        return saturated_fraction(value, white_level=white_level, black_level=black_level)
    if callable(value):
        return float(value())
    f = float(value)
    if not (0.0 <= f <= 1.0):
        raise ExposimError(f"saturated fraction must lie in [0, 1], got {value!r}")
    return f


def _sorted_brackets(brackets: Mapping) -> list[float]:
    if not brackets:
        raise ExposimError("no brackets to select from")
    return sorted(check_exposure(b, "bracket exposure_ms") for b in brackets)


def _key(brackets: Mapping, value: float):
    """The mapping's own key for a (float-converted) bracket exposure."""
    for k in brackets:
        if float(k) == value:
            return k
    raise KeyError(value)  # pragma: no cover - values come from the keys


def bounding(target_ms: float, exposures: list[float]) -> tuple[float | None, float | None, float | None]:
    """(equal, low, high) for a sorted bracket list.

    ``equal`` is the bracket equal to the target (within ``EQUAL_RTOL``) if any; otherwise
    ``low < target < high`` are the bounding brackets, or ``low = high =`` the nearest end
    bracket when the target lies outside the range.
    """
    for b in exposures:
        if math.isclose(b, target_ms, rel_tol=EQUAL_RTOL):
            return b, None, None
    if target_ms < exposures[0]:
        return None, exposures[0], exposures[0]
    if target_ms > exposures[-1]:
        return None, exposures[-1], exposures[-1]
    i = int(np.searchsorted(exposures, target_ms))
    return None, exposures[i - 1], exposures[i]


def higher_no_sat(
    target_ms: float,
    brackets: Mapping,
    *,
    white_level: int,
    black_level: int,
    threshold: float = SATURATION_THRESHOLD,
):
    """HigherNoSat (paper section III-A).

    At or outside the bracket range: the closest bracket.  Equal to a bracket: that one.
    Otherwise, with bounding brackets ``b_l < target < b_h``: ``b_h`` when its saturated
    fraction is below ``threshold`` (strictly), else ``b_l``.  Only ``b_h``'s saturation
    is computed.  Returns the chosen key of ``brackets``.
    """
    target_ms = check_exposure(target_ms, "target_ms")
    exposures = _sorted_brackets(brackets)
    equal, low, high = bounding(target_ms, exposures)
    if equal is not None:
        return _key(brackets, equal)
    if low == high:
        return _key(brackets, low)
    sat_high = _fraction(brackets[_key(brackets, high)], white_level=white_level, black_level=black_level)
    return _key(brackets, high if sat_high < threshold else low)


def closest(target_ms: float, brackets: Mapping, *, white_level: int = 0, black_level: int = 0, **_):
    """The bracket nearest to the target in log-exposure (ties go to the higher one)."""
    target_ms = check_exposure(target_ms, "target_ms")
    exposures = _sorted_brackets(brackets)
    dist = [abs(math.log(b / target_ms)) for b in exposures]
    best = min(range(len(exposures)), key=lambda i: (round(dist[i], 12), -exposures[i]))
    return _key(brackets, exposures[best])


def reference_rule(target_ms: float, brackets: Mapping, *, white_level: int, black_level: int, **_):
    """The published reference code's rule: the higher bounding bracket unless its
    saturated fraction exceeds the lower one's (same range handling as HigherNoSat)."""
    target_ms = check_exposure(target_ms, "target_ms")
    exposures = _sorted_brackets(brackets)
    equal, low, high = bounding(target_ms, exposures)
    if equal is not None:
        return _key(brackets, equal)
    if low == high:
        return _key(brackets, low)
    lv = dict(white_level=white_level, black_level=black_level)
    sat_low = _fraction(brackets[_key(brackets, low)], **lv)
    sat_high = _fraction(brackets[_key(brackets, high)], **lv)
    return _key(brackets, low if sat_high > sat_low else high)


SELECTORS: dict[str, Callable] = {
    "higher-no-sat": higher_no_sat,
    "closest": closest,
    "reference": reference_rule,
}


def select(name: str, target_ms: float, brackets: Mapping, *, white_level: int, black_level: int, **kwargs):
    """Front function: run the selector called ``name`` (see ``SELECTORS``)."""
    try:
        fn = SELECTORS[name]
    except KeyError:
        raise ExposimError(f"unknown selector {name!r}; choose one of {', '.join(SELECTORS)}") from None
    return fn(target_ms, brackets, white_level=white_level, black_level=black_level, **kwargs)
