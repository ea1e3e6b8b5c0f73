"""What a static stack says before and around the response fit of
:mod:`emulator.calibration.stack_engel2016`: its samples checked (:func:`check_stack`), the
conditions under which the fit is less constrained than it looks (:func:`stack_warnings`), and
the temporal noise of one image (:func:`estimate_noise_dn`, for the static-scene check).
"""

from __future__ import annotations

import math

import numpy as np

from emulator.calibration.result import bayer_subsample, table_top_for
from emulator.errors import CalibrationError
from emulator.core.levels import BOREALHDR_LEVELS

__all__ = ["estimate_noise_dn", "stack_warnings", "check_stack"]


def estimate_noise_dn(
    raw: np.ndarray,
    *,
    black_level: int = BOREALHDR_LEVELS.black,
    white_level: int = BOREALHDR_LEVELS.white,
    margin: int = 8,
) -> float:
    """Temporal noise in DN estimated from one image (Immerkaer 1996, robust variant).

    The Laplacian-like kernel [[1,-2,1],[-2,4,-2],[1,-2,1]] is applied to each Bayer plane
    (so a mosaic's colours do not mix); sigma = 1.4826 * median|response| / 6 over pixels
    whose 3x3 neighbourhood is unclipped.  Texture inflates the estimate, so it is an upper
    bound in textured scenes; NaN when fewer than 100 pixels are usable.
    """
    vals = []
    for p in bayer_subsample(np.asarray(raw), 1):
        if p.shape[0] < 3 or p.shape[1] < 3:
            continue
        x = p.astype(np.float64)
        lap = (
            x[:-2, :-2] - 2 * x[:-2, 1:-1] + x[:-2, 2:]
            - 2 * x[1:-1, :-2] + 4 * x[1:-1, 1:-1] - 2 * x[1:-1, 2:]
            + x[2:, :-2] - 2 * x[2:, 1:-1] + x[2:, 2:]
        )
        ok = (p > black_level + margin) & (p < white_level - margin)
        ok3 = ok[:-2, :-2] & ok[:-2, 2:] & ok[2:, :-2] & ok[2:, 2:] & ok[1:-1, 1:-1]
        vals.append(lap[ok3])
    v = np.concatenate(vals) if vals else np.empty(0)
    if v.size < 100:
        return float("nan")
    return 1.4826 * float(np.median(np.abs(v))) / 6.0


def stack_warnings(t: np.ndarray, observed: tuple[int, int], lo: int, hi: int) -> list[str]:
    """Conditions under which the result is less constrained than it looks."""
    out = []
    lt = np.log(np.unique(t))
    if lt.size >= 3:
        step = float(np.min(np.diff(lt)))
        k = (lt - lt[0]) / step
        if np.all(np.abs(k - np.round(k)) < 0.02):
            out.append(
                f"exposure times lie on a geometric progression (ratio {math.exp(step):.4g}): such a stack "
                f"determines f^-1 only up to a factor periodic in log exposure, which the smoothness prior "
                f"resolves approximately; exposure times off the progression (jittered) constrain it"
            )
    span = hi - lo
    if observed[1] - observed[0] < 0.5 * span:
        out.append(
            f"only DN {observed[0]}..{observed[1]} were observed unclipped; f^-1 is extrapolated outside, "
            f"extend the exposure range"
        )
    return out


def check_stack(dn, exposures_ms, white_level: int, black_level: int, margin_dn: int, source: str):
    """The samples of :func:`~emulator.calibration.stack_engel2016.fit_inverse_response` checked: ``(dn int64 of the kept pixels, valid mask,
    exposures, distinct exposures, unclipped samples per image, low, high, table top)``."""
    dn = np.asarray(dn)
    if dn.ndim != 2:
        raise CalibrationError(f"{source}: samples must be (images, pixels), got shape {dn.shape}")
    if dn.dtype.kind not in "ui":
        if dn.dtype.kind != "f" or not np.all(np.isfinite(dn)):
            raise CalibrationError(f"{source}: dn must be finite digital numbers, got {dn.dtype} "
                                   f"{'with NaN or infinity' if dn.dtype.kind == 'f' else ''}".rstrip())
    t = np.asarray(exposures_ms, dtype=np.float64)
    if t.shape != (dn.shape[0],):
        raise CalibrationError(f"{source}: {dn.shape[0]} images but {t.size} exposure times")
    if not np.all(np.isfinite(t) & (t > 0)):
        raise CalibrationError(f"{source}: exposure times must be positive and finite")
    distinct = np.unique(t)
    if distinct.size < 2:
        raise CalibrationError(
            f"{source}: needs at least two distinct exposure times, got {distinct.size} "
            f"({', '.join(f'{e:g}' for e in distinct)} ms)"
        )
    white, black = int(white_level), int(black_level)
    top = table_top_for(white)
    if dn.size and int(dn.max()) > top:
        raise CalibrationError(f"{source}: DN {int(dn.max())} exceeds the {top} of a {white.bit_length()}-bit table")
    lo, hi = black + int(margin_dn), white - int(margin_dn)
    if hi <= lo + 1:
        raise CalibrationError(f"{source}: margin {margin_dn} DN leaves no unclipped range in {black}..{white}")
    valid = (dn > lo) & (dn < hi)
    n_valid_img = valid.sum(axis=1)
    if not valid.any():
        raise CalibrationError(
            f"{source}: every sampled pixel of all {dn.shape[0]} images is clipped "
            f"(<= {lo} or >= {hi} DN): all images saturated or black"
        )
    # a pixel needs unclipped readings at two different exposures
    t_max = np.where(valid, t[:, None], -np.inf).max(axis=0)
    t_min = np.where(valid, t[:, None], np.inf).min(axis=0)
    keep = t_max > t_min
    if keep.sum() < 16:
        raise CalibrationError(
            f"{source}: only {int(keep.sum())} sampled pixel(s) are unclipped at two or more distinct "
            f"exposures (need 16); the stack does not span the exposure range (mostly saturated or black)"
        )
    return dn[:, keep].astype(np.int64), valid[:, keep], t, distinct, n_valid_img, lo, hi, top
