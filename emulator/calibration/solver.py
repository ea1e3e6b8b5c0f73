"""The numerics both estimators share: the piecewise-linear basis, monotone projection, robust weights, solvers.

U (the inverse response) is piecewise linear on knots evenly spaced over DN
``0..table_top`` (:class:`Knots`).  The static-stack objective (Engel et al. 2016) is
solved by variable projection (:func:`solve_varpro`: B eliminated in closed form, one
smallest generalised eigenvector per Huber reweighting) or by the plain alternation
(:func:`solve_als`); the comparametric system (Grossberg and Nayar 2003) by reweighted
smallest-eigenvector solves (:func:`comparametric_irls`).  Every solution is projected
onto the monotone functions (:func:`_monotone`) and scaled to g(table_top) = 255
(:func:`finish_response`).  The estimators in :mod:`emulator.calibration` import the names in
``__all__``; the package's own API does not re-export them.
"""

from __future__ import annotations

import math

import numpy as np

from emulator.calibration.result import report_progress
from emulator.errors import CalibrationError
from emulator.io.pcalib import PCALIB_TOP_VALUE
from emulator.pools import single_thread_pools
from emulator.core.response import CameraResponse

__all__ = ["Knots", "blas_single_thread", "robust_scale", "finish_response", "solve_varpro", "solve_als",
           "comparametric_irls"]


def blas_single_thread():
    """One BLAS thread: the systems here are small (256 knots), and on a loaded machine
    OpenBLAS threads spin-waiting cost 50x the work (:func:`emulator.pools.single_thread_pools`,
    with SciPy's BLAS loaded)."""
    return single_thread_pools(("scipy.linalg",), user_api="blas")


# ============================================================================ numerics
class Knots:
    """Piecewise-linear basis on ``n`` knots evenly spaced over DN ``0..table_top``."""

    def __init__(self, n_knots: int, table_top: int):
        if n_knots < 4:
            raise CalibrationError(f"n_knots must be at least 4, got {n_knots}")
        self.n = int(n_knots)
        self.top = int(table_top)
        self.dn = np.linspace(0.0, float(table_top), self.n)
        self.h = float(table_top) / (self.n - 1)
        all_dn = np.arange(self.top + 1, dtype=np.float64)
        self.j_int, self.f_int = self.locate(all_dn)
        self.penalty = self._second_difference_gram(self.n)

    def locate(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.asarray(d, dtype=np.float64) / self.h
        j = np.clip(np.floor(x).astype(np.int64), 0, self.n - 2)
        return j, x - j

    def table(self, c: np.ndarray) -> np.ndarray:
        """U at every integer DN 0..table_top."""
        return np.interp(np.arange(self.top + 1, dtype=np.float64), self.dn, c)

    def slope_table(self, c: np.ndarray) -> np.ndarray:
        """dU/dDN at every integer DN (the slope of the segment holding it)."""
        seg = np.diff(c) / self.h
        return seg[self.j_int]

    @staticmethod
    def _second_difference_gram(n: int) -> np.ndarray:
        """D2^T D2 in upper banded form (3, n) for scipy.linalg.solveh_banded."""
        main = np.full(n, 6.0)
        main[[0, -1]] = 1.0
        main[[1, -2]] = 5.0
        sup1 = np.full(n, -4.0)
        sup1[[1, -1]] = -2.0
        sup2 = np.ones(n)
        ab = np.zeros((3, n))
        ab[2] = main
        ab[1, 1:] = sup1[1:]
        ab[0, 2:] = sup2[2:]
        return ab

    def second_difference(self) -> np.ndarray:
        """D2, shape (n - 2, n): second differences of the knot values."""
        d2 = np.zeros((self.n - 2, self.n))
        idx = np.arange(self.n - 2)
        d2[idx, idx] = 1.0
        d2[idx, idx + 1] = -2.0
        d2[idx, idx + 2] = 1.0
        return d2

    def dense_penalty(self) -> np.ndarray:
        """D2^T D2, dense (n, n)."""
        d2 = self.second_difference()
        return d2.T @ d2

    def weight_per_knot(self, w_dn: np.ndarray) -> np.ndarray:
        """Data weight carried by each knot from per-DN weights (hat functions)."""
        return np.bincount(self.j_int, w_dn * (1 - self.f_int), self.n) + np.bincount(
            self.j_int + 1, w_dn * self.f_int, self.n
        )


def _isotonic(y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted least-squares increasing fit (pool adjacent violators)."""
    vals: list[float] = []
    wts: list[float] = []
    cnt: list[int] = []
    for v, ww in zip(np.asarray(y, float), np.asarray(w, float)):
        c = 1
        while vals and vals[-1] > v:
            pv, pw, pc = vals.pop(), wts.pop(), cnt.pop()
            tot = pw + ww
            v = (pv * pw + v * ww) / tot
            ww = tot
            c += pc
        vals.append(v)
        wts.append(ww)
        cnt.append(c)
    return np.repeat(np.asarray(vals), cnt)


def _monotone(c: np.ndarray, w: np.ndarray, *, floor: float = 0.0) -> np.ndarray:
    """Isotonic projection, clamped at ``floor`` and made strictly increasing."""
    w = np.asarray(w, float)
    w = w + 1e-9 * max(float(w.max()), 1e-300)
    out = np.maximum(_isotonic(c, w), floor)
    span = max(float(out[-1] - out[0]), 1e-12)
    step = 1e-7 * span
    ramp = step * np.arange(out.size)
    return np.maximum.accumulate(out - ramp) + ramp


def _huber(r: np.ndarray, k: float) -> np.ndarray:
    a = np.abs(r)
    w = np.ones_like(a)
    big = a > k
    w[big] = k / a[big]
    return w


def robust_scale(r: np.ndarray) -> float:
    """1.4826 x the median absolute residual (0 for no residuals)."""
    if r.size == 0:
        return 0.0
    return 1.4826 * float(np.median(np.abs(r)))


def finish_response(
    c: np.ndarray,
    knots: Knots,
    w_knot: np.ndarray,
    name: str,
    black_level: int,
) -> tuple[CameraResponse, np.ndarray]:
    """Monotone, non-negative, strictly increasing knots scaled to g(table_top) = 255."""
    c = _monotone(c, w_knot, floor=0.0)
    c = c * (PCALIB_TOP_VALUE / c[-1])
    c = _monotone(c, w_knot, floor=0.0)  # re-assert strictness after scaling
    # A table evaluated at 256 pcalib knots is what files hold; build the response from the
    # knot values so that writing and reading it back is exact when n_knots == 256.
    resp = CameraResponse.from_samples(c, knots.top, black_level=min(black_level, knots.top - 1), name=name)
    return resp, c


def _knot_system(knots: Knots, d_flat: np.ndarray, w: np.ndarray, y: np.ndarray | None):
    """Per-DN sums -> tridiagonal sum of w * phi phi^T (diag, off), rhs sum of w * y * phi, knot weights."""
    top = knots.top
    j, f = knots.j_int, knots.f_int
    w_dn = np.bincount(d_flat, w, top + 1)
    diag = np.bincount(j, w_dn * (1 - f) ** 2, knots.n) + np.bincount(j + 1, w_dn * f * f, knots.n)
    off = np.bincount(j, w_dn * (1 - f) * f, knots.n)[: knots.n - 1]
    rhs = None
    if y is not None:
        y_dn = np.bincount(d_flat, w * y, top + 1)
        rhs = np.bincount(j, y_dn * (1 - f), knots.n) + np.bincount(j + 1, y_dn * f, knots.n)
    return diag, off, rhs, knots.weight_per_knot(w_dn)


def _irradiance(knots: Knots, c: np.ndarray, d_flat, pix_idx, t_flat, w, n_pix) -> np.ndarray:
    """Closed-form B(x) = sum w t U(I) / sum w t^2 per pixel."""
    u = knots.table(c)[d_flat]
    num = np.bincount(pix_idx, w * t_flat * u, n_pix)
    den = np.bincount(pix_idx, w * t_flat * t_flat, n_pix)
    return num / np.maximum(den, 1e-300)


def _huber_weights(knots: Knots, c, d_flat, pix_idx, t_flat, b, huber_k) -> tuple[np.ndarray, float]:
    """Huber weights of the residuals, measured in DN through the local slope of U."""
    u = knots.table(c)[d_flat]
    slope = np.maximum(knots.slope_table(c), 1e-12)
    r_dn = (u - t_flat * b[pix_idx]) / slope[d_flat]
    sigma = robust_scale(r_dn)
    return _huber(r_dn, huber_k * max(sigma, 0.5)), sigma


def _smallest_eigvec(q: np.ndarray, q1: np.ndarray, x0: np.ndarray, *, max_iter: int = 500, tol: float = 1e-12):
    """Eigenvector of the smallest eigenvalue of q x = mu q1 x (inverse iteration from x0)."""
    from scipy.linalg import cho_factor, cho_solve

    ridge = 1e-12 * float(np.trace(q)) / q.shape[0]
    try:
        fac = cho_factor(q + ridge * np.eye(q.shape[0]))
    except np.linalg.LinAlgError:
        from scipy.linalg import eigh

        vec = eigh(q, q1, subset_by_index=[0, 0])[1][:, 0]
        return vec if vec[-1] >= 0 else -vec
    x = x0 / np.sqrt(float(x0 @ q1 @ x0))
    for _ in range(max_iter):
        y = cho_solve(fac, q1 @ x)
        y = y / np.sqrt(float(y @ q1 @ y))
        if y[-1] < 0:
            y = -y
        done = float(np.max(np.abs(y - x))) < tol * float(np.max(np.abs(y)))
        x = y
        if done:
            break
    return x


def solve_varpro(
    knots, d_flat, pix_idx, t_flat, n_pix, *, smoothness, huber_k, max_iter, tol, progress, c0=None
):
    """Minimise over U with B eliminated: c^T (Q1 - Q2 + lam P) c subject to c^T Q1 c = 1.

    Q1 = sum_s w phi_s phi_s^T (tridiagonal), Q2 = sum_x a_x a_x^T / T_x with
    a_x = sum_i w t_i phi(I_i(x)) and T_x = sum_i w t_i^2.  Huber weights are refreshed
    from the residuals and the system solved again, ``max_iter`` times at most.
    """
    from scipy import sparse

    k = knots.n
    w = np.ones(d_flat.size)
    j_s, f_s = knots.j_int[d_flat], knots.f_int[d_flat]
    pen = knots.dense_penalty()
    c = knots.dn / knots.top if c0 is None else np.asarray(c0, float) / float(c0[-1])
    converged = False
    it = 0
    w_knot = np.zeros(k)
    for it in range(1, max_iter + 1):
        diag, off, _, w_knot = _knot_system(knots, d_flat, w, None)
        q = np.diag(diag) + np.diag(off, 1) + np.diag(off, -1)
        wt = w * t_flat
        t_x = np.bincount(pix_idx, wt * t_flat, n_pix)
        scale_x = 1.0 / np.sqrt(np.maximum(t_x, 1e-300))
        vals = np.concatenate([wt * (1 - f_s), wt * f_s]) * np.concatenate([scale_x[pix_idx]] * 2)
        rows = np.concatenate([pix_idx, pix_idx])
        cols = np.concatenate([j_s, j_s + 1])
        a_mat = sparse.csr_matrix((vals, (rows, cols)), shape=(n_pix, k))
        q -= (a_mat.T @ a_mat).toarray()
        lam = smoothness * float(w_knot[w_knot > 0].mean())
        q += lam * pen
        # normalise by the data: c^T Q1 c = 1 (a fixed knot would let U shrink where the
        # data are and put the scale where none are); smallest generalised eigenvector
        q1 = np.diag(diag + 1e-9 * diag.max()) + np.diag(off, 1) + np.diag(off, -1)
        sol = _smallest_eigvec(0.5 * (q + q.T), q1, c)
        c_new = _monotone(sol, w_knot, floor=0.0)
        c_new = c_new / c_new[-1]
        change = float(np.max(np.abs(c_new - c)))
        c = c_new
        b = _irradiance(knots, c, d_flat, pix_idx, t_flat, w, n_pix)
        w, sigma = _huber_weights(knots, c, d_flat, pix_idx, t_flat, b, huber_k)
        report_progress(progress, it, max_iter, f"fit: robust residual {sigma:.3g} DN")
        if change < tol:
            converged = True
            break
    return c, w, w_knot, it, converged


def solve_als(knots, d_flat, pix_idx, t_flat, n_pix, *, smoothness, huber_k, max_iter, tol, progress, c0=None):
    """Engel et al. 2016: alternate B = closed form, U = banded least squares, with Huber weights."""
    from scipy.linalg import solveh_banded

    w = np.ones(d_flat.size)
    c = knots.dn / knots.top if c0 is None else np.asarray(c0, float) / float(c0[-1])
    converged = False
    it = 0
    w_knot = np.zeros(knots.n)
    for it in range(1, max_iter + 1):
        b = _irradiance(knots, c, d_flat, pix_idx, t_flat, w, n_pix)
        w, sigma = _huber_weights(knots, c, d_flat, pix_idx, t_flat, b, huber_k)
        pred = t_flat * b[pix_idx]
        diag, off, rhs, w_knot = _knot_system(knots, d_flat, w, pred)
        lam = smoothness * float(w_knot[w_knot > 0].mean())
        ab = lam * knots.penalty
        ab[2] += diag
        ab[1, 1:] += off
        c_new = _monotone(solveh_banded(ab, rhs), w_knot, floor=0.0)
        # scale by the data (weighted RMS of U over the samples), not by a knot: a fixed
        # knot lets U shrink slowly where the data are and grow where there are none
        c_new = c_new / math.sqrt(float(w_knot @ (c_new * c_new)) / float(w_knot.sum()))
        change = float(np.max(np.abs(c_new - c))) / float(c_new[-1])
        c = c_new
        report_progress(progress, it, max_iter, f"ALS: robust residual {sigma:.3g} DN")
        if change < tol:
            converged = True
            break
    return c, w, w_knot, it, converged


def comparametric_irls(a_mat, b_mat, d_lo, ratio, knots, presence, smoothness, huber_k, n_iter):
    """Reweighted (relative residuals, Huber) smallest-eigenvector solves of the comparagram system."""
    from scipy import sparse

    n = d_lo.size
    d2_abs = knots.second_difference()
    pen_trace = float(np.trace(d2_abs.T @ d2_abs))
    c = knots.dn / knots.top
    w_rob = np.ones(n)
    for _ in range(n_iter):
        scale = np.maximum(ratio * np.interp(d_lo, knots.dn, c), 1e-6)
        w = w_rob / scale**2
        m = (a_mat.T @ sparse.diags(w) @ a_mat).toarray()
        lam = smoothness * float(np.trace(m)) / max(int((presence > 0).sum()), 1)
        # curvature relative to g itself, like the residuals (an absolute penalty, scaled by
        # the dark knots' large relative weights, would flatten the bright end)
        d2 = d2_abs / np.maximum(c[1:-1], 1e-3 * c[-1])[:, None]
        p_rel = d2.T @ d2
        m = m + lam * p_rel * (pen_trace / np.trace(p_rel))
        # normalise by the data (sum of w * g(d_hi)^2 = 1), not by a knot: a fixed knot lets
        # g shrink where the data are and put the scale where there are none
        norm = (b_mat.T @ sparse.diags(w) @ b_mat).toarray()
        norm[np.diag_indices_from(norm)] += 1e-9 * float(norm.diagonal().max())
        sol = _smallest_eigvec(0.5 * (m + m.T), norm, c)
        c = _monotone(sol, presence, floor=0.0)
        c = c / c[-1]
        rel = (a_mat @ c) / np.maximum(scale, 1e-12)
        sigma = robust_scale(rel)
        w_rob = _huber(rel, huber_k * max(sigma, 1e-6))
    return c
