"""Photon-transfer points of bracket groups and their robust weighted fit (used by :mod:`emulator.noise.insitu`).

Per group and Bayer phase: align the shots (integer phase correlation), form the
exposure-normalised difference (time-interpolated for triples) and the signal, high-pass
the difference, bin by signal, keep the flattest pixels of each bin and take a
sigma-clipped variance (:func:`robust_variance`); :func:`_fit` fits
``variance - quantisation = x_shot / G + x_read r^2 / G^2`` by weighted least squares.
"""

from __future__ import annotations

import math
import cv2
import numpy as np

from emulator.noise.groups import BracketGroup
from emulator.noise.model import PHASES
from emulator.core.response import CameraResponse

__all__ = ["robust_variance", "per_phase_fits", "per_group_fits", "group_points", "gain_read", "finite_percentiles",
           "fit_bins"]

# ---------------------------------------------------------------------------- in-situ estimation
#: The high-pass applied to difference images (separable second difference, [1, -2, 1] in
#: rows and in columns, on one Bayer plane): it removes anything locally linear in x or in
#: y, such as the residue of a sub-pixel motion between the shots over smooth texture.
_HP = np.outer([1.0, -2.0, 1.0], [1.0, -2.0, 1.0])
#: Its squared coefficients: the variance of the output at a pixel is this kernel applied
#: to the per-pixel variances of the input (independent noise); they sum to 36.
_HP_SQ = _HP * _HP


def _truncated_variance_factor(c: float) -> float:
    """Var of a standard normal truncated to [-c, c]."""
    phi = math.exp(-0.5 * c * c) / math.sqrt(2 * math.pi)
    mass = math.erf(c / math.sqrt(2))
    return 1.0 - 2.0 * c * phi / mass


def robust_variance(x: np.ndarray, clip: float = 4.0, iterations: int = 4) -> tuple[float, int]:
    """Variance of the Gaussian core of ``x``: sigma clipping at ``clip`` sigma.

    Starts from the median and 1.4826 MAD, keeps ``|x - m| <= clip s``, re-estimates
    mean and standard deviation of the kept values (corrected for the truncation of a
    normal at ``clip`` sigma), ``iterations`` times.  Returns (variance, values kept).
    """
    x = np.asarray(x, dtype=np.float64)
    if x.size < 3:
        return float("nan"), int(x.size)
    m = float(np.median(x))
    s = 1.4826 * float(np.median(np.abs(x - m)))
    if not s > 0:
        s = float(np.std(x))
    if not s > 0:
        return 0.0, int(x.size)
    factor = _truncated_variance_factor(clip)
    kept = x
    for _ in range(iterations):
        kept = x[np.abs(x - m) <= clip * s]
        if kept.size < 3:
            return float("nan"), int(kept.size)
        m = float(kept.mean())
        s = math.sqrt(float(kept.var(ddof=1)) / factor)
    return s * s, int(kept.size)


def _align_shift(ha: np.ndarray, hb: np.ndarray, max_shift: int) -> tuple[int, int]:
    """Integer (dy, dx) with ``hb[y + dy, x + dx] ~ ha[y, x]`` (phase correlation of log h)."""
    la = np.log(np.maximum(ha, 1e-6)).astype(np.float32)
    lb = np.log(np.maximum(hb, 1e-6)).astype(np.float32)
    window = cv2.createHanningWindow((la.shape[1], la.shape[0]), cv2.CV_32F)
    (dx, dy), _ = cv2.phaseCorrelate(la - float(la.mean()), lb - float(lb.mean()), window)
    dy, dx = int(round(dy)), int(round(dx))
    if abs(dy) > max_shift or abs(dx) > max_shift:
        return 0, 0
    return dy, dx


def _common_crop(planes: list, shifts: list) -> list:
    """Views of every plane on the region where ``plane_i[y + dy_i, x + dx_i]`` pairs with ``ref[y, x]``."""
    h, w = planes[0].shape
    y0 = max(max(0, -dy) for dy, _ in shifts)
    y1 = min(min(h, h - dy) for dy, _ in shifts)
    x0 = max(max(0, -dx) for _, dx in shifts)
    x1 = min(min(w, w - dx) for _, dx in shifts)
    return [p[y0 + dy: y1 + dy, x0 + dx: x1 + dx] for p, (dy, dx) in zip(planes, shifts)]


def _texture(signal: np.ndarray) -> np.ndarray:
    """Local texture energy of a Bayer plane: 3x3 mean of the squared central-difference gradient.

    What a sub-pixel motion between the shots leaves in their difference is about the shift
    times this gradient, so the flattest pixels by this measure carry the least of it.  It
    is computed from the signal S alone, whose noise is independent of the combination's
    (see :func:`estimate_noise_model`), so selecting on it does not bias the variance.
    """
    s = signal.astype(np.float32)
    gx = cv2.Sobel(s, cv2.CV_32F, 1, 0, ksize=1, scale=0.5)
    gy = cv2.Sobel(s, cv2.CV_32F, 0, 1, ksize=1, scale=0.5)
    return cv2.boxFilter(gx * gx + gy * gy, cv2.CV_32F, (3, 3))


def group_points(group: BracketGroup, response: CameraResponse, slope: np.ndarray, *, limits, n_bins: int,
                 flat_fraction: float, min_pixels: int, align: bool, highpass: bool, clip: float):
    """Photon-transfer points of one group: per phase and intensity bin (see estimate_noise_model)."""
    ts = [float(t) for t in group.exposures_ms]
    w = group.weights()
    g = response.g
    black, white = response.black_level, response.white_level
    n = len(group.raws)
    ref = (n - 1) // 2
    planes = [[np.ascontiguousarray(raw[i::2, j::2]) for i, j in PHASES] for raw in group.raws]
    shifts = [(0, 0)] * n
    if align:
        # one shift per shot for all phases, from the 2x2-binned exposure-normalised images,
        # clipped to what no shot saturates, so that saturation does not pull the match
        hs = [sum(g[p] for p in pl) / t for pl, t in zip(planes, ts)]
        top = min(float(h.max()) for h in hs)
        hs = [np.minimum(h, top) for h in hs]
        max_shift = min(hs[0].shape) // 4
        shifts = [(0, 0) if k == ref else _align_shift(hs[ref], hs[k], max_shift) for k in range(n)]
    c_shot = sum(wi * wi / t for wi, t in zip(w, ts))
    c_read = sum(wi * wi / (t * t) for wi, t in zip(w, ts))
    if highpass:
        c_read *= float(_HP_SQ.sum())
    t_lo, t_hi = min(ts), max(ts)
    points = []
    for p in range(len(PHASES)):
        dns = _common_crop([pl[p] for pl in planes], shifts)
        us = [g[d] for d in dns]
        signal = sum(us) / sum(ts)  # total signal / total time: uncorrelated with diff (shot noise)
        diff = sum(wi * u / t for wi, u, t in zip(w, us, ts))
        qterm = sum(wi * wi * slope[d] ** 2 / (t * t) for wi, d, t in zip(w, dns, ts)) / 12.0
        lo, hi = limits(t_lo, t_hi)
        usable = (signal >= lo) & (signal <= hi)
        for d in dns:
            usable &= (d > black) & (d < white)
        if highpass:
            diff = cv2.filter2D(diff, cv2.CV_64F, _HP, borderType=cv2.BORDER_REFLECT)
            x_shot = cv2.filter2D(signal, cv2.CV_64F, _HP_SQ, borderType=cv2.BORDER_REFLECT) * c_shot
            qterm = cv2.filter2D(qterm, cv2.CV_64F, _HP_SQ, borderType=cv2.BORDER_REFLECT)
            # every input pixel of the 3x3 support usable; the image border is not
            usable = cv2.erode(usable.astype(np.uint8), np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT,
                               borderValue=0).astype(bool)
        else:
            x_shot = signal * c_shot
        if np.count_nonzero(usable) < min_pixels:
            continue
        grad = _texture(signal)
        s, d, xs, gr, qt = signal[usable], diff[usable], x_shot[usable], grad[usable], qterm[usable]
        edges = np.geomspace(float(s.min()), float(s.max()) * (1 + 1e-9), n_bins + 1)
        which = np.searchsorted(edges, s, side="right") - 1
        order = np.argsort(which, kind="stable")
        starts = np.searchsorted(which[order], np.arange(n_bins + 1))
        for k in range(n_bins):
            idx = order[starts[k]: starts[k + 1]]
            if idx.size < min_pixels:
                continue
            if flat_fraction < 1.0:
                keep = max(min_pixels, int(round(flat_fraction * idx.size)))
                if keep < idx.size:
                    idx = idx[np.argpartition(gr[idx], keep - 1)[:keep]]
            var, m = robust_variance(d[idx], clip)
            if not math.isfinite(var) or m < min_pixels:
                continue
            points.append((p, float(s[idx].mean()), float(xs[idx].mean()), c_read, var, float(qt[idx].mean()), m,
                           float(np.mean(s[idx] ** 2))))
    return points, shifts


def _fit(x_shot, x_read, y, q, n, *, extra=None, huber: float = 3.0, iterations: int = 8):
    """Weighted least squares ``y - q = alpha x_shot + beta x_read (+ extra @ gamma)``; variance weights, Huber.

    Weights ``(n - 1) / (2 pred^2)`` (the variance of a variance estimate from n normal
    values), iterated with the prediction, times Huber weights on the standardised
    residuals.  Returns (alpha, beta, covariance of (alpha, beta), final weights).
    """
    X = np.column_stack([x_shot, x_read] + ([] if extra is None else [extra]))
    scale = np.abs(X).max(axis=0)
    scale[scale == 0] = 1.0
    Xs = X / scale
    target = y - q
    w = np.ones_like(y)
    coef = np.linalg.lstsq(Xs, target, rcond=None)[0]
    hub = np.ones_like(y)
    floor = 0.25 * np.maximum(y, np.max(y) * 1e-12)  # keeps weights bounded when a fit goes astray
    for _ in range(iterations):
        pred = np.maximum(Xs @ coef + q, floor)
        w = (n - 1) / (2 * pred**2)
        res = (target - Xs @ coef) * np.sqrt(w)
        hub = np.minimum(1.0, huber / np.maximum(np.abs(res), 1e-300))
        ww = w * hub
        A = Xs.T @ (Xs * ww[:, None])
        coef = np.linalg.lstsq(A, Xs.T @ (ww * target), rcond=None)[0]
    ww = w * hub
    A = Xs.T @ (Xs * ww[:, None])
    res = (target - Xs @ coef) * np.sqrt(ww)
    dof = max(len(y) - X.shape[1], 1)
    dispersion = max(1.0, float(res @ res) / dof)
    cov = np.linalg.pinv(A) * dispersion
    coef = coef / scale
    cov = cov / np.outer(scale, scale)
    return float(coef[0]), float(coef[1]), cov[:2, :2], ww


def gain_read(alpha: float, beta: float, cov: np.ndarray) -> tuple[float, float, float, float]:
    """(G, r, std G, std r) from alpha = 1/G, beta = r^2/G^2 (delta method); r = 0 if beta <= 0."""
    if not alpha > 0:
        return float("nan"), float("nan"), float("nan"), float("nan")
    gain = 1.0 / alpha
    sg = math.sqrt(max(cov[0, 0], 0.0)) / alpha**2
    if beta <= 0:
        return gain, 0.0, sg, float("nan")
    r = math.sqrt(beta) / alpha
    jac = np.array([-math.sqrt(beta) / alpha**2, 0.5 / (alpha * math.sqrt(beta))])
    sr = math.sqrt(max(float(jac @ cov @ jac), 0.0))
    return gain, r, sg, sr


def finite_percentiles(values) -> dict:
    """n, median, 16th/84th percentiles, min, max and relative half-width of the finite ``values``
    (``{"n": 0}`` when none is finite)."""
    v = np.asarray([x for x in values if math.isfinite(x)], dtype=np.float64)
    if v.size == 0:
        return {"n": 0}
    p16, med, p84 = (float(x) for x in np.percentile(v, [16, 50, 84]))
    return {"n": int(v.size), "median": med, "p16": p16, "p84": p84, "min": float(v.min()),
            "max": float(v.max()), "relative_half_width": (p84 - p16) / 2 / med if med else float("nan")}


def fit_bins(cols: dict, mask=None, *, motion_term: bool):
    """:func:`_fit` on the photon-transfer points ``cols`` (a boolean ``mask`` selects some),
    with one ``S^2`` column per bracket group when ``motion_term``."""
    m = np.ones(cols["n"].size, dtype=bool) if mask is None else mask
    extra = None
    if motion_term:
        grp = cols["group"][m]
        extra = np.column_stack([(grp == k) * cols["signal2"][m] for k in np.unique(grp)])
    return _fit(cols["x_shot"][m], cols["x_read"][m], cols["variance"][m], cols["quantisation"][m], cols["n"][m],
                extra=extra)


def per_phase_fits(cols: dict, names, gain: float, read: float, motion_term: bool):
    """Gain and read noise fitted per Bayer phase: ``(per_channel, phase gains, phase read noises)``;
    a phase with fewer than 3 bins takes the pooled values."""
    per_channel = {}
    phase_gain, phase_read = [], []
    for p, nm in enumerate(names):
        m = cols["phase"] == p
        if np.count_nonzero(m) < 3:
            per_channel[nm] = {"n_bins": int(np.count_nonzero(m))}
            phase_gain.append(gain)
            phase_read.append(read)
            continue
        a_p, b_p, c_p, _ = fit_bins(cols, m, motion_term=motion_term)
        gp, rp, sgp, srp = gain_read(a_p, b_p, c_p)
        per_channel[nm] = {"gain_e_per_h": gp, "read_noise_e": rp, "gain_std": sgp, "read_noise_std": srp,
                           "n_bins": int(np.count_nonzero(m))}
        phase_gain.append(gp if math.isfinite(gp) else gain)
        phase_read.append(rp if math.isfinite(rp) else read)
    return per_channel, phase_gain, phase_read


def per_group_fits(groups, cols: dict, shifts, motion_term: bool) -> list[dict]:
    """Each group's own fit (where it has 3 bins or more), its shifts and pixel counts."""
    per_group = []
    for i, gr in enumerate(groups):
        m = cols["group"] == i
        entry = {"label": gr.label, "exposures_ms": [float(t) for t in gr.exposures_ms],
                 "shift_px": [[2 * a, 2 * b_] for a, b_ in shifts[i]], "n_bins": int(np.count_nonzero(m)),
                 "n_pixels": int(cols["n"][m].sum())}
        if np.count_nonzero(m) >= 3:
            a_i, b_i, c_i, _ = fit_bins(cols, m, motion_term=motion_term)
            gi, ri, sgi, sri = gain_read(a_i, b_i, c_i)
            entry.update(gain_e_per_h=gi, read_noise_e=ri, gain_std=sgi, read_noise_std=sri)
        per_group.append(entry)
    return per_group
