"""M_Shim: gradient-information exposure control (Shim, Lee, Kweon, IROS 2014); spec section 3.

The image is gamma-mapped with seven gammas; for each, the gradient-information metric
``M_j = sum_i log10(lambda (m_i - delta) + 1) / N`` over pixels whose normalised gradient
``m_i`` reaches ``delta``.  A degree-5 polynomial through (gamma_j, M_j) is maximised on
100 samples; the best gamma drives a multiplicative update of the exposure.

borealhdr mode (REF): min-max normalisation of the image and of the gradient ("Modified"),
gradients from ``cv2.Sobel(..., CV_16U)`` (negatives saturate to 0, values rounded to
integers 0..4), so the metric depends only on the 25 combinations of (Gx, Gy): it is
computed from their counts, with REF's float32 arithmetic per combination.
paper mode: ``Y / 4095`` and ``min(G / (4 sqrt 2), 1)`` with float Sobel gradients.

Guard (both modes, spec section 3): a flat image (max Y = min Y), a gradient that is flat
for every gamma, or metrics whose spread is negligible set gamma-hat by the mean (1/1.9 if
mean < 2048, else 1.9); non-finite metrics return t.
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np

from emulator.autoexposure.base import FULL_SCALE_DN, MAX_DN, AutoExposureError, AutoExposureMethod

__all__ = [
    "Shim2014",
    "GAMMAS",
    "DELTA",
    "LAMBDA",
    "N_NORM",
    "KP",
    "D_NONLINEAR",
    "POLY_DEGREE",
    "N_GAMMA_SAMPLES",
    "SPREAD_RTOL",
    "MID_DN",
    "update_linear",
    "update_nonlinear",
    "gamma_metrics_ref",
    "gamma_metrics_paper",
    "row_blocks",
]

#: The gamma set of Shim 2014 (gamma < 1 brightens).
GAMMAS = (1 / 1.9, 1 / 1.5, 1 / 1.2, 1.0, 1.2, 1.5, 1.9)
#: Gradient-information activation threshold delta (normalised gradient units).
DELTA = 0.06
#: Gradient-information gain lambda.
LAMBDA = 1e3
#: Normaliser N = log10(lambda (1 - delta) + 1) ~ 2.97359, so a full gradient scores 1.
N_NORM = math.log10(LAMBDA * (1 - DELTA) + 1)
#: Proportional gain K_p of the exposure update.
KP = 0.2
#: Shape parameter d of Shim 2018's nonlinear update (REF does not use it).
D_NONLINEAR = 0.75
#: Degree of the least-squares polynomial through the seven (gamma, M) points.
POLY_DEGREE = 5
#: Samples of the polynomial over [1/1.9, 1.9]; gamma-hat is the first argmax.
N_GAMMA_SAMPLES = 100
#: Metrics whose spread is at most this times max(1, |M|) carry no preference.
SPREAD_RTOL = 1e-9
#: The guard's brightness split: dark images brighten, bright ones darken.
MID_DN = FULL_SCALE_DN // 2
#: Largest |Sobel| of a [0, 1] image with the 3x3 kernel (and of the 2-D magnitude, times sqrt 2).
SOBEL_MAX = 4.0


def update_linear(gamma_hat: float, t: float, kp: float = KP) -> float:
    """t' = t (1 + alpha K_p (1 - gamma_hat)), alpha = 1/2 if gamma_hat >= 1 else 1."""
    alpha = 0.5 if gamma_hat >= 1 else 1.0
    return t * (1 + alpha * kp * (1 - gamma_hat))


def update_nonlinear(gamma_hat: float, t: float, kp: float = KP, d: float = D_NONLINEAR) -> float:
    """Shim 2018: R = d tan((2 - gamma_hat) atan(1/d) - atan(1/d)) + 1, t' = t (1 + alpha K_p (R - 1))."""
    alpha = 0.5 if gamma_hat >= 1 else 1.0
    r = d * math.tan((2 - gamma_hat) * math.atan(1 / d) - math.atan(1 / d)) + 1
    return t * (1 + alpha * kp * (r - 1))


def _mbar_f32(m: np.ndarray, delta: float, lam: float, n_norm: float) -> np.ndarray:
    """REF's per-pixel score in float32: log10(lambda (m - delta) + 1) / N where m >= delta, else 0."""
    m = np.asarray(m, dtype=np.float32)
    out = np.zeros_like(m)
    sel = m >= np.float32(delta)
    vals = np.log10(np.float32(lam) * (m[sel] - np.float32(delta)) + np.float32(1))
    out[sel] = (vals.astype(np.float64) * (1.0 / n_norm)).astype(np.float32)
    return out


def row_blocks(height: int, rows: int):
    """(a0, a1, s0, s1): a block of rows [a0, a1) with a one-row halo, and its own rows [s0, s1) inside.

    A 3x3 filter over the block gives exactly the full-image result on the block's own rows
    (the halo supplies the neighbours; at the image's top and bottom the block edge is the
    image edge, so OpenCV's border rule applies as on the whole image).  Working block by
    block keeps every pass in the CPU cache: ~1.5x faster than whole-image passes, same counts.
    """
    for b0 in range(0, height, rows):
        b1 = min(height, b0 + rows)
        a0, a1 = max(0, b0 - 1), min(height, b1 + 1)
        yield a0, a1, b0 - a0, b1 - a0


#: Rows per block of the cache-friendly passes.
BLOCK_ROWS = 48


def _gamma_tables(values: np.ndarray, gammas, size: int = 1 << 16) -> list[np.ndarray]:
    """Per gamma, ``np.power(values, g)`` as a lookup table over every uint16 DN.

    ``values`` holds the normalised image value of each DN (the same arithmetic the image
    would get), so gathering from the table gives the same floating-point numbers as raising
    the whole image to the power (checked on real frames in the tests), at the cost of one
    gather instead of a ``pow`` per pixel.  DN past ``values`` repeat its last entry.
    """
    tables = []
    for g in gammas:
        t = np.empty(size, dtype=values.dtype)
        t[: values.size] = np.power(values, values.dtype.type(g))
        t[values.size :] = t[values.size - 1]
        tables.append(t)
    return tables


def gamma_metrics_ref(y: np.ndarray, gammas=GAMMAS, *, delta=DELTA, lam=LAMBDA, n_norm=N_NORM):
    """REF's metrics M_j for a gray image (uint16), and whether each gamma's gradient was flat.

    Returns (M as float64 array, flat as bool array).  Requires max(y) > min(y).
    Per row block and gamma: one ``cv2.LUT`` (the normalised image to the power g), two
    Sobel passes to uint8, and one 5x5 joint histogram of (Gx, Gy).
    """
    lo, hi = int(y.min()), int(y.max())
    # (DN - lo) / (hi - lo) in float64 as REF computes it per pixel; DN below lo never occur.
    values = np.arange(hi + 1, dtype=np.float64)
    values -= lo
    values /= float(hi - lo)
    values[:lo] = 0.0
    tables = _gamma_tables(values, gammas)
    counts = np.zeros((len(gammas), 25), dtype=np.float64)
    for a0, a1, s0, s1 in row_blocks(y.shape[0], BLOCK_ROWS):
        block = y[a0:a1]
        for j, table in enumerate(tables):
            img = cv2.LUT(block, table)
            # CV_8U equals REF's CV_16U here: |Sobel| <= 4 on [0, 1], both round half to even
            # and saturate negatives to 0 (checked in the tests).
            gx = cv2.Sobel(img, cv2.CV_8U, 1, 0, ksize=3)
            gy = cv2.Sobel(img, cv2.CV_8U, 0, 1, ksize=3)
            # the 5x5 joint histogram of (Gx, Gy), flattened: bin 5 Gx + Gy
            counts[j] += cv2.calcHist([gx[s0:s1], gy[s0:s1]], [0, 1], None, [5, 5], [0, 5, 0, 5]).ravel()
    counts = counts.reshape(len(gammas), 5, 5)
    metrics = np.zeros(len(gammas))
    flat = np.zeros(len(gammas), dtype=bool)
    for j in range(len(gammas)):
        c = counts[j].astype(np.int64)
        if int(c.sum()) != y.size:  # pragma: no cover - |Sobel| <= 4 on a [0, 1] image
            raise AutoExposureError(f"shim: Sobel outside 0..4 on a normalised image ({y.size - int(c.sum())} pixels)")
        ix, iy = np.nonzero(c)
        g_vals = np.sqrt((ix.astype(np.uint16) ** 2 + iy.astype(np.uint16) ** 2)).astype(np.float32)
        gmin, gmax = g_vals.min(), g_vals.max()
        if gmax == gmin:
            flat[j] = True  # REF: 0/0 = NaN, and NaN >= delta is False: M_j = 0
            continue
        m = (g_vals - gmin) / (gmax - gmin)
        mbar = _mbar_f32(m, delta, lam, n_norm)
        metrics[j] = float(np.sum(c[ix, iy] * mbar.astype(np.float64)))
    return metrics, flat


def gamma_metrics_paper(y: np.ndarray, gammas=GAMMAS, *, delta=DELTA, lam=LAMBDA, n_norm=N_NORM,
                        full_dn: float = MAX_DN):
    """Paper-mode metrics: Y / 4095, float Sobel, m = min(G / (4 sqrt 2), 1).

    Returns (M, flat) like :func:`gamma_metrics_ref`; ``flat`` is all False (no division by
    the gradient's spread, so a flat gradient is an ordinary zero metric).  The power is a
    lookup table per gamma (:func:`_paper_tables`); the gradient magnitude is
    ``sqrt(Gx^2 + Gy^2)`` by correctly rounded float32 operations (``cv2.magnitude`` rounds
    some pixels differently depending on the memory alignment of its inputs, so the metric was
    not a function of the image).  The logarithm is taken only where it is not 0 (about a tenth
    of the pixels), as NumPy's float32 natural logarithm, summed in float64 and divided by
    ln 10 once: NumPy computes that logarithm with its own kernel under AVX2 and AVX-512 alike,
    so a method worker (AVX2 on some CPUs, see :mod:`emulator.numpy_dispatch`) and the run's
    own process give the same metric, bit for bit.  ``log10`` in float32 is not such a kernel:
    it is SVML's under AVX-512 and the C library's otherwise, which differ in the last bit.
    """
    metrics = np.zeros(len(gammas))
    scale = np.float32(lam / (SOBEL_MAX * math.sqrt(2.0)))
    tables = _paper_tables(float(full_dn), tuple(float(g) for g in gammas))
    one = np.float32(1.0)
    for a0, a1, s0, s1 in row_blocks(y.shape[0], BLOCK_ROWS):
        block = y[a0:a1]
        for j, table in enumerate(tables):
            img = cv2.LUT(block, table)
            gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3)[s0:s1]
            gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3)[s0:s1]
            np.multiply(gx, gx, out=gx)
            np.multiply(gy, gy, out=gy)
            u = np.add(gx, gy, out=gx)
            np.sqrt(u, out=u)
            # lambda (min(m, 1) - delta) + 1, and its logarithm is 0 exactly where m < delta (u <= 1).
            u *= scale
            np.minimum(u, np.float32(lam), out=u)
            u += np.float32(1.0 - lam * delta)
            logs = u[u > one]  # the pixels whose logarithm is not 0, in the image's order
            np.log(logs, out=logs)
            metrics[j] += float(np.sum(logs, dtype=np.float64))
    return metrics / (math.log(10.0) * n_norm), np.zeros(len(gammas), dtype=bool)


@functools.lru_cache(maxsize=8)
def _paper_tables(full_dn: float, gammas: tuple[float, ...]) -> tuple[np.ndarray, ...]:
    """Paper mode's lookup tables: ``(min(DN, full) / full) ** g`` per gamma, in float32.

    The normalised value is float32 arithmetic, as the image would be normalised.  The power is
    taken in float64 and rounded to float32 once, so the table is the correctly rounded float32
    power but for a value within 2^-29 of a rounding tie, whichever SIMD kernel NumPy picks
    (float32 ``np.power`` is SVML's under AVX-512 and the C library's otherwise, and they differ
    in the last bit).  Read-only: every call shares them.
    """
    values = np.minimum(np.arange(int(full_dn) + 1), full_dn).astype(np.float32)
    values *= np.float32(1.0 / full_dn)
    exponents = [float(np.float32(g)) for g in gammas]  # the float32 gammas, as the float32 power took them
    tables = tuple(t.astype(np.float32) for t in _gamma_tables(values.astype(np.float64), exponents))
    for t in tables:
        t.setflags(write=False)
    return tables


class Shim2014(AutoExposureMethod):
    """M_Shim (spec section 3).

    Parameters
    ----------
    mode : {"paper", "borealhdr"}
        See the module docstring.
    update : {"linear", "nonlinear"}
        Exposure update: REF's linear rule (factor in [0.91, 1.0947]) or Shim 2018's.
    kp : float
        Proportional gain K_p (:data:`KP`).
    range_ms : (float, float) or None
        Optional output clamp, ms.
    """

    name = "shim"

    def __init__(self, *, mode: str = "paper", range_ms="default", update: str = "linear", kp: float = KP) -> None:
        super().__init__(mode=mode, range_ms=range_ms)
        if update not in ("linear", "nonlinear"):
            raise AutoExposureError(f"update must be 'linear' or 'nonlinear', got {update!r}")
        self.update = update
        self.kp = float(kp)
        self._gamma_grid = np.linspace(min(GAMMAS), max(GAMMAS), N_GAMMA_SAMPLES)

    def best_gamma(self, y: np.ndarray) -> float | None:
        """gamma-hat for a gray image (uint16), with the guard; None means 'keep t'."""
        lo, hi = int(y.min()), int(y.max())
        mean = float(y.mean(dtype=np.float64))
        self.last["mean_dn"] = mean
        guess = min(GAMMAS) if mean < MID_DN else max(GAMMAS)
        if hi == lo:
            self.last["guard"] = "flat image"
            return guess
        if self.mode == "borealhdr":
            metrics, flat = gamma_metrics_ref(y)
        else:
            metrics, flat = gamma_metrics_paper(y)
        self.last["metrics"] = metrics.tolist()
        if not np.all(np.isfinite(metrics)):
            self.last["guard"] = "non-finite metric"
            return None
        if flat.all():
            self.last["guard"] = "flat gradient"
            return guess
        spread = float(metrics.max() - metrics.min())
        if spread <= SPREAD_RTOL * max(1.0, float(np.abs(metrics).max())):
            self.last["guard"] = "no preference"
            return guess
        coeffs = np.polyfit(np.asarray(GAMMAS), metrics, POLY_DEGREE)
        values = np.polyval(coeffs, self._gamma_grid)
        if not np.all(np.isfinite(values)):
            self.last["guard"] = "non-finite fit"
            return None
        return float(self._gamma_grid[int(np.argmax(values))])

    def _step(self, raw: np.ndarray, t: float) -> float:
        gamma_hat = self.best_gamma(self.gray(raw))
        self.last["gamma_hat"] = gamma_hat
        if gamma_hat is None:
            return t
        if self.update == "linear":
            return update_linear(gamma_hat, t, self.kp)
        return update_nonlinear(gamma_hat, t, self.kp)

    def _options(self) -> dict:
        return {"update": self.update, "kp": self.kp}
