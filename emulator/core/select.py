"""Bracket selectors: which captured bracket to emulate a target exposure from.

``higher_no_sat`` is the paper's HigherNoSat (section III-A); ``closest`` picks the nearest
bracket in log-exposure; ``reference_rule`` reproduces the published reference code's rule
(higher bracket unless its saturation exceeds the lower one's).  ``predicted_error`` picks
the bracket whose emulation error it predicts from the bracket's DN histogram, the response
and a sensor noise model; on held-out synthetic scenes it beat HigherNoSat (validation
study, ``exposim validate selectors``), but it needs a noise model, so it is not in
``SELECTORS``, whose members need only the bracket images.  All take a mapping
``exposure_ms -> raw image`` or ``exposure_ms -> saturated fraction`` (float in [0, 1]),
and both clip ends (pixels at or below black, at or above white) count as saturated.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from emulator.core.emulate import check_exposure
from emulator.errors import ExposimError

__all__ = [
    "saturated_fraction",
    "higher_no_sat",
    "closest",
    "reference_rule",
    "select",
    "SELECTORS",
    "bounding",
    "NoiseModel",
    "predicted_mse_table",
    "predicted_error",
    "blur_aware",
    "PX_PER_NOISE",
]

#: HigherNoSat takes the higher bracket while its saturated fraction is below this.
SATURATION_THRESHOLD = 0.01
#: Relative tolerance under which a target "equals" a bracket exposure.
EQUAL_RTOL = 1e-9


def saturated_fraction(raw: np.ndarray, *, white_level: int, black_level: int) -> float:
    """Fraction of pixels at or below ``black_level`` or at or above ``white_level``."""
    for label, level in (("white_level", white_level), ("black_level", black_level)):
        if isinstance(level, (bool, np.bool_)) or not isinstance(level, (int, np.integer, float, np.floating)) \
                or not math.isfinite(level) or level != int(level) or level < 0:
            raise ExposimError(f"saturated_fraction: {label} must be a whole number of DN >= 0, got {level!r}")
    if not int(white_level) > int(black_level):
        raise ExposimError(f"saturated_fraction: white_level {white_level!r} must exceed black_level {black_level!r}")
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
    out = sorted(check_exposure(_number(b), "bracket exposure_ms") for b in brackets)
    dup = sorted({v for v in out if out.count(v) > 1})
    if dup:
        raise ExposimError(f"brackets given twice: {', '.join(f'{v:g}' for v in dup)} ms (keys "
                           f"{', '.join(repr(k) for k in brackets if float(k) in dup)})")
    return out


def _number(key):
    """A bracket key as a number: folder-name strings (``"4.0"``) are read as numbers; ``True`` is not one."""
    if isinstance(key, str):
        try:
            return float(key)
        except ValueError:
            return key  # refused by check_exposure, naming it
    return key


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


# ---------------------------------------------------------------------------- predicted error (validated)
@dataclass(frozen=True)
class NoiseModel:
    """Variance of one capture's linear exposure, ``var_h(h) = shot * h + floor``.

    ``h`` is in the units of the response's inverse table g (linear exposure); ``shot``
    (g units) is the g-value of one photo-electron, ``floor`` (g units squared) the read
    noise variance.  Quantisation of the source is handled separately.
    """

    shot: float
    floor: float

    def var_h(self, h) -> np.ndarray:
        return self.shot * np.maximum(np.asarray(h, dtype=np.float64), 0.0) + self.floor


def predicted_mse_table(response, ratio: float, noise: NoiseModel, *, white_level: int, black_level: int,
                        clip_weight: float = 1.0) -> np.ndarray:
    """Predicted squared emulation error (DN^2, float64) for every source DN at one ratio.

    For a source DN ``d`` the true exposure lies in ``[g(d - 1/2), g(d + 1/2)]``; scaled by
    ``k`` and mapped through ``f`` it becomes an interval ``[lo, hi]`` of target DN, of which
    the emulator outputs ``mid = f(k g(d))``.  Taking the truth uniform on that interval,
    the quantisation term is ``((mid - lo)^3 + (hi - mid)^3) / (3 (hi - lo))``.  A source at
    white with ``k < 1`` stands for anything up to white in the target (``hi = white``); a
    black one with ``k > 1`` for anything from black (``lo = black``): those clipped terms
    are multiplied by ``clip_weight``.  The noise term is the source's noise carried
    through the mapping: ``((f(k (g + s)) - f(k (g - s))) / 2)^2`` with ``s^2 = var_h(g)``.
    """
    k = float(ratio)
    g = response.g[: white_level + 1]
    dn = np.arange(white_level + 1, dtype=np.float64)
    top = float(white_level)
    f = response.forward
    mid = np.clip(f(k * g), black_level, white_level)
    lo = np.clip(f(k * response.inverse(np.clip(dn - 0.5, 0.0, top))), black_level, white_level)
    hi = np.clip(f(k * response.inverse(np.clip(dn + 0.5, 0.0, top))), black_level, white_level)
    clipped = np.zeros(dn.shape, dtype=bool)
    if k < 1.0:
        hi[white_level:] = white_level
        clipped[white_level:] = True
    if k > 1.0:
        lo[: black_level + 1] = black_level
        clipped[: black_level + 1] = True
    width = hi - lo
    with np.errstate(invalid="ignore", divide="ignore"):
        quant = np.where(width > 1e-12, ((mid - lo) ** 3 + (hi - mid) ** 3) / (3.0 * width), 0.0)
    quant = np.where(clipped, clip_weight * quant, quant)
    s = np.sqrt(noise.var_h(g))
    noise_dn = 0.5 * (np.clip(f(k * (g + s)), black_level, white_level) - np.clip(f(k * (g - s)), black_level,
                                                                                   white_level))
    noise_dn = np.where(clipped, 0.0, noise_dn)
    return quant + noise_dn * noise_dn


def _histogram(value, white_level: int) -> np.ndarray:
    if isinstance(value, np.ndarray) and value.ndim == 1 and value.size == white_level + 1:
        return value.astype(np.float64)
    if isinstance(value, np.ndarray) and value.ndim == 2 and value.dtype.kind in "ui":
        return np.bincount(np.minimum(value.ravel(), white_level), minlength=white_level + 1).astype(np.float64)
    raise ExposimError("predicted_error needs the bracket images (2-D uint16) or their DN histograms "
                       f"(1-D, white_level + 1 = {white_level + 1} bins)")


def predicted_error(
    target_ms: float,
    brackets: Mapping,
    *,
    response,
    noise: NoiseModel,
    white_level: int,
    black_level: int,
    clip_weight: float = 1.0,
    return_scores: bool = False,
):
    """Pick the bracket whose emulation error at ``target_ms`` is predicted to be smallest.

    Parameters
    ----------
    target_ms : float
        Target exposure, ms.
    brackets : mapping
        ``exposure_ms -> raw image`` (uint16) or ``exposure_ms -> DN histogram`` (length
        ``white_level + 1``).
    response : emulator.CameraResponse
    noise : NoiseModel
        Noise of one capture in the response's linear units.
    white_level, black_level : int
    clip_weight : float
        Weight of clipped source pixels (see :func:`predicted_mse_table`).
    return_scores : bool
        Also return ``{exposure_ms: predicted RMSE (DN)}``.

    Returns
    -------
    The chosen key of ``brackets`` (ties go to the longer exposure), and the scores if asked.
    """
    target_ms = check_exposure(target_ms, "target_ms")
    if not brackets:
        raise ExposimError("no brackets to select from")
    scores = {}
    for key, value in brackets.items():
        b = check_exposure(key, "bracket exposure_ms")
        hist = _histogram(value, white_level)
        table = predicted_mse_table(response, target_ms / b, noise, white_level=white_level,
                                    black_level=black_level, clip_weight=clip_weight)
        scores[key] = math.sqrt(float(hist @ table) / float(hist.sum()))
    best = min(scores, key=lambda kk: (round(scores[kk], 9), -float(kk)))
    return (best, scores) if return_scores else best



#: Default weight of blur against noise in :func:`blur_aware`: one pixel of excess blur costs
#: as much as emulating from a bracket with twice the target's relative noise.
PX_PER_NOISE = 1.0


def blur_aware(
    target_ms: float,
    brackets: Mapping,
    *,
    white_level: int,
    black_level: int,
    excess_blur_px: Callable[[float], float] | None = None,
    px_per_noise: float = PX_PER_NOISE,
    threshold: float = SATURATION_THRESHOLD,
):
    """HigherNoSat that weighs the higher bracket's excess blur against the lower one's noise.

    As :func:`higher_no_sat` at or outside the bracket range, at a bracket, and when the
    higher bounding bracket ``b_h`` saturates.  Otherwise both bounding brackets qualify:
    the lower one ``b_l`` is emulated upwards and carries ``sqrt(target / b_l)`` times the
    relative shot noise of a capture at the target (cost ``sqrt(target / b_l) - 1``); the
    higher one keeps ``excess_blur_px(b_h)`` pixels of blur a capture at the target would
    not have (cost ``excess / px_per_noise``).  The cheaper wins; ties go to ``b_h``.  Without
    motion (``excess_blur_px`` None or 0) it is HigherNoSat.

    Parameters
    ----------
    excess_blur_px : callable(bracket_ms) -> float, optional
        Blur of the bracket beyond a capture at the target, px (e.g.
        :meth:`emulator.playback.motion.RecordingMotion.mismatch_px`); NaN counts as 0.
    px_per_noise : float
        Pixels of excess blur that cost as much as a doubled relative noise (> 0).

    >>> blur_aware(12.0, {8.0: 0.0, 16.0: 0.0}, white_level=4095, black_level=0)
    16.0
    >>> blur_aware(12.0, {8.0: 0.0, 16.0: 0.0}, white_level=4095, black_level=0, excess_blur_px=lambda b: 2.0)
    8.0
    """
    if not (isinstance(px_per_noise, (int, float)) and math.isfinite(px_per_noise) and px_per_noise > 0):
        raise ExposimError(f"px_per_noise must be a finite number > 0, got {px_per_noise!r}")
    choice = higher_no_sat(target_ms, brackets, white_level=white_level, black_level=black_level, threshold=threshold)
    target_ms = check_exposure(target_ms, "target_ms")
    equal, low, high = bounding(target_ms, _sorted_brackets(brackets))
    if excess_blur_px is None or equal is not None or low == high or float(choice) != high:
        return choice
    excess = float(excess_blur_px(high))
    excess = 0.0 if not math.isfinite(excess) else max(0.0, excess)
    noise_cost = math.sqrt(target_ms / low) - 1.0
    return _key(brackets, low) if excess / px_per_noise > noise_cost else choice


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
