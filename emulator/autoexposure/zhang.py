"""M_Zhang: soft-percentile gradient exposure control (Zhang, Forster, Scaramuzza, ICRA 2017).

Spec section 4.  The metric is a soft percentile of the squared image gradient; its
derivative with respect to the exposure t is ``sum_i w_i d_(i)`` with
``d = 2 (Ix Dx + Iy Dy)``, ``D = dI/dt`` from the inverse camera response, and the sine
weights ``w`` of the percentile; the exposure follows that derivative.  Outside the band
(1120, 3040) DN of mean gray level a brightness rule takes over (BorealHDR's stabilisation).

borealhdr mode (REF)
    D = 1 / (h(Y) t) with h a cubic smoothing spline (UnivariateSpline, k=3, s=4096) of the
    per-DN differences of the piecewise-linear f^-1 through E_k = 16 v_k, E_0 = 0,
    E_255 = 4095; d sorted by its own value; weights w / ||w||_2; p = 0.8; Classical-50 (with
    its ``abs``) outside the band; t' = max(t + 1e-6 m, 0.02).  The weights are computed for
    the actual pixel count S (REF hard-codes 1200 x 1920) and, off that size, the step is
    scaled by sqrt(S_ref / S) so that gamma * sum(w) stays ~1.04e-3.
paper mode
    D = dI/dt = f^-1(I) / (f^-1'(I) t) (g = ln f^-1), zero at clipped DN; pixels ranked by
    gradient magnitude (Zhang's soft percentile of the gradient), in bins of one Scharr unit
    whose pixels share the mean weight of the ranks they occupy; weights w / sum(w); p = 0.7
    (Zhang's code); outside the band Zhang's own rule dt = t (127 / mean_8 - 1).  The step
    is gradient ascent on ln M in ln t, ``dt / t = STEP_PAPER * (dM/dt) t / M`` (scale-free,
    a project choice: the spec gives no paper-mode gain), and every update is clamped to
    +-10 % as in Zhang's code.  Zhang's over/under-exposure compensation of d is not
    implemented (the spec does not define it).

Without a camera response, REF's D is constant, so d = 0 and the band (1120, 3040) is a
dead band: a ``UserWarning`` says so (paper mode warns that it assumes a linear response).
"""

from __future__ import annotations

import functools
import math
import warnings

import cv2
import numpy as np

from emulator.autoexposure.base import MAX_DN, AutoExposureError, AutoExposureMethod
from emulator.autoexposure.classical import Classical
from emulator.autoexposure.shim import row_blocks
from emulator.numpy_dispatch import avx512_sort_slow_in_this_process as _avx512_sort_slow_here
from emulator.core.response import CameraResponse

__all__ = [
    "Zhang2017",
    "PERCENTILE_REF",
    "PERCENTILE_PAPER",
    "SINE_ORDER",
    "STEP_REF",
    "STEP_PAPER",
    "LOW_BOUND_DN",
    "HIGH_BOUND_DN",
    "FLOOR_MS",
    "REF_PIXELS",
    "MAX_RELATIVE_STEP",
    "CRF_KNOT_SCALE",
    "sine_weights",
    "ref_icrf_derivative",
    "paper_dlogt_table",
    "sorted_values",
]

#: Percentile p of the soft percentile, REF (BorealHDR).
PERCENTILE_REF = 0.8
#: Percentile p of Zhang's own code (paper mode).
PERCENTILE_PAPER = 0.7
#: Order kappa of the sine weights.
SINE_ORDER = 5
#: REF's gradient step gamma, ms per unit of m, at S = REF_PIXELS.
STEP_REF = 1e-6
#: Paper mode: gain of the gradient ascent on ln M in ln t (dimensionless).
STEP_PAPER = 0.05
#: Mean gray level at or below which the brightness fallback runs: 70/256 * 4096.
LOW_BOUND_DN = 70 / 256 * 4096
#: Mean gray level at or above which the brightness fallback runs: 190/256 * 4096.
HIGH_BOUND_DN = 190 / 256 * 4096
#: Lowest exposure the method returns, ms (REF's only bound).
FLOOR_MS = 0.02
#: Pixel count REF's weights are built for (1200 x 1920).
REF_PIXELS = 1200 * 1920
#: Paper mode (Zhang's code): every update is clamped to +-10 % of t.
MAX_RELATIVE_STEP = 0.1
#: pcalib samples v_k are in units where f^-1(4095) = 255; REF's E_k = 16 v_k are DN-like.
CRF_KNOT_SCALE = 16.0
#: Paper-mode fallback target: Zhang's mid-gray on 8 bits.
PAPER_FALLBACK_TARGET_8BIT = 127.0
#: 12-bit to 8-bit divisor of Zhang's fallback.
DN_PER_8BIT = 16.0
#: Paper mode: half-width (DN) of the moving average that smooths f^-1' across pcalib knots.
DERIVATIVE_SMOOTHING_DN = 16

#: Rows per block of the cache-friendly derivative passes.
BLOCK_ROWS = 48

# Convolution kernels of REF (scipy.signal.convolve2d, mode='same', boundary='symm').
SCHARR_X = np.array([[3, 0, -3], [10, 0, -10], [3, 0, -3]], dtype=np.float64)
SCHARR_Y = np.array([[3, 10, 3], [0, 0, 0], [-3, -10, -3]], dtype=np.float64)


@functools.lru_cache(maxsize=8)
def sine_weights(n_pixels: int, p: float, order: int = SINE_ORDER, norm: str = "l2") -> np.ndarray:
    """Soft-percentile weights for S ranks (cached, read-only float64).

    ``w_i = sin(pi i / (2 tau))^order`` for ``i < tau = floor(p S)``, and
    ``sin(pi/2 - pi (i - tau) / (2 (S - tau)))^order`` after; then divided by the L2 norm
    (``norm="l2"``, REF) or by the sum (``norm="sum"``, Zhang's code).
    """
    s = int(n_pixels)
    if s < 2 or not (0.0 < p < 1.0):
        raise AutoExposureError(f"sine_weights: need S >= 2 and 0 < p < 1, got S={s}, p={p}")
    tau = max(1, min(s - 1, int(math.floor(p * s))))
    i = np.arange(s, dtype=np.float64)
    w = np.empty(s)
    w[:tau] = np.sin(np.pi * i[:tau] / (2 * tau)) ** order
    w[tau:] = np.sin(np.pi / 2 - np.pi * (i[tau:] - tau) / (2 * (s - tau))) ** order
    if norm == "l2":
        w /= np.linalg.norm(w)
    elif norm == "sum":
        w /= w.sum()
    else:
        raise AutoExposureError(f"sine_weights: norm must be 'l2' or 'sum', got {norm!r}")
    w.setflags(write=False)
    return w


@functools.lru_cache(maxsize=4)
def _cumulative_weights(n_pixels: int, p: float, order: int) -> np.ndarray:
    """[0, cumsum(sine_weights(..., "sum"))]: the weight of any run of ranks in O(1)."""
    cum = np.concatenate(([0.0], np.cumsum(sine_weights(n_pixels, p, order, "sum"))))
    cum.setflags(write=False)
    return cum


def sorted_values(d: np.ndarray) -> np.ndarray:
    """``np.sort(d)`` of a float64 array; where NumPy's AVX-512 sort is slow, a little faster (4-14 %).

    Two counting passes (NumPy's radix sort of 16-bit keys) order the values by the top 32 bits
    of their order-preserving integer key, which leaves the array nearly sorted; a stable merge
    sort (runs found and merged in linear time) then sorts it exactly.  The result equals
    ``np.sort(d)`` value for value (NaNs last); only equal values (0.0 and -0.0) may swap.
    """
    if d.size < 1 << 16 or not _avx512_sort_slow_here():
        return np.sort(d)
    bits = d.view(np.int64)
    key = ((bits ^ ((bits >> 63) & 0x7FFFFFFFFFFFFFFF)) >> 32) + (1 << 31)  # monotone, 0 .. 2**32 - 1
    order = np.argsort(key.astype(np.uint16), kind="stable")
    order = order[np.argsort((key >> 16).astype(np.uint16)[order], kind="stable")]
    out = d[order]
    out.sort(kind="stable")
    return out


def _ref_knots(response) -> np.ndarray:
    """The 256-style samples v_k of f^-1 that REF reads, in units where the last is 255."""
    if response is None:  # identity: E_k = 16 v_k = DN_k
        return np.linspace(0.0, MAX_DN / CRF_KNOT_SCALE, 256)
    knots = getattr(response, "knots", None)
    if knots is None:
        dn = np.linspace(0.0, float(response.white_level), 256)
        knots = response.inverse(dn)
    knots = np.asarray(knots, dtype=np.float64)
    if knots.ndim != 1 or knots.size < 4 or not np.all(np.isfinite(knots)) or knots[-1] <= 0:
        raise AutoExposureError(f"zhang: unusable response samples (shape {knots.shape}) from {response!r}")
    return knots * (255.0 / knots[-1])


def ref_icrf_derivative(knots: np.ndarray) -> np.ndarray:
    """REF's h = d f^-1 / dI at DN 0..4095 from pcalib samples (spec section 4).

    E_k = 16 v_k with E_0 = 0 and E_last = 4095 at DN_k = linspace(0, 4095, N); f^-1 is the
    linear interpolation (``interp1d``); the differences over 4096 steps of 4095/4096 DN are
    smoothed by ``UnivariateSpline`` (k = 3, s = 4096) and evaluated at every integer DN.
    With pcalib_inside1 h(0) = -0.342, h < 0 below DN ~237, h(4095) = 4.777.
    """
    from scipy.interpolate import UnivariateSpline, interp1d

    e = CRF_KNOT_SCALE * np.asarray(knots, dtype=np.float64)
    e[0] = 0.0
    e[-1] = float(MAX_DN)
    icrf = interp1d(np.linspace(0.0, float(MAX_DN), e.size), e, kind="linear")
    delta = np.diff(icrf(np.linspace(0.0, float(MAX_DN), MAX_DN + 2)))
    spline = UnivariateSpline(np.arange(MAX_DN + 1), delta)
    return spline(np.arange(MAX_DN + 1, dtype=np.float64))


def paper_dlogt_table(response) -> np.ndarray:
    """Paper mode: f^-1(I) / f^-1'(I) per DN (so D = table[I] / t), zero at clipped DN.

    f^-1' is the central difference of the response table, averaged over
    +-DERIVATIVE_SMOOTHING_DN to smooth the kinks between pcalib knots; the table has
    max(4096, white + 1) entries.
    """
    from scipy.ndimage import uniform_filter1d

    g = np.asarray(response.g, dtype=np.float64)
    deriv = uniform_filter1d(np.gradient(g), size=2 * DERIVATIVE_SMOOTHING_DN + 1, mode="nearest")
    table = np.zeros(max(MAX_DN + 1, g.size))
    ok = deriv > 0
    table[: g.size][ok] = g[ok] / deriv[ok]
    white, black = int(response.white_level), int(response.black_level)
    table[white:] = 0.0
    table[: black + 1] = 0.0
    return table


class Zhang2017(AutoExposureMethod):
    """M_Zhang (spec section 4).

    Parameters
    ----------
    response : CameraResponse or None
        The camera's response.  borealhdr mode reads its pcalib samples (``response.knots``);
        paper mode its per-DN table g.  None warns (see the module docstring).
    mode : {"paper", "borealhdr"}
    percentile_fraction : float or None
        p of the soft percentile, a fraction in (0, 1) (default 0.8 borealhdr, 0.7 paper).
    percentile : float or None
        Deprecated alias of ``percentile_fraction`` (the same fraction; kept for
        ``--option zhang.percentile=...`` and old ``run.json`` files).
    step : float or None
        borealhdr: gamma in ms per unit of m (default 1e-6); paper: the dimensionless gain
        of the ln-domain ascent (default :data:`STEP_PAPER`).
    scale_step_with_size : bool
        borealhdr: multiply gamma by sqrt(REF_PIXELS / S) off the reference size.
    range_ms : (float, float) or None
        Optional output clamp, ms.
    """

    name = "zhang"
    accepts_response = True

    def __init__(
        self,
        *,
        response=None,
        mode: str = "paper",
        range_ms="default",
        percentile_fraction: float | None = None,
        step: float | None = None,
        order: int = SINE_ORDER,
        floor_ms: float = FLOOR_MS,
        scale_step_with_size: bool = True,
        percentile: float | None = None,
    ) -> None:
        super().__init__(mode=mode, range_ms=range_ms)
        ref = self.mode == "borealhdr"
        if percentile is not None:  # the old name of the same fraction
            if percentile_fraction is not None and float(percentile_fraction) != float(percentile):
                raise AutoExposureError(f"percentile_fraction {percentile_fraction!r} and its deprecated alias "
                                        f"percentile {percentile!r} differ; give percentile_fraction only")
            percentile_fraction = percentile
        given = percentile_fraction
        self.percentile_fraction = float(given if given is not None else (PERCENTILE_REF if ref else PERCENTILE_PAPER))
        if not 0.0 < self.percentile_fraction < 1.0:
            raise AutoExposureError(f"percentile_fraction must be a fraction in (0, 1), got {given!r}")
        self.step = float(step if step is not None else (STEP_REF if ref else STEP_PAPER))
        self.order = int(order)
        self.floor_ms = float(floor_ms)
        self.scale_step_with_size = bool(scale_step_with_size)
        self.response = response
        self._fallback = Classical(50, mode=mode, range_ms=None)
        if response is None:
            if ref:
                warnings.warn(
                    "zhang (borealhdr mode): no camera response given; with an identity response "
                    "D is constant, d = 0, and the method never moves while the mean gray level "
                    f"lies in ({LOW_BOUND_DN:.0f}, {HIGH_BOUND_DN:.0f}) DN (a dead band). Pass response=.",
                    UserWarning,
                    stacklevel=2,
                )
            else:
                warnings.warn(
                    "zhang (paper mode): no camera response given; assuming a linear response. Pass response=.",
                    UserWarning,
                    stacklevel=2,
                )
        if ref:
            self._h = ref_icrf_derivative(_ref_knots(response))
        else:
            if response is None:
                response = CameraResponse.linear()
            self._dlogt = paper_dlogt_table(response)

    # ------------------------------------------------------------------ pieces
    def _fallback_step(self, y: np.ndarray, mean: float, t: float) -> float:
        self.last["fallback"] = True
        if self.mode == "borealhdr":
            return self._fallback.update(mean, t)
        mean8 = mean / DN_PER_8BIT
        if mean8 > 0:
            dt = t * (PAPER_FALLBACK_TARGET_8BIT / mean8 - 1.0)
        else:
            dt = math.inf
        return t + min(max(dt, -MAX_RELATIVE_STEP * t), MAX_RELATIVE_STEP * t)

    def _products(self, y: np.ndarray, table: np.ndarray, *, with_g2: bool):
        """d = 2 (Ix Dx + Iy Dy) per pixel (flat float64), and Ix^2 + Iy^2 if ``with_g2``.

        ``D = table[Y]`` (the table clipped at its last entry, as ``np.minimum`` did).  Worked
        in row blocks with a one-row halo, so each block's Scharr passes and products stay in
        the CPU cache; on a block's own rows a 3x3 filter equals the whole-image result
        (BORDER_REFLECT applies at the image's top and bottom as before), and Scharr of the
        integer image is exact in float64 whether it reads uint16 or float64.  OpenCV's
        separable Scharr correlates with the flipped kernel and BORDER_REFLECT is scipy's
        'symm', so this is REF's ``convolve2d(img, SCHARR_X, mode='same', boundary='symm')``
        (exactly on the integer image, to rounding on D).
        """
        h, w = y.shape
        if int(y.max()) >= table.size:
            y = np.minimum(y, table.size - 1)
        lut = np.empty(1 << 16, dtype=np.float64)
        lut[: table.size] = table
        lut[table.size :] = table[-1]
        d = np.empty((h, w), dtype=np.float64)
        g2 = np.empty((h, w), dtype=np.float64) if with_g2 else None
        for a0, a1, s0, s1 in row_blocks(h, BLOCK_ROWS):
            block = y[a0:a1]
            ix = cv2.Scharr(block, cv2.CV_64F, 1, 0, borderType=cv2.BORDER_REFLECT)[s0:s1]
            iy = cv2.Scharr(block, cv2.CV_64F, 0, 1, borderType=cv2.BORDER_REFLECT)[s0:s1]
            dmap = cv2.LUT(block, lut)
            dx = cv2.Scharr(dmap, cv2.CV_64F, 1, 0, borderType=cv2.BORDER_REFLECT)[s0:s1]
            dy = cv2.Scharr(dmap, cv2.CV_64F, 0, 1, borderType=cv2.BORDER_REFLECT)[s0:s1]
            rows = slice(a0 + s0, a0 + s1)
            if g2 is not None:
                gb = np.multiply(ix, ix, out=g2[rows])
                gb += iy * iy
            out = np.multiply(ix, dx, out=d[rows])
            iy *= dy
            out += iy
            out *= 2.0
        return d.ravel(), (g2.ravel() if g2 is not None else None)

    def _ref_derivative(self, y: np.ndarray, t: float) -> float:
        """m = sum_i w_i d_(i), d sorted ascending (REF)."""
        d, _ = self._products(y, 1.0 / (self._h * t), with_g2=False)
        d = sorted_values(d)
        # NaN sorts last and +-inf at the ends: d is all finite iff both ends are (else REF's
        # zeros replace the non-finite values, and they are sorted again).
        if not (math.isfinite(d[0]) and math.isfinite(d[-1])):
            d[~np.isfinite(d)] = 0.0
            d.sort()
        w = sine_weights(d.size, self.percentile_fraction, self.order, "l2")
        return float(np.dot(w, d))

    def _paper_derivative(self, y: np.ndarray, t: float) -> tuple[float, float]:
        """(dM/dt, M) with pixels ranked by gradient magnitude, tie bins sharing weights."""
        d, g2 = self._products(y, self._dlogt / t, with_g2=True)
        bad = ~np.isfinite(d)
        if bad.any():
            d[bad] = 0.0
        bins = np.sqrt(g2).astype(np.intp)  # one Scharr unit per bin
        counts = np.bincount(bins)
        cum_w = _cumulative_weights(d.size, self.percentile_fraction, self.order)
        ends = np.cumsum(counts)
        starts = ends - counts
        occupied = counts > 0
        mean_w = np.zeros(counts.size)
        mean_w[occupied] = (cum_w[ends[occupied]] - cum_w[starts[occupied]]) / counts[occupied]
        w = np.take(mean_w, bins)  # each pixel's weight: the mean over the ranks of its bin
        return float(np.dot(w, d)), float(np.dot(w, g2))

    # ------------------------------------------------------------------ step
    def _step(self, raw: np.ndarray, t: float) -> float:
        y = self.gray(raw)
        mean = self.gray_mean(raw)
        self.last["mean_dn"] = mean
        if mean <= LOW_BOUND_DN or mean >= HIGH_BOUND_DN:
            t_new = self._fallback_step(y, mean, t)
        elif self.mode == "borealhdr":
            m = self._ref_derivative(y, t)
            gamma = self.step
            if self.scale_step_with_size and y.size != REF_PIXELS:
                gamma *= math.sqrt(REF_PIXELS / y.size)
            self.last["m"] = m
            t_new = t + gamma * m
        else:
            dm_dt, metric = self._paper_derivative(y, t)
            self.last["m"] = dm_dt
            self.last["metric"] = metric
            if metric > 0 and math.isfinite(dm_dt):
                rel = self.step * dm_dt * t / metric
                rel = min(max(rel, -MAX_RELATIVE_STEP), MAX_RELATIVE_STEP)
            else:
                rel = 0.0
            t_new = t * (1.0 + rel)
        if not math.isfinite(t_new):
            return t_new  # the base guard returns t
        return max(t_new, self.floor_ms)

    @property
    def percentile(self) -> float:
        """Deprecated alias of :attr:`percentile_fraction`."""
        return self.percentile_fraction

    def _options(self) -> dict:
        resp = self.response
        return {
            "percentile_fraction": self.percentile_fraction,
            "step": self.step,
            "order": self.order,
            "floor_ms": self.floor_ms,
            "scale_step_with_size": self.scale_step_with_size,
            "response": None if resp is None else str(getattr(resp, "name", resp)),
        }
