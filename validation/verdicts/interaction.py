"""The statistic of the agreement verdict: omega2, the method x condition interaction over the live method
variance, and its one-sided bootstrap bounds.

:func:`omega2_untruncated` of walks x methods tables (leading axes vectorised), :func:`omega2_over_plan` of
every resample of a bootstrap plan at the cost of one matrix product, :func:`one_sided_bounds` (the end of
each side that keeps its level) and the p-values of those bounds (:func:`bound_pvalues`).  The verdict rule
that uses them is :func:`validation.verdicts.agreement.judge`; the estimand and the measured error rates are
described there and in docs/verdicts.md.
"""

from __future__ import annotations

import math

import numpy as np

from emulator.core.stats import percentile_interval, variance_components

__all__ = ["ALPHA", "OMEGA2_MAX", "complete_walks", "omega2", "omega2_untruncated", "omega2_over_plan",
           "one_sided_bounds", "bound_pvalues", "pvalues_of_fraction"]

#: Level of every test (and 1 - confidence of every interval).
ALPHA = 0.05
#: The goal: an emulator agrees when omega2's one-sided 95 % upper bound lies at or below this.
OMEGA2_MAX = 0.2


def complete_walks(*tables) -> np.ndarray:
    """Boolean mask of the walks (rows) where every table has a finite value for every method."""
    ok = None
    for t in tables:
        if t is None:
            continue
        r = np.all(np.isfinite(np.asarray(t, dtype=np.float64)), axis=-1)
        ok = r if ok is None else ok & r
    return ok


def omega2_untruncated(live, emulated) -> np.ndarray:
    """The interaction-variance ratio of walks x methods tables (leading axes vectorised), not truncated:
    negative when noise alone explains more than the interaction.  A live method variance component at or
    below 0 (live does not separate the methods) gives +inf (undefined; cannot support agreement)."""
    live = np.asarray(live, dtype=np.float64)
    emulated = np.asarray(emulated, dtype=np.float64)
    s_live, _ = variance_components(live)
    s_int, _ = variance_components(emulated - live)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = s_int / s_live
    return np.where(s_live > 0, r, np.inf)


def _plan_counts(plan, n_walks: int) -> np.ndarray:
    """(resamples, walks) how often each resample of ``plan`` (an index array or a list of them) draws each walk."""
    if isinstance(plan, np.ndarray):
        n = plan.shape[0]
        flat = (np.arange(n)[:, None] * n_walks + plan).ravel()
    else:
        n = len(plan)
        flat = np.concatenate([k * n_walks + np.asarray(p) for k, p in enumerate(plan)])
    return np.bincount(flat, minlength=n * n_walks).reshape(n, n_walks).astype(np.float64)


def _components_over_counts(counts, *tables) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`emulator.core.stats.variance_components` of every resample (``counts`` per walk) of each walks x
    methods table, from per-walk sums (no resampled table is built, one matrix product): the same numbers up
    to rounding."""
    u = counts.sum(axis=1)
    m = tables[0].shape[1]
    parts = []
    for x in tables:
        x = x - x.mean()  # centred: no cancellation in the sums of squares
        parts += [x, (x ** 2).sum(axis=1, keepdims=True), x.sum(axis=1, keepdims=True) ** 2 / m]
    # einsum, not BLAS: BLAS threads contend on a busy machine (measured 20x slower there)
    sums = np.einsum("rw,wk->rk", counts, np.concatenate(parts, axis=1))
    out = []
    for k in range(len(tables)):
        s = sums[:, k * (m + 2):(k + 1) * (m + 2)]
        col = s[:, :m] / u[:, None]
        grand = col.mean(axis=1)
        ss_cols = u * ((col - grand[:, None]) ** 2).sum(axis=1)
        resid = (s[:, m] - s[:, m + 1] - ss_cols) / ((u - 1) * (m - 1))
        out.append(((ss_cols / (m - 1) - resid) / u, resid))
    return out


def omega2_over_plan(plan, live, emulated) -> np.ndarray:
    """:func:`omega2_untruncated` of every resample of ``plan`` (:func:`validation.verdicts.ranking.cluster_plan`)
    of the walks x methods tables: the same numbers as over the resampled tables up to rounding, at the cost of
    a matrix product (the calibrations judge many studies)."""
    L = np.asarray(live, dtype=np.float64)
    E = np.asarray(emulated, dtype=np.float64)
    (s_live, _), (s_int, _) = _components_over_counts(_plan_counts(plan, L.shape[0]), L, E - L)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = s_int / s_live
    return np.where(s_live > 0, r, np.inf)


def omega2(live, emulated) -> np.ndarray:
    """:func:`omega2_untruncated` truncated at 0 (the point estimate the reports give)."""
    return np.maximum(omega2_untruncated(live, emulated), 0.0)


def one_sided_bounds(replicates, estimate, alpha: float = ALPHA) -> tuple[float, float]:
    """(lower, upper) one-sided ``1 - alpha`` bounds from bootstrap replicates of the untruncated statistic,
    truncated at 0 afterwards.

    Lower: the bias-corrected percentile ``alpha``.  Upper: the larger of the plain and the
    bias-corrected percentiles ``1 - alpha``.  Measured on studies of known omega2
    (docs/verdicts.md): at a true omega2 of 0.2 the bias-corrected lower bound lies above it
    in 3.6-4.6 % of studies (nominal 5 %), the plain one in 9.6-12.2 %; the bias-corrected
    upper bound lies below it in 14-29 %, the plain one in 0-2.4 %: each end is the one that
    keeps its level.
    """
    lo, hi_bc = percentile_interval(replicates, 1.0 - 2.0 * alpha, estimate=estimate)
    _, hi = percentile_interval(replicates, 1.0 - 2.0 * alpha)
    return max(float(lo), 0.0), max(float(hi), float(hi_bc), 0.0)


def bound_pvalues(replicates, estimate, omega2_max: float = OMEGA2_MAX) -> tuple[float, float]:
    """(p_agrees, p_disagrees): the smallest level at which :func:`one_sided_bounds` would put the upper bound at
    or below ``omega2_max`` (agrees), and the lower bound above it (disagrees), from the same replicates.

    With ``G`` the fraction of replicates at or below ``omega2_max`` and ``z0`` the bias correction:
    ``p_disagrees = Phi(Phi^-1(G) - 2 z0)`` (the bias-corrected lower bound), ``p_agrees`` the larger of
    ``1 - G`` (the plain upper bound) and ``1 - Phi(Phi^-1(G) - 2 z0)`` (the bias-corrected one).  A verdict's
    p-value, so that a family of verdicts can be corrected (Holm); up to the quantiles' interpolation,
    ``p_agrees <= alpha`` exactly when the upper bound at ``alpha`` is at or below ``omega2_max``.
    """
    from scipy.stats import norm

    r = np.asarray(replicates, dtype=np.float64).ravel()
    r = np.where(np.isnan(r), np.inf, r)
    n = r.size
    if n == 0:
        return math.nan, math.nan
    clip = (0.5 / n, 1.0 - 0.5 / n)
    z0 = 0.0
    if estimate is not None and math.isfinite(float(estimate)):
        frac = (np.sum(r < estimate) + 0.5 * np.sum(r == estimate)) / n
        z0 = float(norm.ppf(min(max(frac, clip[0]), clip[1])))
    return pvalues_of_fraction(float(np.mean(r <= omega2_max)), z0, n)


def pvalues_of_fraction(g: float, z0: float, n: int) -> tuple[float, float]:
    """(p_agrees, p_disagrees) of :func:`bound_pvalues` from ``g``, the fraction of ``n`` replicates at or below the
    margin, and the bias correction ``z0`` (``g`` clipped to ``[0.5 / n, 1 - 0.5 / n]``)."""
    from scipy.stats import norm

    g = min(max(float(g), 0.5 / n), 1.0 - 0.5 / n)
    bc = float(norm.cdf(norm.ppf(g) - 2.0 * z0))
    return max(1.0 - g, 1.0 - bc), bc
