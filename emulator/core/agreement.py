"""Whether AE methods agree across units (numeric core: arrays in, numbers out, no I/O).

* :func:`holm`: Holm's step-down adjustment of p-values;
* :func:`tost_paired`: two one-sided t-tests of equivalence of paired differences within
  a margin;
* :func:`variance_components`: the two-way (unit x method) decomposition without
  replication, vectorised over leading axes: method variance and residual variance;
  :func:`covariance_components`: its cross-product analogue for two tables on the same units;
* :func:`kendall_tau_b`: rank agreement of two orderings, vectorised over leading axes.

:mod:`emulator.core.stats` (the intervals) gives these names too.  SciPy is imported by
:func:`tost_paired` when it runs.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["holm", "tost_paired", "variance_components", "covariance_components", "kendall_tau_b"]


def holm(pvalues) -> np.ndarray:
    """Holm's step-down adjusted p-values (family-wise error control, any dependence).

    NaN p-values (tests that could not be run) stay NaN and do not count in the family.

    Examples
    --------
    >>> holm([0.01, 0.04, 0.03]).round(3).tolist()
    [0.03, 0.06, 0.06]
    """
    p = np.asarray(pvalues, dtype=np.float64)
    out = np.full(p.shape, np.nan)
    flat = p.ravel()
    ok = np.flatnonzero(np.isfinite(flat))
    m = ok.size
    if m == 0:
        return out
    order = ok[np.argsort(flat[ok], kind="stable")]
    adj = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * flat[order]))
    res = out.ravel()
    res[order] = adj
    return res.reshape(p.shape)


def tost_paired(d, margin, axis: int = 0) -> np.ndarray:
    """p-value of two one-sided t-tests that the mean of ``d`` lies within ``(-margin, margin)``.

    ``d`` holds paired differences of independent units along ``axis`` (any leading or
    trailing axes are separate tests).  The p-value is the larger of the two one-sided
    p-values (Schuirmann 1987): below alpha, equivalence is shown at level alpha.  With
    fewer than 2 units, or no spread and the mean outside the margin, the test cannot
    show equivalence (p = 1); no spread and the mean inside gives p = 0.
    """
    from scipy.stats import t as student_t

    d = np.moveaxis(np.asarray(d, dtype=np.float64), axis, 0)
    margin = np.asarray(margin, dtype=np.float64)
    if np.any(margin <= 0):
        raise ValueError(f"margin must be positive, got {margin}")
    n = d.shape[0]
    if n < 2:
        return np.ones(d.shape[1:]) if d.ndim > 1 else np.float64(1.0)
    mean = d.mean(axis=0)
    se = d.std(axis=0, ddof=1) / math.sqrt(n)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_lo = (mean + margin) / se
        t_hi = (mean - margin) / se
    p = np.maximum(student_t.sf(t_lo, n - 1), student_t.cdf(t_hi, n - 1))
    zero = se == 0
    p = np.where(zero, np.where(np.abs(mean) < margin, 0.0, 1.0), p)
    return p


def variance_components(x, axis_units: int = -2, axis_methods: int = -1) -> tuple[np.ndarray, np.ndarray]:
    """Method and residual variance of a units x methods table (two-way, no replication).

    For ``x[u, m] = mu + a_u + b_m + e_um`` (units ``u`` = 1..U, methods ``m`` = 1..M):

    * ``residual = sum (x - row mean - column mean + grand mean)^2 / ((U-1)(M-1))``,
      unbiased for var(e);
    * ``method = (MS_methods - residual) / U`` with ``MS_methods = U * sum_m (column
      mean - grand mean)^2 / (M-1)``: unbiased for the variance of the method effects
      b_m over the methods (ddof 1), and negative when noise alone explains the spread.

    Leading axes are independent tables (e.g. bootstrap replicates).

    Returns
    -------
    (method, residual) : numpy.ndarray
        float64, the leading shape.
    """
    x = np.asarray(x, dtype=np.float64)
    x = np.moveaxis(x, (axis_units, axis_methods), (-2, -1))
    u, m = x.shape[-2:]
    if u < 2 or m < 2:
        raise ValueError(f"need at least 2 units and 2 methods, got {u} x {m}")
    col = x.mean(axis=-2, keepdims=True)
    row = x.mean(axis=-1, keepdims=True)
    grand = col.mean(axis=-1, keepdims=True)
    resid = ((x - row - col + grand) ** 2).sum(axis=(-2, -1)) / ((u - 1) * (m - 1))
    ms_methods = u * ((col - grand) ** 2).sum(axis=(-2, -1)) / (m - 1)
    return (ms_methods - resid) / u, resid


def covariance_components(x, y) -> tuple[np.ndarray, np.ndarray]:
    """Method and residual covariance of two units x methods tables observed on the same units.

    The cross-product analogue of :func:`variance_components` (``covariance_components(x,
    x)`` equals it): unbiased for the covariance over the methods of the two tables'
    method effects when their residuals may be correlated (common random numbers).
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.shape != y.shape:
        raise ValueError(f"x and y must have the same shape, got {x.shape} and {y.shape}")
    u, m = x.shape[-2:]
    if u < 2 or m < 2:
        raise ValueError(f"need at least 2 units and 2 methods, got {u} x {m}")

    def parts(t):
        col = t.mean(axis=-2, keepdims=True)
        row = t.mean(axis=-1, keepdims=True)
        grand = col.mean(axis=-1, keepdims=True)
        return col - grand, t - row - col + grand

    cx, rx = parts(x)
    cy, ry = parts(y)
    resid = (rx * ry).sum(axis=(-2, -1)) / ((u - 1) * (m - 1))
    mcp = u * (cx * cy).sum(axis=(-2, -1)) / (m - 1)
    return (mcp - resid) / u, resid


def kendall_tau_b(x, y) -> np.ndarray:
    """Kendall tau-b of the last axis of ``x`` and ``y`` (vectorised over leading axes).

    Agrees with :func:`scipy.stats.kendalltau` (variant b); NaN where either side ties
    every item (tau-b is undefined there: a tie is not agreement).
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.shape != y.shape:
        raise ValueError(f"x and y must have the same shape, got {x.shape} and {y.shape}")
    i, j = np.triu_indices(x.shape[-1], 1)
    sx = np.sign(x[..., i] - x[..., j])
    sy = np.sign(y[..., i] - y[..., j])
    n0 = i.size
    tx = (sx == 0).sum(axis=-1)
    ty = (sy == 0).sum(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = (sx * sy).sum(axis=-1) / np.sqrt((n0 - tx) * (n0 - ty))
    return np.where((tx == n0) | (ty == n0), np.nan, tau)
