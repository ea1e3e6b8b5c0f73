"""Calibration study inputs and measures: radiance, exposure stacks, OpenCV curves, curve errors, the emulation check."""

from __future__ import annotations

import math
import time

import numpy as np

from emulator.calibration import response_error
from emulator.io.pcalib import PCALIB_TABLE_TOP
from emulator.core.response import CameraResponse
from validation.calibration_study.config import BRACKETS_MS, DN_RANGE
from validation.common import static_radiance

__all__ = ["study_radiance", "electrons_per_ms", "stack_exposures", "capture_stack", "opencv_curves", "codes_to_dn_curve", "curve_error", "code_curve_error", "emulation_check", "capture_image"]


# ---------------------------------------------------------------------------- inputs
def study_radiance(width: int, height: int, spp: int, source: str, cache_dir=None) -> tuple[np.ndarray, str]:
    """static_lab radiance (Mitsuba), or the procedural synth chart when asked or when Mitsuba fails."""
    if source == "static_lab":
        try:
            return static_radiance("static_lab", width=width, height=height, spp=spp, cache_dir=cache_dir), \
                f"static_lab (Mitsuba render {width}x{height}, {spp} spp)"
        except Exception as exc:  # noqa: BLE001 - fall back, and say so in the results
            reason = f"{type(exc).__name__}: {exc}"
    else:
        reason = "asked for"
    from synth.procedural import hdr_chart

    return hdr_chart(width, height, seed=0, dynamic_range_db=60.0), \
        f"synth.procedural.hdr_chart {width}x{height}, 60 dB ({reason})"


def electrons_per_ms(radiance: np.ndarray, camera) -> np.ndarray:
    """Mean electrons per site at 1 ms (vignetting and sensitivities included)."""
    from synth.imaging import mean_electrons

    return mean_electrons(radiance, 1.0, camera)


def stack_exposures(e1: np.ndarray, camera, n: int, *, low_dn: int = 8, jitter: float = 0.4, seed: int = 0):
    """n exposure times (ms): brightest site at ~low_dn DN ... darkest 0.5 % of lit sites saturated."""
    g = camera.response.g
    lit = e1[e1 > 0]
    rel = (g[low_dn] - g[camera.black_level]) / (g[camera.white_level] - g[camera.black_level])
    t_lo = max(rel, 1e-12) * camera.full_well_e / float(lit.max())
    t_hi = 1.5 * camera.full_well_e / float(np.percentile(lit, 0.5))
    t = np.geomspace(t_lo, t_hi, n)
    if jitter:
        step = math.log(t[1] / t[0])
        t = t * np.exp(np.random.default_rng(seed).uniform(-jitter, jitter, n) * step)
    return t


def capture_image(radiance, exposure_ms, camera, *, seed, noise=True) -> np.ndarray:
    """synth's forward model (:func:`synth.imaging.capture`)."""
    from synth.imaging import capture

    return capture(radiance, float(exposure_ms), camera, seed=seed, noise=noise)


def capture_stack(radiance, camera, exposures_ms, *, seed: int, noise: bool = True) -> np.ndarray:
    return np.stack([capture_image(radiance, t, camera, seed=seed + i, noise=noise) for i, t in enumerate(exposures_ms)])


# ---------------------------------------------------------------------------- OpenCV
def opencv_curves(images: np.ndarray, exposures_ms: np.ndarray) -> dict[str, np.ndarray]:
    """Debevec and Robertson inverse responses (256 codes) of the stack converted to 8 bits (DN >> 4)."""
    import cv2

    imgs8 = [cv2.merge([(im >> 4).astype(np.uint8)] * 3) for im in images]
    times = (np.asarray(exposures_ms, dtype=np.float64) / 1000.0).astype(np.float32)
    out = {}
    for name, maker in (("debevec", cv2.createCalibrateDebevec), ("robertson", cv2.createCalibrateRobertson)):
        t0 = time.perf_counter()
        crf = maker().process(imgs8, times)
        out[name] = (np.asarray(crf, dtype=np.float64)[:, 0, 1], time.perf_counter() - t0)
    return out


def codes_to_dn_curve(values: np.ndarray, table_top: int = PCALIB_TABLE_TOP) -> np.ndarray:
    """A 256-code curve at the DN centres 16 v + 7.5 of codes 1..254, interpolated over 0..table_top (plots)."""
    v = np.arange(1, 255)
    return np.interp(np.arange(table_top + 1, dtype=np.float64), 16.0 * v + 7.5, np.asarray(values, float)[v])


def curve_error(g: np.ndarray, truth: CameraResponse) -> dict:
    """Scale-aligned error of any g table (over DN) against the truth, DN 16..4079."""
    e = response_error(g, truth, dn_range=DN_RANGE, align="scale")
    return {"max_pct": e["max_pct"], "rms_pct": e["rms_pct"]}


def code_curve_error(values: np.ndarray, truth: CameraResponse) -> dict:
    """Scale-aligned error of a 256-code (8-bit) curve at the codes whose DN bin lies in 16..4079.

    Code v stands for DN 16 v .. 16 v + 15 and is compared with the truth at the bin centre
    16 v + 7.5 (codes 1..254; code 255 holds every saturated pixel and 0 the black ones).
    """
    v = np.arange(1, 255)
    gt = truth.inverse(16.0 * v + 7.5) * (255.0 / truth.g[-1])
    g = np.asarray(values, dtype=np.float64)[v]
    s = float(np.dot(g, gt) / np.dot(g, g))
    err = (g * s - gt) / (255.0 - truth.g[0] * 255.0 / truth.g[-1]) * 100
    return {"max_pct": float(np.max(np.abs(err))), "rms_pct": float(np.sqrt(np.mean(err**2)))}


# ---------------------------------------------------------------------------- emulation check
def emulation_check(radiance, camera, e1, recovered: CameraResponse, *, seed: int) -> dict:
    """Emulate between-bracket targets from both bounding brackets with the true and the recovered response.

    Brackets are the 1..32 ratio set placed so that the longest saturates ~3 % of the sites;
    targets sit halfway (x sqrt 2) between brackets; ground truth is the noiseless capture.
    RMSE (DN) over the validity mask; ``ratio`` is RMSE(recovered) / RMSE(true).
    """
    from emulator.core.emulate import emulate

    true = camera.response
    rec = recovered.with_levels(white_level=camera.white_level, black_level=camera.black_level)
    # control: the true curve through the pcalib format (256 samples, linear in between)
    top = recovered.white_level
    knots = np.linspace(0.0, top, 256)
    full_truth = np.interp(knots, np.arange(true.g.size), true.g, right=np.nan)
    if np.isnan(full_truth[-1]):  # table ends at the white level: extend its last step
        full_truth[-1] = true.g[-1] + (true.g[-1] - true.g[-2]) * (top - (true.g.size - 1))
    fmt = CameraResponse.from_samples(full_truth, top).with_levels(white_level=camera.white_level,
                                                                    black_level=camera.black_level)
    t_long = camera.full_well_e / float(np.percentile(e1[e1 > 0], 97))
    brackets = [t_long / 32.0 * b for b in BRACKETS_MS]
    shots = {b: capture_image(radiance, b, camera, seed=seed + i, noise=True) for i, b in enumerate(brackets)}
    span = camera.white_level - camera.black_level
    rows = []
    for lo, hi in zip(brackets[:-1], brackets[1:]):
        target = math.sqrt(lo * hi)
        gt = capture_image(radiance, target, camera, seed=None, noise=False).astype(np.float64)
        for src in (lo, hi):
            em_t, mask = emulate(shots[src], src, target, true, return_mask=True)
            em_r = emulate(shots[src], src, target, rec)
            em_f = emulate(shots[src], src, target, fmt)
            if not mask.any():
                continue
            r_t = float(np.sqrt(np.mean((em_t[mask] - gt[mask]) ** 2)))
            r_r = float(np.sqrt(np.mean((em_r[mask] - gt[mask]) ** 2)))
            r_f = float(np.sqrt(np.mean((em_f[mask] - gt[mask]) ** 2)))
            d = float(np.sqrt(np.mean((em_r[mask].astype(float) - em_t[mask]) ** 2)))
            rows.append({"source_ms": src, "target_ms": target, "rmse_true_pct": 100 * r_t / span,
                         "rmse_true_pcalib_format_pct": 100 * r_f / span,
                         "rmse_recovered_pct": 100 * r_r / span, "ratio": r_r / r_t, "ratio_format": r_f / r_t,
                         "ratio_to_format": r_r / r_f, "recovered_vs_true_emulation_pct": 100 * d / span})
    ratios = np.array([r["ratio"] for r in rows])
    return {
        "pairs": rows,
        "max_abs_ratio_minus_1": float(np.max(np.abs(ratios - 1))),
        "max_abs_format_ratio_minus_1": float(np.max(np.abs(np.array([r["ratio_format"] for r in rows]) - 1))),
        "max_abs_ratio_to_format_minus_1": float(np.max(np.abs(np.array([r["ratio_to_format"] for r in rows]) - 1))),
        "median_ratio": float(np.median(ratios)),
        "max_rmse_true_pct": float(max(r["rmse_true_pct"] for r in rows)),
        "max_recovered_vs_true_emulation_pct": float(max(r["recovered_vs_true_emulation_pct"] for r in rows)),
    }
