"""Which image of a static stack has a wrong exposure time (a mislabelled line of times.txt).

After the fit of :func:`emulator.calibration.stack_engel2016.fit_inverse_response`, each
image's exposure factor is measured against the other images (:func:`exposure_scales`:
median of ``log(U(I) / (t B))`` with B from the others); the most deviating ones are
confirmed by a fit without them (:func:`outlier_image`).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["OUTLIER_MIN_G", "exposure_scales", "outlier_image"]

#: The exposure check of each image uses samples with U(I) at least this fraction of
#: U(table_top): the dark end, where U is least determined, is left out.
OUTLIER_MIN_G = 0.001


def exposure_scales(table: np.ndarray, d_flat, pix_idx, img_idx, t_flat, w, n_img: int, n_pix: int, *,
                     min_g: float, min_samples: int = 50) -> np.ndarray:
    """Per image, the factor its exposure time is off by: ``exp(median log(U(I) / (t B)))``.

    B of each sample's pixel is estimated from the *other* images only (its own sample
    removed from the closed-form ratio), so a wrong image does not pull it.  Samples with
    U(I) below ``min_g`` (the dark end, where U is least determined) are left out; NaN for
    an image with fewer than ``min_samples`` usable samples.
    """
    u = table[d_flat]
    num = np.bincount(pix_idx, w * t_flat * u, n_pix)
    den = np.bincount(pix_idx, w * t_flat * t_flat, n_pix)
    num_o = num[pix_idx] - w * t_flat * u
    den_o = den[pix_idx] - w * t_flat * t_flat
    ok = (den_o > 1e-12 * den[pix_idx]) & (u >= min_g)
    b = np.where(ok, num_o / np.where(ok, den_o, 1.0), 0.0)
    ok &= b > 0
    log_s = np.full(d_flat.size, np.nan)
    log_s[ok] = np.log(u[ok] / (t_flat[ok] * b[ok]))
    out = np.full(n_img, np.nan)
    order = np.argsort(img_idx, kind="stable")
    starts = np.searchsorted(img_idx[order], np.arange(n_img + 1))
    for i in range(n_img):
        v = log_s[order[starts[i]: starts[i + 1]]]
        v = v[np.isfinite(v)]
        if v.size >= min_samples:
            out[i] = math.exp(float(np.median(v)))
    return out


def outlier_image(solve, finish, d_flat, pix_idx, img_idx, t_flat, n_img: int, n_pix: int, scales, rms: float, *,
                   tol: float, min_g: float, max_candidates: int = 3) -> tuple[int, float] | None:
    """The image whose exposure time does not fit the others, or None.

    Candidates: the (at most ``max_candidates``) images whose scale deviates from the
    median by more than ``tol`` (log).  The fit is repeated without each; a candidate
    qualifies when that fit's residual is below 0.8 of ``rms`` (the full fit's) and,
    against it, the candidate's own scale is off by more than ``tol`` while every other
    image's is within half of that.  Of those, the one whose removal leaves the smallest
    residual.  Returns (image index, factor its exposure time is off by).
    """
    log_s = np.log(scales)
    dev = np.abs(log_s - np.nanmedian(log_s))
    dev[~np.isfinite(dev)] = -1.0
    best = None
    for k in np.argsort(-dev)[:max_candidates]:
        if dev[k] <= tol:
            break
        keep = img_idx != k
        c, w, _, _, _ = solve(d_flat[keep], pix_idx[keep], t_flat[keep])
        resp = finish(c)
        u = resp.g[d_flat[keep]]
        b = np.bincount(pix_idx[keep], w * t_flat[keep] * u, n_pix) / np.maximum(
            np.bincount(pix_idx[keep], w * t_flat[keep] ** 2, n_pix), 1e-300)
        r = d_flat[keep] - resp.forward(t_flat[keep] * b[pix_idx[keep]])
        rms_k = float(np.sqrt(np.mean(r * r)))
        if not rms_k < 0.8 * rms:
            continue
        w_all = np.zeros(d_flat.size)  # B from the refit's images only, for the candidate too
        w_all[keep] = w
        refit = exposure_scales(resp.g, d_flat, pix_idx, img_idx, t_flat, w_all, n_img, n_pix, min_g=min_g)
        own = abs(math.log(refit[k])) if math.isfinite(refit[k]) else 0.0
        others = np.abs(np.log(np.delete(refit, k)))
        others = others[np.isfinite(others)]
        if own > tol and (others.size == 0 or float(others.max()) <= 0.5 * own):
            if best is None or rms_k < best[2]:
                best = (int(k), float(refit[k]), rms_k)
    return None if best is None else best[:2]
