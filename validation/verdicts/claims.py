"""A claim about methods tested as stated: per-walk contrasts, one-sided paired t-tests, intersection-union.

A claim such as "M_fixed has the most matches" is a statement about *every* other method:
fixed minus classical-30 > 0 and fixed minus classical-50 > 0 and ... .  Each part is a
per-walk contrast of the methods (a weight vector over the methods; its walk mean is the
part's effect), and the claim is

* ``"all"``: every contrast's mean is above 0 (a "best", "most", "poorest", "lowest" claim,
  and the equivalence claim "largest / smallest at most 1.5" written as
  ``1.5 x_j - x_i > 0`` for every ordered pair);
* ``"any"``: at least one contrast's mean is above 0 ("M_fixed is not the best": some other
  method beats it).

The test of one contrast is the one-sided one-sample t-test of its per-walk values (walks are
the independent units; the contrast is paired within the walk).  An ``"all"`` claim holds
when every one of its tests rejects: the intersection-union test, whose p-value is the
largest of the parts' and whose level is the parts' level, with no correction (Berger 1982).
An ``"any"`` claim holds when one part rejects after Bonferroni over the parts (the
union-intersection test).  The opposite claim (the one that ``contradicts``) swaps the two:
an ``"all"`` claim is contradicted when some contrast lies significantly below 0
(Bonferroni), an ``"any"`` claim when every contrast does (intersection-union).

Everything is vectorised over leading axes (simulated studies) so that the calibration runs
thousands of studies at once.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["Claim", "one_sided_p", "claim_pvalues", "holm_rows"]


class Claim:
    """Contrasts (``weights``: (parts, methods)), ``kind`` ``"all"`` or ``"any"``, a label per part."""

    def __init__(self, weights, kind: str, labels):
        if kind not in ("all", "any"):
            raise ValueError(f"kind must be 'all' or 'any', got {kind!r}")
        self.weights = np.atleast_2d(np.asarray(weights, dtype=np.float64))
        self.kind = kind
        self.labels = list(labels)
        if len(self.labels) != self.weights.shape[0]:
            raise ValueError(f"{len(self.labels)} labels for {self.weights.shape[0]} contrasts")

    def contrasts(self, table) -> np.ndarray:
        """Per-walk contrast values: (..., walks, methods) -> (..., walks, parts)."""
        return np.asarray(table, dtype=np.float64) @ self.weights.T


def one_sided_p(x, axis: int = -2) -> tuple[np.ndarray, np.ndarray]:
    """(p of mean > 0, p of mean < 0): one-sample one-sided t-tests along ``axis`` (the walks).

    No spread: p = 0 on the side the mean lies strictly on, 1 otherwise (a mean of exactly 0
    supports neither side); fewer than 2 walks: 1 on both sides.
    """
    from scipy.stats import t as student_t

    x = np.moveaxis(np.asarray(x, dtype=np.float64), axis, -1)
    n = x.shape[-1]
    if n < 2:
        ones = np.ones(x.shape[:-1])
        return ones, ones.copy()
    mean = x.mean(axis=-1)
    se = x.std(axis=-1, ddof=1) / math.sqrt(n)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = mean / se
    p_up = student_t.sf(t, n - 1)
    p_down = student_t.cdf(t, n - 1)
    zero = ~(se > 0)
    p_up = np.where(zero, np.where(mean > 0, 0.0, 1.0), p_up)
    p_down = np.where(zero, np.where(mean < 0, 0.0, 1.0), p_down)
    return p_up, p_down


def claim_pvalues(claim: Claim, table) -> dict[str, np.ndarray]:
    """``holds`` and ``contradicted`` p-values of ``claim`` on (..., walks, methods) tables, with the parts'.

    Returns ``{"holds": (...), "contradicted": (...), "part_mean": (..., parts),
    "part_p_above": (..., parts), "part_p_below": (..., parts)}``.
    """
    c = claim.contrasts(table)
    up, down = one_sided_p(c, axis=-2)
    k = c.shape[-1]
    iut_up, uit_up = up.max(axis=-1), np.minimum(1.0, k * up.min(axis=-1))
    iut_down, uit_down = down.max(axis=-1), np.minimum(1.0, k * down.min(axis=-1))
    if claim.kind == "all":
        holds, contra = iut_up, uit_down
    else:
        holds, contra = uit_up, iut_down
    return {"holds": holds, "contradicted": contra, "part_mean": c.mean(axis=-2), "part_p_above": up,
            "part_p_below": down}


def holm_rows(p) -> np.ndarray:
    """Holm-adjusted p-values along the last axis (one family per row; NaN: not in the family)."""
    p = np.asarray(p, dtype=np.float64)
    flat = p.reshape(-1, p.shape[-1])
    out = np.full(flat.shape, np.nan)
    for r in range(flat.shape[0]):
        ok = np.flatnonzero(np.isfinite(flat[r]))
        if ok.size == 0:
            continue
        order = ok[np.argsort(flat[r, ok], kind="stable")]
        m = ok.size
        out[r, order] = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * flat[r, order]))
    return out.reshape(p.shape)
