"""Intervals and tests for comparing AE methods (numeric core: arrays in, numbers out, no I/O).

Every number a report writes that compares methods carries an interval from here:

* :func:`bootstrap_indices`, :func:`block_bootstrap_indices`: resampling plans over
  independent units (walks, sequences, segments) or, within one run, over blocks of
  consecutive cycles (a circular block bootstrap: a time series' neighbours are not
  independent, so single cycles must not be resampled one by one);
* :func:`percentile_interval`: the percentile interval of bootstrap replicates (a
  replicate that is not finite makes the interval unbounded on its side, never dropped);
* :func:`statistic_interval`: a statistic (mean, median) of one sample with its interval,
  :func:`difference_interval`: the difference of a statistic between two methods on the
  same cycles or units (paired: the same resampled indices for both);
* :func:`compare_methods`: per method a statistic with its interval and its difference
  from the best method with an interval (what every report table that ranks methods shows);
* :func:`compare_methods_by_segment`: the same when each value belongs to a segment of a
  time series (an RPE pose pair and the stretch of the run it starts in): a circular block
  bootstrap over the segments, methods on the same segments resampled together (paired);
* :func:`holm`, :func:`tost_paired`, :func:`variance_components`, :func:`covariance_components`,
  :func:`kendall_tau_b`: whether methods agree across units, from :mod:`emulator.core.agreement`
  (given here too).

Randomness arrives as a seed or :class:`numpy.random.Generator`; the same seed gives the
same interval.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from emulator.core.agreement import covariance_components, holm, kendall_tau_b, tost_paired, variance_components

__all__ = [
    "CONFIDENCE",
    "N_RESAMPLES",
    "rng_of",
    "bootstrap_indices",
    "default_block_length",
    "block_bootstrap_indices",
    "percentile_interval",
    "statistic_interval",
    "difference_interval",
    "holm",
    "tost_paired",
    "variance_components",
    "covariance_components",
    "kendall_tau_b",
    "compare_methods",
    "compare_methods_by_segment",
]

#: Confidence level of every interval in the reports.
CONFIDENCE = 0.95
#: Bootstrap replicates of the reports' intervals.
N_RESAMPLES = 2000

_STATISTICS: dict[str, Callable] = {
    "mean": lambda a, axis: np.mean(a, axis=axis),
    "median": lambda a, axis: np.median(a, axis=axis),
}


def rng_of(seed) -> np.random.Generator:
    """A :class:`numpy.random.Generator` from a seed, a SeedSequence or a Generator (passed through)."""
    if isinstance(seed, np.random.Generator):
        return seed
    return np.random.default_rng(seed)


def bootstrap_indices(n_units: int, n_resamples: int, seed=0) -> np.ndarray:
    """Indices of ``n_resamples`` resamples of ``n_units`` independent units, with replacement.

    Returns
    -------
    numpy.ndarray
        int64, shape (n_resamples, n_units).
    """
    if n_units < 1 or n_resamples < 1:
        raise ValueError(f"n_units and n_resamples must be >= 1, got {n_units}, {n_resamples}")
    return rng_of(seed).integers(0, n_units, size=(n_resamples, n_units))


def default_block_length(n: int) -> int:
    """Block length of the block bootstrap for a series of ``n``: ``round(n ** (1/3))``, at least 1.

    The n^(1/3) rate is the mean-squared-error optimal order for the bias and variance
    of a block-bootstrap variance estimate (Hall, Horowitz and Jing 1995).
    """
    return max(1, int(round(n ** (1.0 / 3.0))))


def block_bootstrap_indices(n: int, n_resamples: int, seed=0, block_length: int | None = None) -> np.ndarray:
    """Circular block bootstrap over a series of ``n`` consecutive observations.

    Each resample joins blocks of ``block_length`` consecutive indices (wrapping at the
    end) that start at uniformly drawn positions, cut to length ``n``.  Block length 1 is
    the ordinary bootstrap.

    Returns
    -------
    numpy.ndarray
        int64, shape (n_resamples, n).
    """
    if n < 1 or n_resamples < 1:
        raise ValueError(f"n and n_resamples must be >= 1, got {n}, {n_resamples}")
    b = default_block_length(n) if block_length is None else int(block_length)
    if b < 1:
        raise ValueError(f"block_length must be >= 1, got {block_length}")
    n_blocks = math.ceil(n / b)
    starts = rng_of(seed).integers(0, n, size=(n_resamples, n_blocks))
    idx = (starts[:, :, None] + np.arange(b)[None, None, :]) % n
    return idx.reshape(n_resamples, n_blocks * b)[:, :n]


def percentile_interval(replicates, confidence: float = CONFIDENCE, axis: int = 0, estimate=None) -> tuple:
    """The percentile interval of bootstrap replicates along ``axis``.

    With ``estimate`` (the statistic on the original sample; scalar, 1-D replicates) the
    interval is bias-corrected (the BC percentile interval, Efron 1987): the quantiles
    are moved by ``z0 = Phi^-1(fraction of replicates below the estimate)``, which undoes
    a median bias of the statistic under resampling (a variance component, for one, is
    biased upwards when resampled walks repeat).

    Non-finite replicates (an undefined statistic in that resample, e.g. a ratio over a
    zero denominator) are ordered as +inf, so they can only widen the interval: a
    statistic undefined in more than ``(1 - confidence) / 2`` of the resamples has an
    unbounded upper end.  NaN never comes out of a finite-or-inf input.

    Returns
    -------
    (lo, hi) : float or arrays (the shape of ``replicates`` without ``axis``)
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence}")
    r = np.asarray(replicates, dtype=np.float64)
    r = np.where(np.isnan(r), np.inf, r)
    alpha = (1.0 - confidence) / 2.0
    q = [alpha, 1.0 - alpha]
    if estimate is not None and r.ndim == 1 and r.size and math.isfinite(float(estimate)):
        from scipy.stats import norm

        est = float(estimate)
        frac = (np.sum(r < est) + 0.5 * np.sum(r == est)) / r.size
        frac = min(max(frac, 0.5 / r.size), 1.0 - 0.5 / r.size)
        z0 = norm.ppf(frac)
        q = [float(norm.cdf(2 * z0 + norm.ppf(alpha))), float(norm.cdf(2 * z0 + norm.ppf(1.0 - alpha)))]
    with np.errstate(invalid="ignore"):
        lo, hi = np.quantile(r, q, axis=axis, method="linear")
    # quantile interpolates inf - inf -> nan at a boundary: take the order statistic there
    lo = np.where(np.isnan(lo), np.inf, lo)
    hi = np.where(np.isnan(hi), np.inf, hi)
    if lo.ndim == 0:
        return float(lo), float(hi)
    return lo, hi


def _stat(statistic) -> Callable:
    if callable(statistic):
        return statistic
    try:
        return _STATISTICS[statistic]
    except KeyError:
        raise ValueError(f"statistic must be one of {', '.join(_STATISTICS)} or a callable, got {statistic!r}") \
            from None


def statistic_interval(x, statistic="mean", *, block: bool = False, block_length: int | None = None,
                       confidence: float = CONFIDENCE, n_resamples: int = N_RESAMPLES, seed=0) -> dict:
    """A statistic of one sample with its bootstrap percentile interval.

    Parameters
    ----------
    x : array_like
        1-D; non-finite values are left out (the count left is ``n``).
    statistic : "mean", "median" or callable ``f(array, axis)``
    block : bool
        The values are a time series (per cycle or per image pair): resample blocks of
        consecutive values (:func:`block_bootstrap_indices`); False: independent units.

    Returns
    -------
    dict
        ``estimate``, ``ci95`` ([lo, hi]; None when fewer than 2 values), ``n``,
        ``method`` (how the interval was resampled).
    """
    a = np.asarray(x, dtype=np.float64).ravel()
    a = a[np.isfinite(a)]
    f = _stat(statistic)
    how = ("circular block bootstrap" if block else "bootstrap") + f", {n_resamples} resamples"
    if a.size == 0:
        return {"estimate": None, "ci95": None, "n": 0, "method": how}
    est = float(f(a, None))
    if a.size < 2:
        return {"estimate": est, "ci95": None, "n": int(a.size), "method": how}
    idx = (block_bootstrap_indices(a.size, n_resamples, seed, block_length) if block
           else bootstrap_indices(a.size, n_resamples, seed))
    lo, hi = percentile_interval(f(a[idx], 1), confidence)
    return {"estimate": est, "ci95": [float(lo), float(hi)], "n": int(a.size), "method": how}


def difference_interval(a, b, statistic="mean", *, block: bool = False, block_length: int | None = None,
                        confidence: float = CONFIDENCE, n_resamples: int = N_RESAMPLES, seed=0) -> dict:
    """``statistic(a) - statistic(b)`` of two methods observed on the same cycles or units.

    ``a`` and ``b`` are aligned (index i is the same cycle or unit); pairs where either is
    not finite are left out, and both are resampled with the same indices (a paired
    bootstrap: what the two methods share cancels).  ``excludes_zero`` says whether the
    interval excludes 0 (the methods differ at this confidence).

    Returns
    -------
    dict
        ``estimate``, ``ci95``, ``n``, ``excludes_zero``, ``method``.
    """
    x = np.asarray(a, dtype=np.float64).ravel()
    y = np.asarray(b, dtype=np.float64).ravel()
    if x.shape != y.shape:
        raise ValueError(f"a and b must be aligned, got shapes {x.shape} and {y.shape}")
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    f = _stat(statistic)
    how = ("paired circular block bootstrap" if block else "paired bootstrap") + f", {n_resamples} resamples"
    if x.size == 0:
        return {"estimate": None, "ci95": None, "n": 0, "excludes_zero": None, "method": how}
    est = float(f(x, None) - f(y, None))
    if x.size < 2:
        return {"estimate": est, "ci95": None, "n": int(x.size), "excludes_zero": None, "method": how}
    idx = (block_bootstrap_indices(x.size, n_resamples, seed, block_length) if block
           else bootstrap_indices(x.size, n_resamples, seed))
    lo, hi = percentile_interval(f(x[idx], 1) - f(y[idx], 1), confidence)
    return {"estimate": est, "ci95": [float(lo), float(hi)], "n": int(x.size),
            "excludes_zero": bool(lo > 0 or hi < 0), "method": how}


def _resample(n: int, n_resamples: int, seed, block: bool, block_length: int | None) -> np.ndarray:
    return (block_bootstrap_indices(n, n_resamples, seed, block_length) if block
            else bootstrap_indices(n, n_resamples, seed))


def compare_methods(series, statistic="median", *, higher_is_better: bool = True, block: bool = False,
                    block_length: int | None = None, confidence: float = CONFIDENCE, n_resamples: int = N_RESAMPLES,
                    seed=0) -> dict:
    """Each method's statistic with its interval, and its difference from the best method with an interval.

    Parameters
    ----------
    series : mapping of str to array_like
        Per method, the values the statistic is taken over (per cycle, per image pair, per
        sequence); non-finite values are left out.  Methods whose series have the same
        length are taken as aligned (the same cycles or units): their difference is a paired
        bootstrap; otherwise the two are resampled independently.
    higher_is_better : bool
        Which end of the statistic is the best method.
    block : bool
        Series are time series: circular block bootstrap (:func:`block_bootstrap_indices`).

    Returns
    -------
    dict
        ``{"best": name, "methods": {name: {estimate, ci95, n, difference_to_best: {estimate,
        ci95, excludes_zero}}}, "method": how the intervals were resampled}``; the best
        method's difference is None.  ``excludes_zero`` False means this data cannot tell the
        method from the best one.
    """
    rng = rng_of(seed)
    f = _stat(statistic)
    raw = {m: np.asarray(v, dtype=np.float64).ravel() for m, v in series.items()}
    out = {m: statistic_interval(v, f, block=block, block_length=block_length, confidence=confidence,
                                 n_resamples=n_resamples, seed=rng) for m, v in raw.items()}
    have = {m: r["estimate"] for m, r in out.items() if r["estimate"] is not None}
    best = (max if higher_is_better else min)(have, key=have.get) if have else None
    for m, r in out.items():
        r.pop("method", None)
        r["difference_to_best"] = None
        if best is None or m == best or r["estimate"] is None:
            continue
        a, b = raw[m], raw[best]
        if a.size == b.size:
            d = difference_interval(a, b, f, block=block, block_length=block_length, confidence=confidence,
                                    n_resamples=n_resamples, seed=rng)
        else:
            a, b = a[np.isfinite(a)], b[np.isfinite(b)]
            d = {"estimate": float(f(a, None) - f(b, None)), "ci95": None, "excludes_zero": None}
            if a.size >= 2 and b.size >= 2:
                ra = f(a[_resample(a.size, n_resamples, rng, block, block_length)], 1)
                rb = f(b[_resample(b.size, n_resamples, rng, block, block_length)], 1)
                lo, hi = percentile_interval(ra - rb, confidence)
                d["ci95"], d["excludes_zero"] = [float(lo), float(hi)], bool(lo > 0 or hi < 0)
        r["difference_to_best"] = {k: d[k] for k in ("estimate", "ci95", "excludes_zero")}
    how = ("circular block bootstrap" if block else "bootstrap") + f", {n_resamples} resamples, {confidence:.0%}"
    return {"best": best, "statistic": statistic if isinstance(statistic, str) else "custom", "methods": out,
            "method": how}


def compare_methods_by_segment(values, segments, statistic="median", *, higher_is_better: bool = False,
                               block_length: int | None = None, confidence: float = CONFIDENCE,
                               n_resamples: int = N_RESAMPLES, seed=0) -> dict:
    """:func:`compare_methods` for values grouped in ordered segments of a time series.

    ``values[m]`` and ``segments[m]`` are aligned 1-D arrays per method: each value (e.g.
    one RPE pose pair's error) and the integer label of the segment it belongs to (the
    stretch of the run where the pair starts); labels order the segments in time.  A
    resample draws the segments by a circular block bootstrap (:func:`block_bootstrap_indices`,
    block length ``n_segments ** (1/3)`` unless given) and takes the statistic over every
    value of the drawn segments, so values that share a segment (and neighbouring
    segments) are never treated as independent.  Methods observed on the same segments
    are resampled with the same draws (their difference is paired); others independently.

    Returns the structure of :func:`compare_methods`, each method with ``n`` (values) and
    ``n_segments``; ``ci95`` is None with fewer than 2 segments.
    """
    rng = rng_of(seed)
    f = _stat(statistic)
    plans: dict[tuple, np.ndarray] = {}
    out, reps = {}, {}
    for m in values:
        v = np.asarray(values[m], dtype=np.float64).ravel()
        g = np.asarray(segments[m]).ravel()
        if v.shape != g.shape:
            raise ValueError(f"{m}: values and segments must be aligned, got {v.shape} and {g.shape}")
        ok = np.isfinite(v)
        v, g = v[ok], g[ok]
        units = tuple(int(u) for u in np.unique(g))
        r = {"estimate": None if v.size == 0 else float(f(v, None)), "ci95": None, "n": int(v.size),
             "n_segments": len(units)}
        if len(units) >= 2:
            if units not in plans:
                plans[units] = block_bootstrap_indices(len(units), n_resamples, rng, block_length)
            groups = [v[g == u] for u in units]
            reps[m] = np.array([f(np.concatenate([groups[i] for i in row]), None) for row in plans[units]])
            lo, hi = percentile_interval(reps[m], confidence)
            r["ci95"] = [float(lo), float(hi)]
        out[m] = r
    have = {m: r["estimate"] for m, r in out.items() if r["estimate"] is not None}
    best = (max if higher_is_better else min)(have, key=have.get) if have else None
    for m, r in out.items():
        r["difference_to_best"] = None
        if best is None or m == best or r["estimate"] is None:
            continue
        d = {"estimate": r["estimate"] - out[best]["estimate"], "ci95": None, "excludes_zero": None}
        if m in reps and best in reps:
            lo, hi = percentile_interval(reps[m] - reps[best], confidence)
            d["ci95"], d["excludes_zero"] = [float(lo), float(hi)], bool(lo > 0 or hi < 0)
        r["difference_to_best"] = d
    how = (f"circular block bootstrap over segments, {n_resamples} resamples, {confidence:.0%}; methods on the "
           "same segments resampled together")
    return {"best": best, "statistic": statistic if isinstance(statistic, str) else "custom", "methods": out,
            "method": how}
