"""Kim's REF metric, the exact part: per-bin sums and the 256-bin arithmetic, correctly rounded.

:func:`emulator.autoexposure.kim.metric_ref` reduces the image to the Y_8 histogram and the
exact integer sum of Q per bin (:func:`bin_sums`); :func:`metric_ref_bins` evaluates REF's
formula on those 256 bins in 30-digit decimal arithmetic and rounds once to float64, so the
metric has the same bits on every machine (tests/emulator/autoexposure/test_autoexposure_kim.py checks it against a
direct 50-digit evaluation).
"""

from __future__ import annotations

import decimal
import math

import numpy as np

__all__: list[str] = ["bin_sums", "metric_ref_bins"]

#: Decimal digits of the 256-bin arithmetic of :func:`metric_ref` (float64 has 17; 30 keeps
#: the result correctly rounded but for values within 1e-13 ulp of a rounding boundary).
_DECIMAL_DIGITS = 30


#: Rows per block of :func:`bin_sums` (a block's float64 weights stay in the CPU cache).
_BIN_BLOCK_ROWS = 32


def bin_sums(y8: np.ndarray, q: np.ndarray) -> list:
    """Exact per-bin sums of ``q`` (uint16) over the bins ``y8`` (uint8), as 256 Python ints.

    ``np.bincount`` with float64 weights, in row blocks: every partial sum is an integer below
    2**53 (2.3 M pixels of at most 65535), so it is exact in any order; the blocks keep the
    converted weights in the cache (twice as fast as one whole-image call).
    """
    rows = max(1, _BIN_BLOCK_ROWS * 1920 // max(1, y8.shape[1]))
    total = np.zeros(256, dtype=np.float64)
    for r in range(0, y8.shape[0], rows):
        total += np.bincount(y8[r:r + rows].ravel(), weights=q[r:r + rows].ravel(), minlength=256)
    return total.astype(np.int64).tolist()


_LN2: dict = {}


def _ln(x: decimal.Decimal) -> decimal.Decimal:
    """ln x for 0 < x <= 1 in the current context, from float64's log and one Newton step.

    ``y0 = log(x)`` (float64, relative error about 1e-16) is exact as a Decimal; with
    ``d = x exp(-y0) - 1`` (about 1e-16), ``ln x = y0 + ln(1 + d) = y0 + d - d^2/2 + O(d^3)``,
    correct to the context's precision (30 digits: |d^3| < 1e-45), at the cost of one
    ``exp``, a third of :meth:`decimal.Decimal.ln`'s.
    """
    y0 = +decimal.Decimal(math.log(float(x)))  # rounded to the context: d is relative to this y0
    d = x * (-y0).exp() - 1
    return y0 + (d - d * d / 2)


def metric_ref_bins(counts: list, q_bin: list, s: int, alpha, tau, threshold) -> float:
    """REF's metric from the Y_8 histogram and per-bin Q sums (ints), in 30-digit decimal arithmetic."""
    with decimal.localcontext(decimal.Context(prec=_DECIMAL_DIGITS, Emax=999999, Emin=-999999)):
        D = decimal.Decimal
        n = D(s)
        occ = [(D(c), D(q)) for c, q in zip(counts, q_bin) if c > 0]
        ln2 = _LN2.get(_DECIMAL_DIGITS)
        if ln2 is None:
            ln2 = _LN2[_DECIMAL_DIGITS] = D(2).ln()
        h = []
        for c, _ in occ:
            p = c / n
            h.append(-p * (_ln(p) / ln2))
        mu = sum(c * hb for (c, _), hb in zip(occ, h)) / n
        var = sum(c * (hb - mu) ** 2 for (c, _), hb in zip(occ, h)) / n
        h_lo, h_hi = min(h), max(h)
        if not var > 0 or h_hi == h_lo:
            return math.nan
        # REF's weights exp(+(H - mu)^2 / (2 sigma^2)) / sum: the 1/sigma factor cancels
        two_var = 2 * var
        e = [((hb - mu) ** 2 / two_var).exp() for hb in h]
        total = sum(c * eb for (c, _), eb in zip(occ, e))
        q_sum = D(sum(q_bin))
        thr = D(repr(float(threshold)))
        a, t = D(repr(float(alpha))), D(repr(float(tau)))
        span = h_hi - h_lo
        gated = D(0)
        weighted = D(0)
        for (c, q), hb, eb in zip(occ, h, e):
            w = eb / total
            weighted += w * q
            h_norm = (hb - h_lo) / span
            if h_norm < thr:
                act = 2 / (1 + (-a * h_norm + t).exp()) - 1
                gated += c * act * w
        return float(weighted + q_sum / n * gated)
