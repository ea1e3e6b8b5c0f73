"""Inverse response from a static stack of images at several exposure times.

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
* One image whose exposure time is wrong (a mislabelled line of times.txt) bends the
  whole fit.  Each image's exposure factor is measured against the others (median of
  ``log(U(I) / (t B))``, B from the other images); an image off by more than 5 % is
  confirmed by a fit without it and named in the warnings, with the exposure time its
  pixels fit.  Measured on 12-image synthetic stacks with one exposure off by 0.5x to 2x
  (4 responses x 5 mislabels): 15 of 20 found, each with its true exposure within 1 %,
  never a wrong image; missed: large errors that bend a gamma-2.2 fit beyond repair, and
  10 % errors within the noise.  No false alarm on 108 clean stacks (6-20 images, 4
  responses, 3 noise levels).
"""

from __future__ import annotations

import math
import os
from typing import Sequence as SequenceType

import numpy as np

from emulator.calibration.exposure_check import OUTLIER_MIN_G, exposure_scales, outlier_image
from emulator.calibration.result import (
    CalibrationResult,
    Progress,
    origin_warnings,
    report_progress,
)
from emulator.calibration.solver import Knots, blas_single_thread, finish_response, robust_scale, solve_als, solve_varpro
from emulator.calibration.stack_checks import check_stack, estimate_noise_dn, stack_warnings
from emulator.errors import CalibrationError
from emulator.io.pcalib import PCALIB_SAMPLES
from emulator.io.stack import Stack, read_stack
from emulator.core.levels import BOREALHDR_LEVELS

__all__ = ["estimate_noise_dn", "fit_inverse_response", "calibrate_stack"]


def _flat_samples(dn: np.ndarray, valid: np.ndarray, ts: np.ndarray):
    """The unclipped samples in pixel-major order (chunks of pixels are contiguous): ``(DN, pixel index,
    image index, relative exposure)``, one entry per sample."""
    n_img, n_pix = dn.shape
    d_flat = dn.T[valid.T]
    pix_idx = np.broadcast_to(np.arange(n_pix)[:, None], (n_pix, n_img))[valid.T]
    img_idx = np.broadcast_to(np.arange(n_img)[None, :], (n_pix, n_img))[valid.T]
    return d_flat, pix_idx, img_idx, ts[img_idx]


def _run_solver(solver: str, knots, d_flat, pix_idx, t_flat, n_pix, *, smoothness, huber_k, max_iter, tol, progress,
                init):
    """The knots of U fitted by ``solver`` (``"varpro"`` or ``"als"``) on one BLAS thread:
    ``(knots, sample weights, knot weights, iterations, converged)``."""
    with blas_single_thread():
        return (solve_varpro if solver == "varpro" else solve_als)(
            knots, d_flat, pix_idx, t_flat, n_pix, smoothness=smoothness, huber_k=huber_k,
            max_iter=max_iter, tol=tol, progress=progress, c0=init,
        )


def _fit_residuals(resp, d_flat, pix_idx, t_flat, w, n_pix):
    """The final residual in DN with the finished response (B refitted per pixel) and the predicted
    exposures ``g`` of the samples: ``(residual, g)``."""
    u = resp.g[d_flat]
    num = np.bincount(pix_idx, w * t_flat * u, n_pix)
    den = np.bincount(pix_idx, w * t_flat * t_flat, n_pix)
    b = num / np.maximum(den, 1e-300)
    pred_g = t_flat * b[pix_idx]
    return d_flat - resp.forward(pred_g), pred_g


def _checked_solver(solver: str, max_iter: int | None) -> int:
    """``max_iter`` or the solver's default (10 reweightings for varpro, 500 alternations for als)."""
    if solver not in ("varpro", "als"):
        raise ValueError(f"solver must be 'varpro' or 'als', got {solver!r}")
    if max_iter is None:
        max_iter = 10 if solver == "varpro" else 500
    return max_iter


def _solver_info(solver, iterations, converged, knots, margin_dn, smoothness, huber_k) -> dict:
    """How the fit was made, as ``info`` records it."""
    return {
        "solver": solver,
        "iterations": int(iterations),
        "converged": bool(converged),
        "n_knots": int(knots.n),
        "margin_dn": int(margin_dn),
        "smoothness": float(smoothness),
        "huber_k": float(huber_k),
    }


def _per_image_info(n_valid_img, per_image_rms, scales, outliers) -> dict:
    """Each image's unclipped samples, residual and exposure factor, and the outlier, as ``info`` records them."""
    return {
        "unclipped_samples_per_image": [int(v) for v in n_valid_img],
        "residual_rms_dn_per_image": [None if not math.isfinite(v) else float(v) for v in per_image_rms],
        "exposure_scale_per_image": [None if not math.isfinite(v) else float(v) for v in scales],
        "outlier_images": outliers,
    }


def _per_image_rms(img_idx: np.ndarray, r: np.ndarray, n_img: int) -> np.ndarray:
    """RMS of the residuals ``r`` of each image (NaN for an image without samples)."""
    count = np.bincount(img_idx, minlength=n_img)
    per_image_rms = np.sqrt(np.bincount(img_idx, r * r, n_img) / np.maximum(count, 1))
    per_image_rms[count == 0] = np.nan
    return per_image_rms


def _outliers(knots, solver, d_flat, pix_idx, img_idx, t_flat, t, n_img, n_pix, scales, rms, per_image_rms, table, *,
              black, smoothness, huber_k, max_iter, tol, init, outlier_tol, image_names) -> list[dict]:
    """The image whose exposure time its pixels do not fit (refit without it), as :func:`fit_inverse_response`
    records it in ``info["outlier_images"]`` (at most one)."""
    outliers: list[dict] = []

    def solve(d_sub, pix_sub, t_sub):
        return _run_solver(solver, knots, d_sub, pix_sub, t_sub, n_pix, smoothness=smoothness, huber_k=huber_k,
                           max_iter=max_iter, tol=tol, progress=None, init=init)

    def finish(c_sub):
        return finish_response(c_sub, knots, np.ones(knots.n), "refit", black)[0]

    found = outlier_image(solve, finish, d_flat, pix_idx, img_idx, t_flat, n_img, n_pix, scales, rms,
                           tol=float(outlier_tol), min_g=OUTLIER_MIN_G * float(table[-1]))
    if found is not None:
        k, factor = found
        name = image_names[k] if image_names is not None else f"image {k}"
        fitted = float(t[k] * factor)
        outliers.append({
            "index": k,
            "name": str(name),
            "exposure_ms": float(t[k]),
            "fitted_exposure_ms": fitted,
            "residual_rms_dn": float(per_image_rms[k]),
            "median_residual_rms_dn": float(np.nanmedian(per_image_rms)),
            "warning": (
                f"{name}: its exposure time {t[k]:g} ms does not fit the other images: its pixels fit "
                f"{fitted:.4g} ms ({100 * (factor - 1):+.0f} %; residual {per_image_rms[k]:.3g} DN RMS against a "
                f"median of {np.nanmedian(per_image_rms):.3g} DN over the images). Check its exposure line "
                f"(times.txt) or remove the image, then calibrate again"
            ),
        })
    return outliers


def fit_inverse_response(
    dn: np.ndarray,
    exposures_ms: SequenceType[float],
    *,
    white_level: int = BOREALHDR_LEVELS.white,
    black_level: int = BOREALHDR_LEVELS.black,
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
    image_names: SequenceType[str] | None = None,
    outlier_tol: float = 0.05,
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
    image_names : sequence of str, optional
        One name per image (file names), used in the outlier warnings; default
        ``image <i> (<t> ms)``.
    outlier_tol : float
        After the fit, the exposure factor each image's pixels fit is measured against
        the other images (median of ``log(U(I) / (t B))``, B from the others).  When one
        deviates by more than ``outlier_tol`` (log; 0.05 is about 5 %), the fit is repeated
        without it; if it still deviates by more than ``outlier_tol`` while the others
        agree, its exposure time is wrong (a mislabelled line in times.txt): it is named
        in ``info["warnings"]`` and ``info["outlier_images"]`` with the exposure time its
        pixels fit.  ``None`` skips the check.

    Returns
    -------
    CalibrationResult
    """
    dn, valid, t, distinct, n_valid_img, lo, hi, top = check_stack(dn, exposures_ms, white_level, black_level,
                                                                       margin_dn, source)
    white, black = int(white_level), int(black_level)
    n_img, n_pix = dn.shape
    ts = t / t.max()

    knots = Knots(n_knots, top)
    d_flat, pix_idx, img_idx, t_flat = _flat_samples(dn, valid, ts)
    max_iter = _checked_solver(solver, max_iter)
    c, w, w_knot, it, converged = _run_solver(solver, knots, d_flat, pix_idx, t_flat, n_pix, smoothness=smoothness,
                                              huber_k=huber_k, max_iter=max_iter, tol=tol, progress=progress,
                                              init=init)

    resp, g = finish_response(c, knots, w_knot, f"calibrated:{source}", black)
    table = resp.g
    r, pred_g = _fit_residuals(resp, d_flat, pix_idx, t_flat, w, n_pix)
    rms = float(np.sqrt(np.mean(r * r)))
    robust = robust_scale(r)
    pick = np.random.default_rng(rng).choice(d_flat.size, size=min(n_plot_samples, d_flat.size), replace=False)
    observed = (int(d_flat.min()), int(d_flat.max()))
    warnings = stack_warnings(t, observed, lo, hi)
    per_image_rms = _per_image_rms(img_idx, r, n_img)
    scales = exposure_scales(table, d_flat, pix_idx, img_idx, t_flat, w, n_img, n_pix,
                              min_g=OUTLIER_MIN_G * float(table[-1]))
    outliers = [] if outlier_tol is None else _outliers(
        knots, solver, d_flat, pix_idx, img_idx, t_flat, t, n_img, n_pix, scales, rms, per_image_rms, table,
        black=black, smoothness=smoothness, huber_k=huber_k, max_iter=max_iter, tol=tol, init=init,
        outlier_tol=outlier_tol, image_names=image_names)
    warnings.extend(o["warning"] for o in outliers)
    warnings.extend(origin_warnings(resp, black, source))
    info = {
        "warnings": warnings,
        "n_images": int(n_img),
        "n_exposures": int(distinct.size),
        "exposures_ms": [float(e) for e in t],
        "n_pixels": int(n_pix),
        "n_samples": int(d_flat.size),
        "clipped_fraction": float(1 - valid.mean()),
        **_solver_info(solver, it, converged, knots, margin_dn, smoothness, huber_k),
        **_per_image_info(n_valid_img, per_image_rms, scales, outliers),
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
        residual_rms_percent=100.0 * rms / (white - black),
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
    static_floor_percent: float = 1.0,
    check_static: bool = True,
    rng: np.random.Generator | int | None = 0,
    progress: Progress = None,
    static_floor_pct: float | None = None,
    **fit_kwargs,
) -> CalibrationResult:
    """Recover the inverse response from a static-scene stack (TUM layout) by ALS.

    Reads the images one by one, keeps ``max_pixels`` random pixel positions (the same in
    every image), estimates the noise of each image, and calls
    :func:`fit_inverse_response` (``fit_kwargs`` go there).

    Raises :class:`CalibrationError` naming the stack for fewer than two distinct
    exposures, images of mixed sizes, a stack whose pixels are all clipped, and a scene that
    is not static: the RMS fit residual exceeds ``max(static_factor * noise,
    static_floor_percent % of the range)`` (disable with ``check_static=False``).
    ``static_floor_pct`` is a deprecated alias of ``static_floor_percent``.
    """
    if static_floor_pct is not None:
        static_floor_percent = float(static_floor_pct)
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
        report_progress(progress, i + 1, total, f"reading {st.names[i]}")
    dn = np.stack(samples)
    result = fit_inverse_response(
        dn,
        st.exposures_ms,
        white_level=st.white_level,
        black_level=st.black_level,
        rng=gen,
        progress=progress,
        source=src,
        image_names=[str(st.image_path(i)) for i in range(total)],
        **fit_kwargs,
    )
    noise_arr = np.asarray(noise)
    noise_dn = float(np.nanmedian(noise_arr)) if np.isfinite(noise_arr).any() else float("nan")
    result.noise_dn = noise_dn
    span = st.white_level - st.black_level
    limit = max(static_factor * (noise_dn if math.isfinite(noise_dn) else 0.0), static_floor_percent / 100 * span)
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
            f"noise, {static_floor_percent:g} % of range)); did the camera or the scene move?"
            + "".join(f"; {o['warning']}" for o in result.info["outlier_images"])
        )
    return result
