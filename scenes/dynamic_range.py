"""Dynamic range of a radiance image, in decibels.

``DR = 20 log10(L_high / L_low)`` with ``L_high`` and ``L_low`` the 99.9th and
0.1st percentiles of luminance (Rec.709 weights).  Percentiles instead of the
extremes make the figure robust to a few outlier pixels (and to the sun disk,
which covers a handful of pixels).  A 12-bit sensor spans about 72 dB; the
1..32 ms brackets add 30 dB.
"""

from __future__ import annotations

import math

import numpy as np

from scenes.errors import RenderError
from scenes.lighting import LUMINANCE_WEIGHTS_REC709

__all__ = ["luminance", "dynamic_range_db", "DEFAULT_MAX_DB"]

#: Cap of the figure: the low percentile is floored at high * 10**(-DEFAULT_MAX_DB/20).
DEFAULT_MAX_DB = 200.0


def luminance(radiance) -> np.ndarray:
    """Relative luminance Y of linear Rec.709 RGB radiance.

    Parameters
    ----------
    radiance : array-like
        (..., 3) linear RGB, or (...) already single-channel (returned as is).

    Returns
    -------
    numpy.ndarray
        float64 (...).
    """
    a = np.asarray(radiance, dtype=np.float64)
    if a.ndim >= 1 and a.shape[-1] == 3:
        return a @ np.asarray(LUMINANCE_WEIGHTS_REC709)
    return a


def dynamic_range_db(
    radiance,
    *,
    low_percentile: float = 0.1,
    high_percentile: float = 99.9,
    max_db: float = DEFAULT_MAX_DB,
) -> float:
    """Dynamic range of an image in dB: 20 log10 of a high over a low luminance percentile.

    Parameters
    ----------
    radiance : array-like
        (H, W, 3) linear RGB or (H, W) luminance.  Non-finite pixels are ignored.
    low_percentile, high_percentile : float
        Percentiles in [0, 100], low < high (defaults 0.1 and 99.9).
    max_db : float
        Floor for zeros: the low percentile is clamped to at least
        ``high * 10**(-max_db / 20)``, so an image with black pixels reports
        ``max_db`` (200 dB by default), never infinity.

    Returns
    -------
    float
        Dynamic range in dB (0 for a uniform image; 0 if the high percentile is 0).

    Raises
    ------
    RenderError
        Bad percentiles, or no finite pixel.

    Examples
    --------
    >>> import numpy as np
    >>> img = np.ones((10, 100)); img[:, :50] = 1000.0
    >>> round(dynamic_range_db(img), 6)
    60.0
    """
    if not 0.0 <= low_percentile < high_percentile <= 100.0:
        raise RenderError(f"need 0 <= low_percentile < high_percentile <= 100, got {low_percentile}, "
                          f"{high_percentile}")
    y = luminance(radiance).ravel()
    y = y[np.isfinite(y)]
    if y.size == 0:
        raise RenderError("dynamic_range_db: no finite pixel")
    y = np.maximum(y, 0.0)
    lo, hi = np.percentile(y, [low_percentile, high_percentile])
    if hi <= 0.0:
        return 0.0
    lo = max(float(lo), float(hi) * 10.0 ** (-max_db / 20.0))
    return 20.0 * math.log10(float(hi) / lo)
