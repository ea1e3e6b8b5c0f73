"""Frozen copies of the AE methods' per-frame arithmetic as it was before the throughput work.

Copied verbatim from commit 7a65fb8 (emulator/autoexposure/shim.py, zhang.py, kim.py) so
that tests can compare the optimised implementations with them on real frames, bit for bit.
Do not edit: this is the oracle, not library code.  The Zhang functions take the method
instance (``self``) for its tables and options, exactly as the methods did.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from emulator.autoexposure.base import MAX_DN, AutoExposureError
from emulator.autoexposure.kim import ACTIVATION_ALPHA, ACTIVATION_TAU, BIT_SHIFT, ENTROPY_THRESHOLD, \
    LOCAL_ENTROPY_SIZE, PAPER_SCALE, softmax_weights
from emulator.autoexposure.shim import DELTA, GAMMAS, LAMBDA, N_NORM, SOBEL_MAX
from emulator.autoexposure.zhang import SCHARR_X, SCHARR_Y, _cumulative_weights, sine_weights

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


BLOCK_ROWS = 48


def gamma_metrics_ref(y: np.ndarray, gammas=GAMMAS, *, delta=DELTA, lam=LAMBDA, n_norm=N_NORM):
    """REF's metrics M_j for a gray image (uint16), and whether each gamma's gradient was flat.

    Returns (M as float64 array, flat as bool array).  Requires max(y) > min(y).
    """
    lo, hi = int(y.min()), int(y.max())
    counts = np.zeros((len(gammas), 5, 5), dtype=np.float64)
    for a0, a1, s0, s1 in row_blocks(y.shape[0], BLOCK_ROWS):
        base = y[a0:a1].astype(np.float64)
        base -= lo
        base /= float(hi - lo)
        for j, g in enumerate(gammas):
            img = np.power(base, g)
            # CV_8U equals REF's CV_16U here: |Sobel| <= 4 on [0, 1], both round half to even
            # and saturate negatives to 0 (checked in the tests).
            gx = cv2.Sobel(img, cv2.CV_8U, 1, 0, ksize=3)
            gy = cv2.Sobel(img, cv2.CV_8U, 0, 1, ksize=3)
            counts[j] += cv2.calcHist([gx[s0:s1], gy[s0:s1]], [0, 1], None, [5, 5], [0, 5, 0, 5])
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
    the gradient's spread, so a flat gradient is an ordinary zero metric).
    """
    metrics = np.zeros(len(gammas))
    scale = np.float32(lam / (SOBEL_MAX * math.sqrt(2.0)))
    for a0, a1, s0, s1 in row_blocks(y.shape[0], BLOCK_ROWS):
        base = np.minimum(y[a0:a1], full_dn).astype(np.float32)
        base *= np.float32(1.0 / full_dn)
        for j, g in enumerate(gammas):
            img = np.power(base, np.float32(g))
            gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3)
            gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3)
            u = cv2.magnitude(gx[s0:s1], gy[s0:s1])
            # lambda (min(m, 1) - delta) + 1, and log10 of max(., 1) is 0 exactly where m < delta.
            u *= scale
            np.minimum(u, np.float32(lam), out=u)
            u += np.float32(1.0 - lam * delta)
            np.maximum(u, np.float32(1.0), out=u)
            np.log10(u, out=u)
            metrics[j] += float(np.sum(u, dtype=np.float64))
    return metrics / n_norm, np.zeros(len(gammas), dtype=bool)


def _scharr(img: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """True 2-D convolution with ``kernel`` (SCHARR_X or SCHARR_Y) and symmetric borders.

    Equals ``scipy.signal.convolve2d(img, kernel, mode='same', boundary='symm')`` (exactly on
    integer images, to rounding on float ones): OpenCV's separable Scharr correlates with
    the flipped kernel, and BORDER_REFLECT is scipy's 'symm'.
    """
    dx, dy = (1, 0) if kernel is SCHARR_X else (0, 1)
    return cv2.Scharr(img, cv2.CV_64F, dx, dy, borderType=cv2.BORDER_REFLECT)


def _ref_derivative(self, y: np.ndarray, t: float) -> float:
    """m = sum_i w_i d_(i), d sorted ascending (REF)."""
    yi = np.minimum(y, MAX_DN)
    y64 = yi.astype(np.float64)
    ix = _scharr(y64, SCHARR_X)
    iy = _scharr(y64, SCHARR_Y)
    d_table = 1.0 / (self._h * t)
    dmap = np.take(d_table, yi)
    dx = _scharr(dmap, SCHARR_X)
    dy = _scharr(dmap, SCHARR_Y)
    d = ix
    d *= dx
    iy *= dy
    d += iy
    d *= 2.0
    d = d.ravel()
    bad = ~np.isfinite(d)
    if bad.any():
        d[bad] = 0.0
    d.sort()
    w = sine_weights(d.size, self.percentile, self.order, "l2")
    return float(np.dot(w, d))


def _paper_derivative(self, y: np.ndarray, t: float) -> tuple[float, float]:
    """(dM/dt, M) with pixels ranked by gradient magnitude, tie bins sharing weights."""
    yi = np.minimum(y, self._dlogt.size - 1)
    y64 = yi.astype(np.float64)
    ix = _scharr(y64, SCHARR_X)
    iy = _scharr(y64, SCHARR_Y)
    dmap = np.take(self._dlogt / t, yi)
    dx = _scharr(dmap, SCHARR_X)
    dy = _scharr(dmap, SCHARR_Y)
    g2 = ix * ix
    g2 += iy * iy
    d = ix
    d *= dx
    iy *= dy
    d += iy
    d *= 2.0
    d = d.ravel()
    d[~np.isfinite(d)] = 0.0
    g2 = g2.ravel()
    bins = np.sqrt(g2).astype(np.intp)  # one Scharr unit per bin
    counts = np.bincount(bins)
    cum_w = _cumulative_weights(d.size, self.percentile, self.order)
    ends = np.cumsum(counts)
    starts = ends - counts
    occupied = counts > 0
    mean_w = np.zeros(counts.size)
    mean_w[occupied] = (cum_w[ends[occupied]] - cum_w[starts[occupied]]) / counts[occupied]
    w = np.take(mean_w, bins)  # each pixel's weight: the mean over the ranks of its bin
    return float(np.dot(w, d)), float(np.dot(w, g2))


def _activation(h_norm: np.ndarray, alpha: float, tau: float) -> np.ndarray:
    return 2.0 / (1.0 + np.exp(-alpha * h_norm + tau)) - 1.0


def _y8(y: np.ndarray) -> np.ndarray:
    """Y_8 = floor(Y / 16) as uint8 (REF's ``(Y / 16.0).astype(np.uint8)``), DN above 4095 clipped."""
    if int(y.max()) > MAX_DN:
        y = np.minimum(y, MAX_DN)
    return (y >> BIT_SHIFT).astype(np.uint8)


def _sobel_16u(img8: np.ndarray, dx: int, dy: int) -> np.ndarray:
    """``cv2.Sobel(img8, CV_16U, dx, dy, ksize=3)`` (negatives saturate to 0), via OpenCV's
    faster signed path: |Sobel| <= 1020 on 8-bit input fits int16 exactly."""
    g = cv2.Sobel(img8, cv2.CV_16S, dx, dy, ksize=3)
    np.maximum(g, 0, out=g)
    return g.view(np.uint16)


def metric_ref(y: np.ndarray, *, alpha=ACTIVATION_ALPHA, tau=ACTIVATION_TAU,
               threshold=ENTROPY_THRESHOLD) -> float:
    """REF's metric E of a gray image (uint16 DN); NaN where REF divides by zero."""
    y8 = _y8(y)
    s = y8.size
    hist = cv2.calcHist([y8], [0], None, [256], [0, 256]).ravel().astype(np.float64)
    occ = hist > 0
    p = hist / s
    h = np.zeros(256)
    h[occ] = -p[occ] * np.log2(p[occ])
    gx = _sobel_16u(y8, 1, 0)
    gy = _sobel_16u(y8, 0, 1)
    q_img = gx * gx  # uint16: wraps mod 65536 like REF
    q_img += gy * gy
    q_flat = q_img.ravel().astype(np.float64)
    q_mean = float(q_flat.sum()) / s
    mu = float(np.dot(hist, h)) / s
    var = float(np.dot(hist, (h - mu) ** 2)) / s
    hh, cc = h[occ], hist[occ]
    h_lo, h_hi = hh.min(), hh.max()
    if not (var > 0.0) or h_hi == h_lo:
        return math.nan
    w = np.zeros(256)
    w[occ] = softmax_weights((hh - mu) ** 2 / (2.0 * var), cc)
    h_norm = (hh - h_lo) / (h_hi - h_lo)
    act = _activation(h_norm, alpha, tau)
    mask = h_norm < threshold
    # sum_i W(Y8_i) Q_i: the per-bin weight gathered by a 256-entry lookup table
    w_img = cv2.LUT(y8, w.reshape(1, 256))
    return float(np.dot(w_img.ravel(), q_flat) + q_mean * np.dot(cc * act * mask, w[occ]))


def local_entropy(img8: np.ndarray, size: int = LOCAL_ENTROPY_SIZE) -> np.ndarray:
    """Entropy (bits) of each pixel's size x size neighbourhood, 256 bins, symmetric padding.

    Like MATLAB's ``entropyfilt(I, true(size))``; float64, same shape.
    """
    r = size // 2
    pad = cv2.copyMakeBorder(img8, r, r, r, r, cv2.BORDER_REFLECT)
    h, w = img8.shape
    views = [pad[i : i + h, j : j + w] for i in range(size) for j in range(size)]
    n = len(views)
    table = np.zeros(n + 1)
    table[1:] = np.log2(np.arange(1, n + 1) / n) / n
    ent = np.zeros((h, w))
    for vj in views:
        c = np.zeros((h, w), dtype=np.uint8)
        for vk in views:
            c += vj == vk
        ent -= table[c]
    return ent


def metric_paper(y: np.ndarray, *, alpha=ACTIVATION_ALPHA, tau=ACTIVATION_TAU,
                 threshold=ENTROPY_THRESHOLD, scale=PAPER_SCALE) -> float:
    """Paper-mode metric E (local entropy, float gradients, Gaussian weight with minus sign).

    Always finite: a flat image scores E = 0 (no gradient), so the GP learns that this
    exposure is poor instead of skipping the frame as REF's guard must.
    """
    y8 = _y8(y)
    hh, ww = y8.shape
    small = cv2.resize(y8, (max(3, round(ww * scale)), max(3, round(hh * scale))), interpolation=cv2.INTER_AREA)
    ent = local_entropy(small).ravel()
    f = small.astype(np.float32)
    gx = cv2.Sobel(f, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(f, cv2.CV_32F, 0, 1, ksize=3)
    qv = (gx.astype(np.float64) ** 2 + gy.astype(np.float64) ** 2).ravel()
    mu = float(ent.mean())
    var = float(ent.var())
    h_lo, h_hi = float(ent.min()), float(ent.max())
    # Degenerate entropy (a flat image): the limits of the formulas, not NaN.  Equal entropies
    # give equal weights, and a flat image has Q = 0, so E = 0: "no gradient information".
    if var > 0.0:
        w = softmax_weights(-((ent - mu) ** 2) / (2.0 * var))
    else:
        w = np.full(ent.size, 1.0 / ent.size)
    h_norm = (ent - h_lo) / (h_hi - h_lo) if h_hi > h_lo else np.zeros_like(ent)
    act = _activation(h_norm, alpha, tau)
    mask = h_norm < threshold
    return float(np.dot(w, qv) + qv.mean() * np.dot(act * mask, w))
