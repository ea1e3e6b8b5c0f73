"""Inverse response in situ, from a bracketed recording's own sweeps (no static scene needed).

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
"""

from __future__ import annotations

import math
from typing import Sequence as SequenceType

import numpy as np

from emulator.calibration.result import (
    CalibrationResult,
    Progress,
    origin_warnings,
    planes_of,
    sweep_neighbours,
    table_top_for,
)
from emulator.calibration.solver import Knots, blas_single_thread, comparametric_irls, finish_response, robust_scale
from emulator.errors import CalibrationError
from emulator.core.levels import BOREALHDR_LEVELS
from emulator.core.dataset import Sequence
from emulator.io.borealhdr import load_sequence

__all__ = ["comparagram_pairs", "fit_comparametric", "calibrate_from_recording"]


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
    out: list[dict] = []
    for cyc, cam, a, b, planes_a, planes_b in sweep_neighbours(
            sequence, cams, max_ratio, lambda raw: [_dithered_sorted(p, gen) for p in planes_of(raw, stride)],
            progress, "comparagram"):
        da_all, db_all = [], []
        for pa, pb in zip(planes_a, planes_b):
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
    return out


def fit_comparametric(
    pairs: list[dict],
    *,
    white_level: int = BOREALHDR_LEVELS.white,
    black_level: int = BOREALHDR_LEVELS.black,
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
    knots = Knots(n_knots, top)
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
    with blas_single_thread():
        c = comparametric_irls(a_mat, b_mat, d_lo, ratio, knots, presence, smoothness, huber_k, n_iter)
    resp, g = finish_response(c, knots, presence, f"comparametric:{source}", black)
    pred = resp.forward(ratio * resp.inverse(d_lo))
    r = d_hi - pred
    rms = float(np.sqrt(np.mean(r * r)))
    observed = (int(math.floor(min(d_lo.min(), d_hi.min()))), int(math.ceil(max(d_lo.max(), d_hi.max()))))
    info = {
        "warnings": origin_warnings(resp, black, source),
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
        residual_robust_dn=robust_scale(r),
        residual_rms_percent=100.0 * rms / (white - black),
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

    ``sequence`` is a path or an :class:`emulator.core.dataset.Sequence`.  Images are read
    every ``stride``-th pixel of each Bayer plane.  See :func:`comparagram_pairs` and
    :func:`fit_comparametric`.
    """
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
