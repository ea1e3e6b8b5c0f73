"""Inverse camera response calibration: from a static stack, or in situ from a recording.

Two estimators of g = f^-1 (DN -> linear exposure), both written as a pcalib table
(256 samples over DN ``0..table_top``, g(table_top) = 255) that
:meth:`CameraResponse.from_pcalib` reads:

**Static stack** (:func:`calibrate_stack`, :func:`fit_inverse_response`), after Engel,
Usenko and Cremers 2016 (the TUM monoVO photometric calibration).  Images ``I_i`` of a
static scene at exposure times ``t_i``; minimise over U (the inverse response) and
B (per-pixel irradiance, vignetting included)::

    sum_i sum_x  w_ix * (U(I_i(x)) - t_i * B(x))^2   +  lam * ||D2 U||^2

over samples that are not clipped (``black + margin < I < white - margin``).  Details:

* U is piecewise linear on ``n_knots`` knots evenly spaced over ``0..table_top`` (256 by
  default: exactly the pcalib knots, 16.06 DN apart), not one unknown per DN: with 12-bit
  data many single DN values have few samples.  The second-difference penalty
  (``smoothness`` = 0.1 of the mean data weight per knot) ties knots without data to
  their neighbours, which extrapolates linearly beyond the observed DN range.
* The solver (``solver="varpro"``, default) eliminates B in closed form (B is the weighted
  ratio ``sum w t U(I) / sum w t^2``), which leaves a quadratic form in the knots; its
  minimum under a data-weighted normalisation is a smallest generalised eigenvector.  This
  is the fixed point of Engel's alternation, reached in one solve per robust reweighting;
  the plain alternation (``solver="als"``) is kept for comparison, it crawls along the
  nearly flat directions of the objective (thousands of iterations).
* Huber weights (threshold ``huber_k`` = 2 times the robust residual scale, residuals
  measured in DN through the local slope of U), refreshed up to 10 times.
* Each solution is projected onto the monotone functions (weighted isotonic regression,
  pool-adjacent-violators), clamped at 0 and made strictly increasing.
* :func:`calibrate_stack` samples ``max_pixels`` random pixel positions (65536 by default).
* The scale of U is free in the objective and fixed at the end by U(table_top) = 255, as
  in pcalib files; the *offset* is identified by the data (two exposures of one pixel pin
  it), so U(0) is estimated, not forced to 0.  DN outside the observed range are
  extrapolated; the result reports the observed range.
* Exposure times on one geometric progression leave the objective flat along
  ``U -> U * p(log U)`` with p periodic of the progression's ratio (the comparametric
  ambiguity below); only the penalty resolves it, so a warning says so and stacks should
  use jittered exposure times.
* Vignetting is *not* recovered: it needs views of one surface from many positions
  (Engel et al. use a moving camera and a white wall with markers), which a static stack
  does not provide.  B absorbs V(x) * E(x); emulation does not need V.
* A fit whose RMS residual is far above the noise estimated from the images (Immerkaer's
  method per Bayer plane) means the scene moved: :class:`CalibrationError`.

**In situ from a recording** (:func:`calibrate_from_recording`), after the comparametric
approach of Grossberg and Nayar 2003.  The brackets of one sweep (1, 2, 4 ... ms, one
shot every ~46 ms) see nearly the same view, so the distribution of pixel values barely
changes between two brackets except through the exposure ratio r.  Matching quantiles
of the two images (every ``stride``-th pixel of each Bayer plane, values dithered by
+-0.5 DN so that the quantile function is continuous) gives the comparagram
``d_b = tau(d_a)`` and the constraint ``g(tau(d)) = r * g(d)``, solved for a
piecewise-linear U (128 knots) by reweighted least squares on relative residuals over
all consecutive bracket pairs of all sweeps, with the clipped tails excluded.  With
exposure ratios that are all powers of two, g multiplied by any function periodic in
log2(g) satisfies the same equations (the comparametric ambiguity); the smoothness prior
resolves it.

**Scoring a response on a recording** (:func:`cross_bracket_error`): emulate each bracket
from its neighbour in the same sweep (both directions) and compare quantiles 1..99 % of
the emulated and the real pixel values (RMSE in % of the DN range).

Library code never prints; long loops take a ``progress(done, total, label)`` callable.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Callable, Sequence as SequenceType

import numpy as np

from emulator.errors import CalibrationError
from emulator.io.pcalib import PCALIB_SAMPLES, PCALIB_TOP_VALUE
from emulator.io.stack import Stack, read_stack
from emulator.response import BOREALHDR_BLACK_LEVEL, BOREALHDR_WHITE_LEVEL, CameraResponse

__all__ = [
    "CalibrationResult",
    "fit_inverse_response",
    "calibrate_stack",
    "comparagram_pairs",
    "fit_comparametric",
    "calibrate_from_recording",
    "CrossBracketError",
    "cross_bracket_error",
    "bayer_subsample",
    "estimate_noise_dn",
    "response_error",
    "table_top_for",
    "DEFAULT_QUANTILES",
]

Progress = Callable[[int, int, str], None] | None

#: Quantile levels of the cross-bracket score: 1 %, 2 %, ... 99 %.
DEFAULT_QUANTILES = np.arange(1, 100) / 100.0


def _blas_single_thread():
    """Context limiting BLAS to one thread: the systems here are small (256 knots), and on
    a loaded machine OpenBLAS threads spin-waiting cost 50x the work.  No-op without
    threadpoolctl."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl comes with scikit-learn
        import contextlib

        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def _report(progress: Progress, done: int, total: int, label: str) -> None:
    if progress is not None:
        progress(done, total, label)


def table_top_for(white_level: int) -> int:
    """Top DN of a response table for this white level: 2**bits - 1 (4095 for 12-bit data)."""
    return (1 << int(white_level).bit_length()) - 1


# ============================================================================ numerics
class _Knots:
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


def _robust_scale(r: np.ndarray) -> float:
    if r.size == 0:
        return 0.0
    return 1.4826 * float(np.median(np.abs(r)))


def bayer_subsample(raw: np.ndarray, stride: int = 1) -> list[np.ndarray]:
    """The four Bayer planes of a mosaic, each subsampled by ``stride`` (list of 2-D views)."""
    return [raw[i::2, j::2][::stride, ::stride] for i in (0, 1) for j in (0, 1)]


def estimate_noise_dn(
    raw: np.ndarray,
    *,
    black_level: int = BOREALHDR_BLACK_LEVEL,
    white_level: int = BOREALHDR_WHITE_LEVEL,
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


# ============================================================================ result
@dataclass
class CalibrationResult:
    """A recovered inverse response and how well it fits.

    Attributes
    ----------
    response : CameraResponse
        g over DN ``0..table_top`` with g(table_top) = 255 (pcalib units); use
        ``response.with_levels(white_level=...)`` to emulate with the data's clip level.
    knots_dn, knots_g : ndarray, float64, shape (n_knots,)
        The piecewise-linear U: knot positions (DN) and values (pcalib units).
    method : str
        ``"als_engel2016"`` (static stack) or ``"comparametric_grossberg2003"`` (in situ).
    observed_dn : (int, int)
        Lowest and highest DN that carried data; g outside is extrapolated.
    residual_rms_dn, residual_robust_dn : float
        Fit residual in DN (RMS and 1.4826 * MAD).  Stack: observed DN minus f(t * B);
        in situ: matched quantile of the longer bracket minus f(r * g(shorter)).
    residual_rms_pct : float
        ``residual_rms_dn`` in % of the DN range (white - black).
    noise_dn : float
        Noise estimated from the images (stack only; NaN otherwise).
    samples_dn, samples_g : ndarray
        A subset of the fitted observations (DN, exposure in pcalib units) for plots.
    info : dict
        Everything else (counts, iterations, settings, notes), JSON-ready.
    """

    response: CameraResponse
    knots_dn: np.ndarray
    knots_g: np.ndarray
    method: str
    observed_dn: tuple[int, int]
    residual_rms_dn: float
    residual_robust_dn: float
    residual_rms_pct: float
    noise_dn: float
    samples_dn: np.ndarray
    samples_g: np.ndarray
    white_level: int
    black_level: int
    info: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready summary (the knots included, the plot samples not)."""
        return {
            "method": self.method,
            "white_level": self.white_level,
            "black_level": self.black_level,
            "table_top": self.response.white_level,
            "observed_dn": list(self.observed_dn),
            "residual_rms_dn": self.residual_rms_dn,
            "residual_robust_dn": self.residual_robust_dn,
            "residual_rms_pct": self.residual_rms_pct,
            "noise_dn": None if not math.isfinite(self.noise_dn) else self.noise_dn,
            "knots_dn": self.knots_dn.tolist(),
            "knots_g": self.knots_g.tolist(),
            **self.info,
        }


def _finish(
    c: np.ndarray,
    knots: _Knots,
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


# ============================================================================ static stack (ALS)
def _stack_warnings(t: np.ndarray, observed: tuple[int, int], lo: int, hi: int) -> list[str]:
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


def _knot_system(knots: _Knots, d_flat: np.ndarray, w: np.ndarray, y: np.ndarray | None):
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


def _irradiance(knots: _Knots, c: np.ndarray, d_flat, pix_idx, t_flat, w, n_pix) -> np.ndarray:
    """Closed-form B(x) = sum w t U(I) / sum w t^2 per pixel."""
    u = knots.table(c)[d_flat]
    num = np.bincount(pix_idx, w * t_flat * u, n_pix)
    den = np.bincount(pix_idx, w * t_flat * t_flat, n_pix)
    return num / np.maximum(den, 1e-300)


def _huber_weights(knots: _Knots, c, d_flat, pix_idx, t_flat, b, huber_k) -> tuple[np.ndarray, float]:
    """Huber weights of the residuals, measured in DN through the local slope of U."""
    u = knots.table(c)[d_flat]
    slope = np.maximum(knots.slope_table(c), 1e-12)
    r_dn = (u - t_flat * b[pix_idx]) / slope[d_flat]
    sigma = _robust_scale(r_dn)
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


def _solve_varpro(
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
        _report(progress, it, max_iter, f"fit: robust residual {sigma:.3g} DN")
        if change < tol:
            converged = True
            break
    return c, w, w_knot, it, converged


def _solve_als(knots, d_flat, pix_idx, t_flat, n_pix, *, smoothness, huber_k, max_iter, tol, progress, c0=None):
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
        _report(progress, it, max_iter, f"ALS: robust residual {sigma:.3g} DN")
        if change < tol:
            converged = True
            break
    return c, w, w_knot, it, converged


def fit_inverse_response(
    dn: np.ndarray,
    exposures_ms: SequenceType[float],
    *,
    white_level: int = BOREALHDR_WHITE_LEVEL,
    black_level: int = BOREALHDR_BLACK_LEVEL,
    margin_dn: int = 8,
    n_knots: int = PCALIB_SAMPLES,
    smoothness: float = 0.1,
    huber_k: float = 2.0,
    max_iter: int | None = None,
    tol: float = 1e-5,
    solver: str = "varpro",
    init: np.ndarray | None = None,
    n_plot_samples: int = 20000,
    rng: np.random.Generator | int | None = 0,
    progress: Progress = None,
    source: str = "stack",
) -> CalibrationResult:
    """Alternating least squares for U and B (Engel et al. 2016) on sampled pixels.

    Parameters
    ----------
    dn : ndarray, uint16, shape (N, P)
        DN of P pixels in each of N images of a static scene (black level included).
    exposures_ms : sequence of float, length N
        Exposure times in milliseconds.
    white_level, black_level : int
        Clip levels of the data.  The table spans ``0..table_top_for(white_level)``.
    margin_dn : int
        Samples at or below ``black + margin`` or at or above ``white - margin`` are clipped
        and excluded.
    n_knots : int
        Knots of the piecewise-linear U (256: the pcalib knots).
    smoothness : float
        Weight of the second-difference penalty, relative to the mean data weight per knot.
    huber_k : float
        Huber threshold in units of the robust residual scale (DN).
    max_iter, tol : int, float
        Stop when the largest knot change is below ``tol`` of the range, or after
        ``max_iter`` iterations (robust reweightings for ``varpro``, alternations for ``als``).
    solver : {"varpro", "als"}
        ``"varpro"`` (default) eliminates B in closed form, which leaves a quadratic in the
        knots of U: one linear solve per Huber reweighting gives the exact minimum of the
        objective above, i.e. the fixed point of the alternation.  ``"als"`` alternates the
        closed-form updates of B and U as Engel et al. do; it reaches the same minimum but
        converges slowly: the objective has directions along which it is nearly flat (see
        the module docstring), and ALS crawls along them (thousands of iterations).
    init : ndarray, shape (n_knots,), optional
        Starting knot values of U (default: linear).
    rng : Generator or int or None
        Picks the samples kept for plots.
    progress : callable(done, total, label), optional
        Called once per iteration.
    source : str
        Named in error messages.

    Returns
    -------
    CalibrationResult
    """
    dn = np.asarray(dn)
    if dn.ndim != 2:
        raise CalibrationError(f"{source}: samples must be (images, pixels), got shape {dn.shape}")
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
    dn = dn[:, keep].astype(np.int64)
    valid = valid[:, keep]
    n_img, n_pix = dn.shape
    ts = t / t.max()

    knots = _Knots(n_knots, top)
    # samples in pixel-major order (chunks of pixels are contiguous)
    d_flat = dn.T[valid.T]
    pix_idx = np.broadcast_to(np.arange(n_pix)[:, None], (n_pix, n_img))[valid.T]
    img_idx = np.broadcast_to(np.arange(n_img)[None, :], (n_pix, n_img))[valid.T]
    t_flat = ts[img_idx]
    if solver not in ("varpro", "als"):
        raise ValueError(f"solver must be 'varpro' or 'als', got {solver!r}")
    if max_iter is None:
        max_iter = 10 if solver == "varpro" else 500
    with _blas_single_thread():
        c, w, w_knot, it, converged = (_solve_varpro if solver == "varpro" else _solve_als)(
            knots, d_flat, pix_idx, t_flat, n_pix, smoothness=smoothness, huber_k=huber_k,
            max_iter=max_iter, tol=tol, progress=progress, c0=init,
        )

    resp, g = _finish(c, knots, w_knot, f"calibrated:{source}", black)
    # final residual in DN with the finished response
    table = resp.g
    u = table[d_flat]
    num = np.bincount(pix_idx, w * t_flat * u, n_pix)
    den = np.bincount(pix_idx, w * t_flat * t_flat, n_pix)
    b = num / np.maximum(den, 1e-300)
    pred_g = t_flat * b[pix_idx]
    r = d_flat - resp.forward(pred_g)
    rms = float(np.sqrt(np.mean(r * r)))
    robust = _robust_scale(r)
    gen = np.random.default_rng(rng)
    pick = gen.choice(d_flat.size, size=min(n_plot_samples, d_flat.size), replace=False)
    observed = (int(d_flat.min()), int(d_flat.max()))
    warnings = _stack_warnings(t, observed, lo, hi)
    info = {
        "warnings": warnings,
        "n_images": int(n_img),
        "n_exposures": int(distinct.size),
        "exposures_ms": [float(e) for e in t],
        "n_pixels": int(n_pix),
        "n_samples": int(d_flat.size),
        "clipped_fraction": float(1 - valid.mean()),
        "solver": solver,
        "iterations": int(it),
        "converged": bool(converged),
        "n_knots": int(knots.n),
        "margin_dn": int(margin_dn),
        "smoothness": float(smoothness),
        "huber_k": float(huber_k),
        "unclipped_samples_per_image": [int(v) for v in n_valid_img],
        "vignetting": "not recovered (a static stack has no views that separate V(x) from E(x))",
    }
    return CalibrationResult(
        response=resp,
        knots_dn=knots.dn.copy(),
        knots_g=g,
        method="als_engel2016",
        observed_dn=observed,
        residual_rms_dn=rms,
        residual_robust_dn=robust,
        residual_rms_pct=100.0 * rms / (white - black),
        noise_dn=float("nan"),
        samples_dn=d_flat[pick].astype(np.float64),
        samples_g=pred_g[pick],
        white_level=white,
        black_level=black,
        info=info,
    )


def calibrate_stack(
    stack: str | os.PathLike | Stack,
    *,
    max_pixels: int = 65536,
    static_factor: float = 5.0,
    static_floor_pct: float = 1.0,
    check_static: bool = True,
    rng: np.random.Generator | int | None = 0,
    progress: Progress = None,
    **fit_kwargs,
) -> CalibrationResult:
    """Recover the inverse response from a static-scene stack (TUM layout) by ALS.

    Reads the images one by one, keeps ``max_pixels`` random pixel positions (the same in
    every image), estimates the noise of each image, and calls
    :func:`fit_inverse_response` (``fit_kwargs`` go there).

    Raises :class:`CalibrationError` naming the stack for fewer than two distinct
    exposures, images of mixed sizes, a stack whose pixels are all clipped, and a scene that
    is not static: the RMS fit residual exceeds ``max(static_factor * noise,
    static_floor_pct % of the range)`` (disable with ``check_static=False``).
    """
    st = stack if isinstance(stack, Stack) else read_stack(stack)
    src = str(st.path)
    distinct = np.unique(st.exposures_ms)
    if distinct.size < 2:
        raise CalibrationError(
            f"{src}: needs at least two distinct exposure times, got {distinct.size} "
            f"({', '.join(f'{e:g}' for e in distinct)} ms in {len(st)} image(s))"
        )
    gen = np.random.default_rng(rng)
    total = len(st)
    idx = None
    shape = None
    samples = []
    noise = []
    margin = int(fit_kwargs.get("margin_dn", 8))
    for i in range(total):
        img = st.load(i)
        if shape is None:
            shape = img.shape
            n = img.size
            idx = np.sort(gen.choice(n, size=min(int(max_pixels), n), replace=False))
        elif img.shape != shape:
            raise CalibrationError(
                f"{st.image_path(i)}: image size {img.shape[1]}x{img.shape[0]} differs from the first "
                f"image's {shape[1]}x{shape[0]} (mixed sizes in one stack)"
            )
        samples.append(img.reshape(-1)[idx])
        noise.append(estimate_noise_dn(img, black_level=st.black_level, white_level=st.white_level, margin=margin))
        _report(progress, i + 1, total, f"reading {st.names[i]}")
    dn = np.stack(samples)
    result = fit_inverse_response(
        dn,
        st.exposures_ms,
        white_level=st.white_level,
        black_level=st.black_level,
        rng=gen,
        progress=progress,
        source=src,
        **fit_kwargs,
    )
    noise_arr = np.asarray(noise)
    noise_dn = float(np.nanmedian(noise_arr)) if np.isfinite(noise_arr).any() else float("nan")
    result.noise_dn = noise_dn
    span = st.white_level - st.black_level
    limit = max(static_factor * (noise_dn if math.isfinite(noise_dn) else 0.0), static_floor_pct / 100 * span)
    result.info.update(
        {
            "stack": src,
            "image_size": [int(shape[1]), int(shape[0])],
            "max_pixels": int(max_pixels),
            "static_limit_dn": float(limit),
        }
    )
    if check_static and result.residual_rms_dn > limit:
        raise CalibrationError(
            f"{src}: scene is not static: fit residual {result.residual_rms_dn:.1f} DN RMS is far above the "
            f"noise ({noise_dn:.1f} DN estimated from the images; limit {limit:.1f} DN = max({static_factor:g} x "
            f"noise, {static_floor_pct:g} % of range)); did the camera or the scene move?"
        )
    return result


# ============================================================================ in situ (comparametric)
def _planes_of(raw: np.ndarray, stride: int) -> list[np.ndarray]:
    return [p.reshape(-1) for p in bayer_subsample(raw, stride)]


def _dithered_sorted(x: np.ndarray, gen: np.random.Generator) -> np.ndarray:
    """Sorted values with uniform +-0.5 DN dither: a continuous quantile function."""
    return np.sort(x.astype(np.float64) + gen.uniform(-0.5, 0.5, x.size))


def comparagram_pairs(
    sequence,
    *,
    cameras: SequenceType[str] | None = None,
    stride: int = 4,
    n_levels: int = 256,
    margin_dn: int = 8,
    tail: float = 0.005,
    max_ratio: float = 4.0,
    rng: np.random.Generator | int | None = 0,
    progress: Progress = None,
) -> list[dict]:
    """Matched quantiles of consecutive brackets of each sweep (the comparagrams).

    For every cycle and camera, every two consecutive brackets ``a < b`` of that sweep
    with ``b / a <= max_ratio``, and every Bayer plane (subsampled by ``stride``), the
    quantiles of both images at ``n_levels`` levels between the clipped tails (plus
    ``tail``) give points ``(d_a, d_b)`` with ``g(d_b) = (b / a) * g(d_a)``.

    Returns a list of dicts: ``cycle``, ``camera``, ``source_ms``, ``target_ms``,
    ``ratio``, ``d_lo`` and ``d_hi`` (float64 arrays of matched DN).
    """
    cams = tuple(cameras) if cameras is not None else tuple(sequence.cameras)
    white, black = int(sequence.white_level), int(sequence.black_level)
    lo, hi = black + margin_dn, white - margin_dn
    gen = np.random.default_rng(rng)
    jobs = []
    for cyc in sequence.cycles:
        for cam in cams:
            frames = cyc.frames.get(cam, {})
            es = sorted(frames)
            for a, b in zip(es[:-1], es[1:]):
                if b / a <= max_ratio:
                    jobs.append((cyc, cam, a, b))
    out: list[dict] = []
    cache: dict = {}
    for k, (cyc, cam, a, b) in enumerate(jobs):
        for e in (a, b):
            key = (cyc.index, cam, e)
            if key not in cache:
                raw = cyc.frames[cam][e].load()
                cache[key] = [_dithered_sorted(p, gen) for p in _planes_of(raw, stride)]
        for key in [key for key in cache if key[0] != cyc.index]:  # only this sweep is needed
            del cache[key]
        da_all, db_all = [], []
        for pa, pb in zip(cache[(cyc.index, cam, a)], cache[(cyc.index, cam, b)]):
            # clipped fractions (in dithered units the clip sits at lo + 0.5 / hi - 0.5)
            fa_lo = np.searchsorted(pa, lo + 0.5) / pa.size
            fb_lo = np.searchsorted(pb, lo + 0.5) / pb.size
            fa_hi = 1 - np.searchsorted(pa, hi - 0.5) / pa.size
            fb_hi = 1 - np.searchsorted(pb, hi - 0.5) / pb.size
            p0 = max(fa_lo, fb_lo) + tail
            p1 = 1 - max(fa_hi, fb_hi) - tail
            if p1 - p0 < 0.02:
                continue
            levels = np.linspace(p0, p1, n_levels)
            da = np.quantile(pa, levels)
            db = np.quantile(pb, levels)
            ok = (da > lo) & (da < hi) & (db > lo) & (db < hi)
            da_all.append(da[ok])
            db_all.append(db[ok])
        if da_all:
            out.append(
                {
                    "cycle": int(cyc.index),
                    "camera": cam,
                    "source_ms": float(a),
                    "target_ms": float(b),
                    "ratio": float(b / a),
                    "d_lo": np.concatenate(da_all),
                    "d_hi": np.concatenate(db_all),
                }
            )
        _report(progress, k + 1, len(jobs), f"comparagram {cam} cycle {cyc.index} {a:g}->{b:g} ms")
    return out


def _comparametric_irls(a_mat, b_mat, d_lo, ratio, knots, presence, smoothness, huber_k, n_iter):
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
        sigma = _robust_scale(rel)
        w_rob = _huber(rel, huber_k * max(sigma, 1e-6))
    return c


def fit_comparametric(
    pairs: list[dict],
    *,
    white_level: int = BOREALHDR_WHITE_LEVEL,
    black_level: int = BOREALHDR_BLACK_LEVEL,
    n_knots: int = 128,
    smoothness: float = 0.1,
    huber_k: float = 2.0,
    n_iter: int = 8,
    source: str = "recording",
) -> CalibrationResult:
    """Solve ``g(d_hi) = ratio * g(d_lo)`` for a piecewise-linear monotone g.

    Least squares on ``n_knots`` knots over ``0..table_top_for(white_level)``, iteratively
    reweighted (``n_iter`` times) so that residuals count relative to g
    (``1 / (ratio * g(d_lo))``) and with Huber weights (``huber_k`` times the robust
    scale), plus a curvature penalty measured relative to g as well (second differences
    divided by g; ``smoothness`` relative to the mean data weight per knot).  Each solve is
    the smallest generalised eigenvector with the data norm ``sum w g(d_hi)^2`` fixed, so
    the scale is never pinned to a knot without data; g(table_top) = 255 at the end.  The
    offset is identified by the equations.  128 knots (32 DN apart) and the penalty resolve
    the comparametric ambiguity (module docstring).
    """
    from scipy import sparse

    if not pairs:
        raise CalibrationError(
            f"{source}: no usable bracket pairs (need two consecutive brackets of one sweep with "
            f"unclipped pixels)"
        )
    white, black = int(white_level), int(black_level)
    top = table_top_for(white)
    knots = _Knots(n_knots, top)
    d_lo = np.concatenate([p["d_lo"] for p in pairs])
    d_hi = np.concatenate([p["d_hi"] for p in pairs])
    ratio = np.concatenate([np.full(p["d_lo"].size, p["ratio"]) for p in pairs])
    n = d_lo.size
    if n < 8:
        raise CalibrationError(f"{source}: only {n} matched quantiles; the brackets are clipped")
    ja, fa = knots.locate(d_lo)
    jb, fb = knots.locate(d_hi)
    rows = np.repeat(np.arange(n), 4)
    cols = np.stack([jb, jb + 1, ja, ja + 1], axis=1).ravel()
    vals = np.stack([1 - fb, fb, -ratio * (1 - fa), -ratio * fa], axis=1).ravel()
    a_mat = sparse.csr_matrix((vals, (rows, cols)), shape=(n, knots.n))
    b_mat = sparse.csr_matrix(
        (np.stack([1 - fb, fb], axis=1).ravel(), (np.repeat(np.arange(n), 2), np.stack([jb, jb + 1], axis=1).ravel())),
        shape=(n, knots.n),
    )
    presence = np.abs(a_mat).T @ np.ones(n)
    with _blas_single_thread():
        c = _comparametric_irls(a_mat, b_mat, d_lo, ratio, knots, presence, smoothness, huber_k, n_iter)
    resp, g = _finish(c, knots, presence, f"comparametric:{source}", black)
    pred = resp.forward(ratio * resp.inverse(d_lo))
    r = d_hi - pred
    rms = float(np.sqrt(np.mean(r * r)))
    observed = (int(math.floor(min(d_lo.min(), d_hi.min()))), int(math.ceil(max(d_lo.max(), d_hi.max()))))
    info = {
        "n_pairs": len(pairs),
        "n_cycles": len({p["cycle"] for p in pairs}),
        "cameras": sorted({p["camera"] for p in pairs}),
        "ratios": sorted({p["ratio"] for p in pairs}),
        "n_matched_quantiles": int(n),
        "n_knots": int(knots.n),
        "smoothness": float(smoothness),
        "huber_k": float(huber_k),
        "iterations": int(n_iter),
        "vignetting": "not recovered (cancels in the exposure ratio)",
    }
    return CalibrationResult(
        response=resp,
        knots_dn=knots.dn.copy(),
        knots_g=g,
        method="comparametric_grossberg2003",
        observed_dn=observed,
        residual_rms_dn=rms,
        residual_robust_dn=_robust_scale(r),
        residual_rms_pct=100.0 * rms / (white - black),
        noise_dn=float("nan"),
        samples_dn=d_hi.copy(),
        samples_g=ratio * resp.inverse(d_lo),
        white_level=white,
        black_level=black,
        info=info,
    )


def calibrate_from_recording(
    sequence,
    *,
    cameras: SequenceType[str] | None = None,
    stride: int = 4,
    n_levels: int = 256,
    margin_dn: int = 8,
    tail: float = 0.005,
    n_knots: int = 128,
    smoothness: float = 0.1,
    rng: np.random.Generator | int | None = 0,
    progress: Progress = None,
) -> CalibrationResult:
    """Recover g from a bracketed recording's own sweeps (comparametric, no static scene).

    ``sequence`` is a path or an :class:`emulator.dataset.Sequence`.  Images are read
    every ``stride``-th pixel of each Bayer plane.  See :func:`comparagram_pairs` and
    :func:`fit_comparametric`.
    """
    from emulator.dataset import Sequence
    from emulator.io.borealhdr import load_sequence

    seq = sequence if isinstance(sequence, Sequence) else load_sequence(sequence)
    pairs = comparagram_pairs(
        seq, cameras=cameras, stride=stride, n_levels=n_levels, margin_dn=margin_dn, tail=tail, rng=rng,
        progress=progress,
    )
    result = fit_comparametric(
        pairs,
        white_level=seq.white_level,
        black_level=seq.black_level,
        n_knots=n_knots,
        smoothness=smoothness,
        source=str(seq.path),
    )
    result.info.update({"sequence": str(seq.path), "stride": int(stride), "n_levels": int(n_levels),
                        "tail": float(tail), "margin_dn": int(margin_dn)})
    return result


# ============================================================================ scoring
@dataclass
class CrossBracketError:
    """Cross-bracket distribution error of a response on a recording.

    ``pairs`` holds one dict per (cycle, camera, source, target): ``rmse_pct`` is the RMSE
    between quantiles of the emulated and the real target bracket, in % of the DN range.
    """

    pairs: list[dict]
    median_pct: float
    mean_pct: float
    response_name: str
    settings: dict

    def to_dict(self) -> dict:
        return {
            "response": self.response_name,
            "median_pct": self.median_pct,
            "mean_pct": self.mean_pct,
            "n_pairs": len(self.pairs),
            "settings": self.settings,
            "pairs": self.pairs,
        }


def cross_bracket_error(
    sequence,
    response: CameraResponse,
    *,
    cameras: SequenceType[str] | None = None,
    stride: int = 4,
    quantiles: np.ndarray | None = None,
    max_ratio: float = 2.0,
    progress: Progress = None,
) -> CrossBracketError:
    """Score a response on a recording by emulating brackets from their sweep neighbours.

    For every cycle, camera and pair of consecutive brackets ``a < b`` of that sweep with
    ``b / a <= max_ratio``, emulate b from a and a from b; compare the quantiles
    (``quantiles``, default 1 %, 2 % ... 99 %) of the emulated and the real pixel values
    and take the RMSE in % of the DN range (white - black).  Images are read every
    ``stride``-th pixel of each Bayer plane (all four planes pooled).  The response is
    clipped to the recording's levels.  Motion between the brackets (~46 ms) barely changes
    the distributions, so this needs no alignment.
    """
    from emulator.dataset import Sequence
    from emulator.io.borealhdr import load_sequence
    from emulator.emulate import emulate

    seq = sequence if isinstance(sequence, Sequence) else load_sequence(sequence)
    qs = DEFAULT_QUANTILES if quantiles is None else np.asarray(quantiles, float)
    resp = response
    if resp.white_level > seq.white_level or resp.black_level != seq.black_level:
        resp = resp.with_levels(white_level=min(resp.white_level, seq.white_level), black_level=seq.black_level)
    span = float(seq.white_level - seq.black_level)
    cams = tuple(cameras) if cameras is not None else tuple(seq.cameras)
    jobs = []
    for cyc in seq.cycles:
        for cam in cams:
            es = sorted(cyc.frames.get(cam, {}))
            for a, b in zip(es[:-1], es[1:]):
                if b / a <= max_ratio:
                    jobs.append((cyc, cam, a, b))
    pairs: list[dict] = []
    cache: dict = {}
    for k, (cyc, cam, a, b) in enumerate(jobs):
        for e in (a, b):
            key = (cyc.index, cam, e)
            if key not in cache:
                raw = cyc.frames[cam][e].load()
                cache[key] = np.concatenate(_planes_of(raw, stride)).reshape(1, -1)
        for key in [key for key in cache if key[0] != cyc.index]:
            del cache[key]
        for src, tgt in ((a, b), (b, a)):
            emu = emulate(cache[(cyc.index, cam, src)], src, tgt, resp).ravel()
            real = cache[(cyc.index, cam, tgt)].ravel()
            d = np.quantile(emu, qs) - np.quantile(real, qs)
            pairs.append(
                {
                    "cycle": int(cyc.index),
                    "camera": cam,
                    "source_ms": float(src),
                    "target_ms": float(tgt),
                    "rmse_pct": float(100.0 * np.sqrt(np.mean(d * d)) / span),
                }
            )
        _report(progress, k + 1, len(jobs), f"scoring {cam} cycle {cyc.index} {a:g}<->{b:g} ms")
    if not pairs:
        raise CalibrationError(f"{seq.path}: no sweep holds two consecutive brackets to compare")
    errs = np.array([p["rmse_pct"] for p in pairs])
    settings = {
        "stride": int(stride),
        "quantiles": f"{len(qs)} levels {qs[0]:g}..{qs[-1]:g}",
        "max_ratio": float(max_ratio),
        "cameras": list(cams),
        "white_level": int(seq.white_level),
        "black_level": int(seq.black_level),
    }
    return CrossBracketError(pairs, float(np.median(errs)), float(np.mean(errs)), resp.name, settings)


# ============================================================================ comparison, output
def response_error(
    recovered: CameraResponse | np.ndarray,
    true: CameraResponse | np.ndarray,
    *,
    dn_range: tuple[int, int] = (16, 4079),
    align: str = "top",
) -> dict:
    """Error of a recovered g against the true one, in % of the true range.

    Both are g tables over the same DN (or responses).  ``align="top"`` scales both to
    g(top) = 255 (what files hold); ``"scale"`` fits the recovered curve's scale to the true
    one by least squares over ``dn_range`` (g is identified only up to scale).  Returns max
    and RMS of ``|g_rec - g_true|`` over ``dn_range`` in % of ``g_true(top) - g_true(0)``,
    and the same as a DN-equivalent error (``|f_true(g_rec(d)) - d|``).
    """
    gr = recovered.g if isinstance(recovered, CameraResponse) else np.asarray(recovered, float)
    gt = true.g if isinstance(true, CameraResponse) else np.asarray(true, float)
    n = min(gr.size, gt.size)
    gr, gt = gr[:n], gt[:n]
    lo, hi = int(dn_range[0]), min(int(dn_range[1]), n - 1)
    sl = slice(lo, hi + 1)
    gt = gt * (PCALIB_TOP_VALUE / gt[-1])
    if align == "top":
        gr = gr * (PCALIB_TOP_VALUE / gr[-1])
    elif align == "scale":
        gr = gr * float(np.dot(gr[sl], gt[sl]) / np.dot(gr[sl], gr[sl]))
    else:
        raise ValueError(f"align must be 'top' or 'scale', got {align!r}")
    rng_g = gt[-1] - gt[0]
    err = (gr[sl] - gt[sl]) / rng_g * 100
    dn = np.arange(n, dtype=float)
    dn_eq = np.interp(gr[sl], gt, dn) - dn[sl]
    return {
        "max_pct": float(np.max(np.abs(err))),
        "rms_pct": float(np.sqrt(np.mean(err**2))),
        "max_dn_equiv": float(np.max(np.abs(dn_eq))),
        "rms_dn_equiv": float(np.sqrt(np.mean(dn_eq**2))),
        "dn_range": [lo, hi],
        "align": align,
    }
