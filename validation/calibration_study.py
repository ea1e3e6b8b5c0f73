"""Validation of the inverse-response calibration: synthetic stacks, OpenCV, in situ, real sample.

Run from the repository root::

    python -m validation.calibration_study OUT [--quick] [--force]

Writes ``OUT/results.json`` (every figure, the settings and versions), ``OUT/report.md``
(the tables), ``OUT/*.png`` (plots) and ``OUT/curves.npz`` (the arrays behind them).

Parts:

1. **Static stacks** through each synthetic camera preset (``synth.Camera.preset``:
   borealhdr, linear, gamma22, s_curve), with shot and read noise, rendered from the
   ``static_lab`` Mitsuba scene (or, without Mitsuba, the procedural ``synth`` HDR chart;
   results.json says which).  Exposure times are log-spaced from "brightest pixel near
   DN 8" to "darkest 0.5 % of the lit pixels saturated", jittered off the geometric
   progression (+-0.4 of a step).  Recovery error of f^-1 over DN 16..4079, in % of the
   range; emulation with the recovered vs the true response.
2. **OpenCV** Debevec and Robertson calibrations on the same stacks.  They need 8-bit
   images: ``DN >> 4`` (12 -> 8 bit), the mono mosaic replicated to 3 channels, times in
   seconds.  Their curves (256 codes) are placed at the DN centres ``16 v + 7.5`` and
   interpolated; our method on the same 8-bit images is listed too.  Every curve is
   scale-aligned to the truth before the error is taken (f^-1 is defined up to scale).
3. **BorealHDR**: the response recovered from the borealhdr-preset stack against the
   real table ``pcalib_inside1.txt`` (the preset is a parametric fit of that table).
4. **In situ** on synthetic moving recordings (``synth.procedural.TranslatingChart``,
   walking speed, 1..32 ms sweeps) with each preset: recovered vs true f^-1 and the
   cross-bracket scores of the recovered, the true and a linear response.
5. **Real sample**: cross-bracket error (emulate each bracket from its sweep neighbours,
   compare 1..99 % quantiles, RMSE in % of 4094) of pcalib_inside1, a linear response and
   the in-situ responses (both cameras, and each camera scored on the other).
"""

from __future__ import annotations

import argparse
import math
import shlex
import sys
import time
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from emulator.calibration import (  # noqa: E402
    CalibrationResult,
    calibrate_from_recording,
    calibrate_stack,
    cross_bracket_error,
    fit_inverse_response,
    response_error,
)
from emulator.io.files import save_figure  # noqa: E402
from emulator.report.figures import subplots  # noqa: E402
from emulator.io.pcalib import PCALIB_TABLE_TOP, read_response  # noqa: E402
from emulator.io.stack import write_stack  # noqa: E402
from emulator.response import CameraResponse  # noqa: E402
from emulator.report.html import write_report

__all__ = ["run_study", "main", "opencv_curves", "codes_to_dn_curve", "stack_exposures"]

PRESETS = ("borealhdr", "linear", "gamma22", "s_curve")
DN_RANGE = (16, 4079)
#: Full and quick configurations.
CONFIGS = {
    "full": {"width": 320, "height": 200, "n_exposures": 40, "spp": 16, "max_pixels": 65536,
             "insitu_width": 320, "insitu_height": 200, "insitu_sweeps": 12, "geometric_control": True,
             "als_control": True, "real_sample": True},
    "quick": {"width": 160, "height": 100, "n_exposures": 16, "spp": 4, "max_pixels": 16000,
              "insitu_width": 160, "insitu_height": 100, "insitu_sweeps": 4, "geometric_control": False,
              "als_control": False, "real_sample": True},
}
SHOT_INTERVAL_S = 1.0 / 22.0
BRACKETS_MS = (1.0, 2.0, 4.0, 8.0, 16.0, 32.0)


# ---------------------------------------------------------------------------- inputs
def study_radiance(width: int, height: int, spp: int, source: str, cache_dir=None) -> tuple[np.ndarray, str]:
    """static_lab radiance (Mitsuba), or the procedural synth chart when asked or when Mitsuba fails."""
    if source == "static_lab":
        try:
            from validation.common import static_radiance

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


def _capture(radiance, exposure_ms, camera, *, seed, noise=True) -> np.ndarray:
    """synth's forward model (:func:`synth.imaging.capture`)."""
    from synth.imaging import capture

    return capture(radiance, float(exposure_ms), camera, seed=seed, noise=noise)


def capture_stack(radiance, camera, exposures_ms, *, seed: int, noise: bool = True) -> np.ndarray:
    return np.stack([_capture(radiance, t, camera, seed=seed + i, noise=noise) for i, t in enumerate(exposures_ms)])


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
    from emulator.emulate import emulate

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
    shots = {b: _capture(radiance, b, camera, seed=seed + i, noise=True) for i, b in enumerate(brackets)}
    span = camera.white_level - camera.black_level
    rows = []
    for lo, hi in zip(brackets[:-1], brackets[1:]):
        target = math.sqrt(lo * hi)
        gt = _capture(radiance, target, camera, seed=None, noise=False).astype(np.float64)
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


# ---------------------------------------------------------------------------- part 1-3: stacks
def static_part(cfg: dict, radiance: np.ndarray, out: Path, progress) -> tuple[dict, dict]:
    from validation.common import make_camera

    h, w = radiance.shape[:2]
    results, arrays = {}, {}
    for k, preset in enumerate(PRESETS):
        camera = make_camera(preset, width=w, height=h)
        truth = camera.response
        e1 = electrons_per_ms(radiance, camera)
        t = stack_exposures(e1, camera, cfg["n_exposures"], seed=k)
        images = capture_stack(radiance, camera, t, seed=1000 * (k + 1))
        stack_dir = write_stack(out / "stacks" / preset, images, t, white_level=camera.white_level,
                                black_level=camera.black_level, overwrite=True)
        rows = {}
        t0 = time.perf_counter()
        ours = calibrate_stack(stack_dir, max_pixels=cfg["max_pixels"], rng=k)
        dt = time.perf_counter() - t0
        e_top = response_error(ours.response, truth, dn_range=DN_RANGE, align="top")
        e_scale = response_error(ours.response, truth, dn_range=DN_RANGE, align="scale")
        rows["ours_12bit"] = {"max_pct": e_scale["max_pct"], "rms_pct": e_scale["rms_pct"],
                              "max_pct_as_written": e_top["max_pct"], "rms_pct_as_written": e_top["rms_pct"],
                              "max_dn_equiv": e_scale["max_dn_equiv"], "seconds": dt}
        centres = ours.response.inverse(16.0 * np.arange(256) + 7.5)  # same yardstick as the 8-bit rows
        rows["ours_12bit_at_8bit_bin_centres"] = code_curve_error(centres, truth)
        fit = _fit_summary(ours)
        arrays[f"{preset}_truth"] = truth.g * (255.0 / truth.g[-1])
        arrays[f"{preset}_ours"] = ours.response.g
        # OpenCV at 8 bits, and ours on the same 8-bit images
        for name, (curve, secs) in opencv_curves(images, t).items():
            rows[f"opencv_{name}_8bit"] = {**code_curve_error(curve, truth), "seconds": secs}
            arrays[f"{preset}_{name}"] = codes_to_dn_curve(curve)
        d8 = (images >> 4).astype(np.uint16).reshape(len(t), -1)[:, : cfg["max_pixels"]]
        t0 = time.perf_counter()
        ours8 = fit_inverse_response(d8, t, white_level=255, margin_dn=1, n_knots=256)
        rows["ours_8bit"] = {**code_curve_error(ours8.response.g, truth), "seconds": time.perf_counter() - t0}
        arrays[f"{preset}_ours8"] = codes_to_dn_curve(ours8.response.g)
        if cfg["geometric_control"]:
            tg = stack_exposures(e1, camera, cfg["n_exposures"], seed=k, jitter=0.0)
            imgs_g = capture_stack(radiance, camera, tg, seed=2000 * (k + 1))
            rg = fit_inverse_response(imgs_g.reshape(len(tg), -1)[:, : cfg["max_pixels"]], tg,
                                      white_level=camera.white_level, black_level=camera.black_level)
            rows["ours_12bit_geometric_exposures"] = curve_error(rg.response.g, truth)
        if cfg["als_control"] and preset == "borealhdr":
            d = images.reshape(len(t), -1)[:, : cfg["max_pixels"]]
            t0 = time.perf_counter()
            ra = fit_inverse_response(d, t, white_level=camera.white_level, black_level=camera.black_level,
                                      solver="als", max_iter=500)
            rows["ours_12bit_als_500_iterations"] = {**curve_error(ra.response.g, truth),
                                                     "seconds": time.perf_counter() - t0}
        results[preset] = {
            "camera": {"preset": preset, "white_level": camera.white_level, "black_level": camera.black_level,
                       "full_well_e": camera.full_well_e, "read_noise_e": camera.read_noise_e,
                       "vignetting_strength": camera.vignetting_strength, "width": w, "height": h},
            "exposures_ms": t.tolist(),
            "exposure_span_decades": float(math.log10(t.max() / t.min())),
            "fit": fit,
            "errors": rows,
            "emulation": emulation_check(radiance, camera, e1, ours.response, seed=3000 * (k + 1)),
        }
        if preset == "borealhdr":
            results[preset]["borealhdr_table"] = borealhdr_check(ours, truth)
        progress(f"static stack {preset}: ours max {rows['ours_12bit']['max_pct']:.3f} %")
    return results, arrays


def _fit_summary(r: CalibrationResult) -> dict:
    i = r.info
    return {"observed_dn": list(r.observed_dn), "residual_rms_dn": r.residual_rms_dn,
            "residual_robust_dn": r.residual_robust_dn,
            "noise_dn": r.noise_dn if math.isfinite(r.noise_dn) else None, "n_pixels": i["n_pixels"],
            "n_samples": i["n_samples"], "iterations": i["iterations"], "converged": i["converged"],
            "warnings": i["warnings"], "static_limit_dn": i.get("static_limit_dn")}


def borealhdr_check(ours: CalibrationResult, preset_truth: CameraResponse) -> dict:
    """Recovered (borealhdr preset stack) vs the real pcalib table, against the preset's own fit error."""
    path = Path(__file__).resolve().parents[2] / "shared" / "data" / "borealhdr_sample" / "calibration" / \
        "pcalib_inside1.txt"
    if not path.is_file():
        return {"skipped": f"{path} not found"}
    table = read_response(path)
    out = {}
    for name, a, b in (("recovered_vs_table", ours.response, table), ("preset_vs_table", preset_truth, table),
                       ("recovered_vs_preset", ours.response, preset_truth)):
        out[name] = {align: {k: v for k, v in response_error(a, b, dn_range=DN_RANGE, align=align).items()
                             if k in ("max_pct", "rms_pct")} for align in ("top", "scale")}
    return out


# ---------------------------------------------------------------------------- part 4: in situ, synthetic
def insitu_synthetic(cfg: dict, out: Path, progress) -> tuple[dict, dict]:
    from synth.procedural import WALK_SPEED_M_S, TranslatingChart

    from emulator.io.borealhdr import load_sequence, write_frame
    from validation.common import make_camera

    w, h, n_sweeps = cfg["insitu_width"], cfg["insitu_height"], cfg["insitu_sweeps"]
    duration = n_sweeps * len(BRACKETS_MS) * SHOT_INTERVAL_S + 0.1
    chart = TranslatingChart(w, h, seed=7, speed_m_s=WALK_SPEED_M_S, duration_s=duration, dynamic_range_db=45.0)
    results, arrays = {}, {}
    for k, preset in enumerate(PRESETS):
        camera = make_camera(preset, width=w, height=h)
        rad0, _ = chart(0.0)
        e1 = electrons_per_ms(rad0, camera)
        scale = camera.full_well_e / (32.0 * float(np.percentile(e1, 97)))  # 32 ms saturates ~3 %
        root = out / "recordings" / preset
        ts = 0
        for shot in range(n_sweeps * len(BRACKETS_MS)):
            b = BRACKETS_MS[shot % len(BRACKETS_MS)]
            rad, _ = chart(shot * SHOT_INTERVAL_S)
            raw = _capture(rad * np.float32(scale), b, camera, seed=10_000 * (k + 1) + shot, noise=True)
            ts = int(round(shot * SHOT_INTERVAL_S * 1e9)) + 1_000_000_000
            write_frame(root, "left", b, ts, raw, overwrite=True)
        seq = load_sequence(root, white_level=camera.white_level, black_level=camera.black_level)
        t0 = time.perf_counter()
        rec = calibrate_from_recording(seq, stride=1)
        dt = time.perf_counter() - t0
        truth = camera.response
        lo, hi = rec.observed_dn
        scores = {name: cross_bracket_error(seq, r, stride=1).median_pct
                  for name, r in (("recovered", rec.response), ("true", truth),
                                  ("linear", CameraResponse.linear(camera.white_level)))}
        results[preset] = {
            "n_sweeps": n_sweeps, "size": [w, h], "shift_px_per_shot": chart.pixels_per_m * WALK_SPEED_M_S *
            SHOT_INTERVAL_S, "observed_dn": [lo, hi], "seconds": dt,
            "error_16_4079": curve_error(rec.response.g, truth),
            "error_observed": {k2: v for k2, v in response_error(rec.response, truth, dn_range=(max(lo, 16), min(
                hi, 4079)), align="scale").items() if k2 in ("max_pct", "rms_pct", "dn_range")},
            "cross_bracket_median_pct": scores,
            "residual_rms_dn": rec.residual_rms_dn,
        }
        arrays[f"insitu_{preset}_truth"] = truth.g * (255.0 / truth.g[-1])
        arrays[f"insitu_{preset}_recovered"] = rec.response.g
        progress(f"in situ {preset}: max {results[preset]['error_16_4079']['max_pct']:.2f} %")
    return results, arrays


# ---------------------------------------------------------------------------- part 5: real sample
def real_sample_part(progress) -> tuple[dict, dict]:
    from emulator.io.borealhdr import load_sequence, sequence_response

    root = Path(__file__).resolve().parents[2] / "shared" / "data" / "borealhdr_sample"
    seq_path = root / "backpack_2023-09-25-15-05-03"
    if not seq_path.is_dir():
        return {"skipped": f"{seq_path} not found"}, {}
    seq = load_sequence(seq_path)
    pcalib = sequence_response(seq)
    linear = CameraResponse.linear(seq.white_level, black_level=seq.black_level)
    fits = {}
    for name, cams in (("both", None), ("left", ("left",)), ("right", ("right",))):
        t0 = time.perf_counter()
        fits[name] = calibrate_from_recording(seq, cameras=cams)
        fits[name].info["seconds"] = time.perf_counter() - t0
    table = read_response(root / "calibration" / "pcalib_inside1.txt")
    scores = {}
    pairs = {}
    for rname, resp in (("pcalib_inside1", pcalib), ("linear", linear), ("in_situ_both", fits["both"].response),
                        ("in_situ_left", fits["left"].response), ("in_situ_right", fits["right"].response)):
        scores[rname] = {}
        for cam in ("both", "left", "right"):
            sc = cross_bracket_error(seq, resp, cameras=None if cam == "both" else (cam,))
            scores[rname][cam] = {"median_pct": sc.median_pct, "mean_pct": sc.mean_pct, "n": len(sc.pairs)}
            if cam == "both":
                pairs[rname] = sc.pairs
        progress(f"real sample: scored {rname}")
    q1000 = np.linspace(0.0, 1.0, 1000)
    variant = {rname: cross_bracket_error(seq, resp, quantiles=q1000).median_pct
               for rname, resp in (("pcalib_inside1", pcalib), ("linear", linear),
                                   ("in_situ_both", fits["both"].response))}
    shape = {name: {"16_3000": {k: v for k, v in response_error(f.response, table, dn_range=(16, 3000),
                                                                  align="scale").items() if k in ("max_pct", "rms_pct")},
                    "16_4079": {k: v for k, v in response_error(f.response, table, dn_range=DN_RANGE,
                                                                  align="scale").items() if k in ("max_pct", "rms_pct")}}
             for name, f in fits.items()}
    res = {
        "sequence": str(seq_path),
        "method": "cross_bracket_error: every consecutive bracket pair of a sweep, both directions; quantiles "
                  "1..99 %; every 4th pixel of each Bayer plane; RMSE in % of 4094 (white 4094, black 0)",
        "scores": scores,
        "median_1000_quantiles_0_to_1": variant,
        "in_situ_vs_pcalib_shape": shape,
        "in_situ_fits": {name: {"observed_dn": list(f.observed_dn), "residual_rms_dn": f.residual_rms_dn,
                                "n_pairs": f.info["n_pairs"], "seconds": f.info["seconds"]}
                         for name, f in fits.items()},
        "pairs": pairs,
    }
    arrays = {"real_pcalib": table.g, "real_in_situ_both": fits["both"].response.g,
              "real_in_situ_left": fits["left"].response.g, "real_in_situ_right": fits["right"].response.g}
    return res, arrays


# ---------------------------------------------------------------------------- report
def _plots(results: dict, arrays: dict, out: Path) -> list[str]:
    names = []
    presets = [p for p in PRESETS if f"{p}_truth" in arrays]
    if presets:
        fig, axes = subplots(2, len(presets), figsize=(4.2 * len(presets), 7), squeeze=False)
        for j, p in enumerate(presets):
            gt = arrays[f"{p}_truth"]
            dn = np.arange(gt.size)
            ax, axe = axes[0, j], axes[1, j]
            ax.plot(dn, gt, "k-", lw=2, label="true")
            for key, style, label in (("ours", "C0-", "ours 12-bit"), ("ours8", "C0:", "ours 8-bit"),
                                      ("debevec", "C1--", "Debevec 8-bit"), ("robertson", "C2-.", "Robertson 8-bit")):
                g = arrays[f"{p}_{key}"][: gt.size]
                sl = slice(DN_RANGE[0], DN_RANGE[1] + 1)
                s = float(np.dot(g[sl], gt[sl]) / np.dot(g[sl], g[sl]))
                ax.plot(dn, g * s, style, lw=1, label=label)
                axe.plot(dn[sl], (g[sl] * s - gt[sl]) / (gt[-1] - gt[0]) * 100, style, lw=1, label=label)
            ax.set_title(f"{p}: f^-1 (scale-aligned)")
            ax.set_xlabel("DN")
            ax.legend(fontsize=7)
            axe.set_title("error, % of range")
            axe.set_xlabel("DN")
            axe.set_ylim(-3, 3)
            axe.grid(alpha=0.3)
        fig.tight_layout()
        save_figure(fig, out / "static_stacks.png", dpi=100)
        names.append("static_stacks.png")
    ins = [p for p in PRESETS if f"insitu_{p}_truth" in arrays]
    if ins:
        fig, axes = subplots(1, len(ins), figsize=(4.2 * len(ins), 3.6), squeeze=False)
        for j, p in enumerate(ins):
            gt, g = arrays[f"insitu_{p}_truth"], arrays[f"insitu_{p}_recovered"][: arrays[f"insitu_{p}_truth"].size]
            sl = slice(DN_RANGE[0], DN_RANGE[1] + 1)
            s = float(np.dot(g[sl], gt[sl]) / np.dot(g[sl], g[sl]))
            axes[0, j].plot(gt, "k-", lw=2, label="true")
            axes[0, j].plot(g * s, "C3-", lw=1, label="in situ")
            axes[0, j].set_title(f"in situ, moving, {p}")
            axes[0, j].set_xlabel("DN")
            axes[0, j].legend(fontsize=8)
        fig.tight_layout()
        save_figure(fig, out / "in_situ_synthetic.png", dpi=100)
        names.append("in_situ_synthetic.png")
    real = results.get("real_sample", {})
    if "real_pcalib" in arrays:
        fig, (ax, axb) = subplots(1, 2, figsize=(12, 4))
        gt = arrays["real_pcalib"]
        ax.plot(gt, "k-", lw=2, label="pcalib_inside1")
        for key, style in (("both", "C3-"), ("left", "C0--"), ("right", "C2:")):
            g = arrays[f"real_in_situ_{key}"]
            sl = slice(16, 3001)
            s = float(np.dot(g[sl], gt[sl]) / np.dot(g[sl], g[sl]))
            ax.plot(g * s, style, lw=1, label=f"in situ ({key}), scaled on DN 16..3000")
        ax.set_xlabel("DN")
        ax.set_title("real sample: inverse response")
        ax.legend(fontsize=8)
        for k, (rname, style) in enumerate((("pcalib_inside1", "ko"), ("in_situ_both", "C3s"), ("linear", "C7^"))):
            pr = real["pairs"][rname]
            axb.semilogy(np.arange(len(pr)), [p["rmse_pct"] for p in pr], style, ms=4, label=rname)
        axb.set_xlabel("emulation (cycle, camera, source -> target)")
        axb.set_ylabel("quantile RMSE, % of range")
        axb.set_title("cross-bracket error per emulation")
        axb.legend(fontsize=8)
        axb.grid(alpha=0.3, which="both")
        fig.tight_layout()
        save_figure(fig, out / "real_sample.png", dpi=100)
        names.append("real_sample.png")
    return names


def _f(v, d=3):
    return "n/a" if v is None else f"{v:.{d}f}"


def _report(results: dict, figures: list[str]) -> str:
    cfg = results["config"]
    lines = ["# Inverse-response calibration: validation", "",
             f"Command: `{results['command']}`  ", f"Radiance of the static stacks: {results['radiance']}  ",
             f"Stacks: {cfg['n_exposures']} exposures each, jittered log spacing, noise on (synth presets: full "
             f"well 10500 e-, read noise 2.4 e-), {cfg['width']}x{cfg['height']} Bayer, "
             f"{cfg['max_pixels']} pixels sampled.  Errors: f^-1 over DN {DN_RANGE[0]}..{DN_RANGE[1]} in % of "
             "its range after scale alignment (f^-1 is defined up to scale); 'as written' normalises both to "
             "g(top) = 255 like the pcalib file.", ""]
    st = results.get("static", {})
    if st:
        methods = ["ours_12bit", "ours_12bit_at_8bit_bin_centres", "ours_8bit", "opencv_debevec_8bit",
                   "opencv_robertson_8bit"]
        extra = [m for m in ("ours_12bit_geometric_exposures", "ours_12bit_als_500_iterations")
                 if any(m in st[p]["errors"] for p in st)]
        lines += ["## Recovery error of f^-1 (max / RMS, % of range, DN 16..4079)", "",
                  "| method | " + " | ".join(st) + " |", "|---" * (len(st) + 1) + "|"]
        for m in methods + extra:
            cells = []
            for p in st:
                e = st[p]["errors"].get(m)
                cells.append("-" if e is None else f"{_f(e['max_pct'])} / {_f(e['rms_pct'])}")
            lines.append(f"| {m} | " + " | ".join(cells) + " |")
        lines.append("| ours_12bit as written (g(top)=255) | " + " | ".join(
            f"{_f(st[p]['errors']['ours_12bit']['max_pct_as_written'])} / "
            f"{_f(st[p]['errors']['ours_12bit']['rms_pct_as_written'])}" for p in st) + " |")
        lines += ["", "8-bit rows: inputs DN >> 4, curves compared at the bin centres DN 16 v + 7.5 of codes "
                  "1..254.  Target: ours below 0.5 % max.",
                  "", "## Fit and emulation with the recovered response", "",
                  "Emulation: 1..32 bracket set (longest saturating ~3 %), targets halfway between brackets, "
                  "each from both bounding brackets, against the noiseless capture; RMSE over the validity "
                  "mask.  'pcalib format' is the true curve sampled at the 256 pcalib knots.", "",
                  "| preset | observed DN | residual DN RMS | noise DN (image estimate) | exposures span | "
                  "max abs(RMSE_rec / RMSE_true - 1) | same, true in pcalib format | max abs(RMSE_rec / RMSE_format - 1) "
                  "| max RMSE_true % | max RMSE(rec - true emulation) % |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for p, r in st.items():
            f, em = r["fit"], r["emulation"]
            lines.append(f"| {p} | {f['observed_dn'][0]}..{f['observed_dn'][1]} | {_f(f['residual_rms_dn'], 2)} | "
                         f"{_f(f['noise_dn'], 2)} | {_f(r['exposure_span_decades'], 1)} decades | "
                         f"{_f(em['max_abs_ratio_minus_1'])} | {_f(em['max_abs_format_ratio_minus_1'])} | "
                         f"{_f(em['max_abs_ratio_to_format_minus_1'])} | {_f(em['max_rmse_true_pct'])} | "
                         f"{_f(em['max_recovered_vs_true_emulation_pct'])} |")
        b = st.get("borealhdr", {}).get("borealhdr_table")
        if b and "skipped" not in b:
            lines += ["", "## BorealHDR: recovered vs the real table pcalib_inside1", "",
                      "| comparison | max % (scale) | RMS % (scale) | max % (as written) |", "|---|---|---|---|"]
            for name, v in b.items():
                lines.append(f"| {name} | {_f(v['scale']['max_pct'])} | {_f(v['scale']['rms_pct'])} | "
                             f"{_f(v['top']['max_pct'])} |")
    ins = results.get("in_situ_synthetic", {})
    if ins:
        lines += ["", "## In situ on synthetic moving recordings", "",
                  "| preset | sweeps | observed DN | max % 16..4079 | RMS % | max % observed | cross-bracket median %: recovered / true / linear |",
                  "|---|---|---|---|---|---|---|"]
        for p, r in ins.items():
            s = r["cross_bracket_median_pct"]
            lines.append(f"| {p} | {r['n_sweeps']} | {r['observed_dn'][0]}..{r['observed_dn'][1]} | "
                         f"{_f(r['error_16_4079']['max_pct'], 2)} | {_f(r['error_16_4079']['rms_pct'], 2)} | "
                         f"{_f(r['error_observed']['max_pct'], 2)} | {_f(s['recovered'])} / {_f(s['true'])} / "
                         f"{_f(s['linear'])} |")
    real = results.get("real_sample", {})
    if real and "skipped" not in real:
        sc = real["scores"]
        lines += ["", "## Real BorealHDR sample: cross-bracket error (median %, reference: pcalib 0.56-0.60, linear 9.6)",
                  "", real["method"], "", "| response | both cameras | left | right |", "|---|---|---|---|"]
        for rname, v in sc.items():
            lines.append(f"| {rname} | {_f(v['both']['median_pct'])} | {_f(v['left']['median_pct'])} | "
                         f"{_f(v['right']['median_pct'])} |")
        v = real["median_1000_quantiles_0_to_1"]
        lines += ["", "With 1000 quantile levels 0..1 instead: " + ", ".join(f"{k} {_f(x)}" for k, x in v.items()),
                  "", "In-situ shape vs pcalib (scale-aligned, max / RMS %): " + "; ".join(
                      f"{k}: DN 16..3000 {_f(s['16_3000']['max_pct'], 2)} / {_f(s['16_3000']['rms_pct'], 2)}, "
                      f"DN 16..4079 {_f(s['16_4079']['max_pct'], 2)} / {_f(s['16_4079']['rms_pct'], 2)}"
                      for k, s in real["in_situ_vs_pcalib_shape"].items())]
    lines += [""] + [f"![{f}]({f})" for f in figures] + [""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------- driver
def run_study(out, *, quick: bool = False, force: bool = False, radiance_source: str = "static_lab",
              parts=("static", "insitu", "real"), command: str = "", progress=None) -> dict:
    """Run the study into folder ``out``; returns the results dict (also written to results.json)."""
    from emulator.io.files import prepare_output, write_arrays, write_results, write_text
    from validation.common import provenance

    out = prepare_output(out, force=force)
    cfg = dict(CONFIGS["quick" if quick else "full"])
    say = progress or (lambda msg: None)
    results = {"command": command, "config": cfg, **provenance("calibration_study", cfg)}
    arrays = {}
    t0 = time.perf_counter()
    if "static" in parts:
        radiance, label = study_radiance(cfg["width"], cfg["height"], cfg["spp"], radiance_source)
        results["radiance"] = label
        results["static"], a = static_part(cfg, radiance, out, say)
        arrays.update(a)
    else:
        results["radiance"] = "not used"
    if "insitu" in parts:
        results["in_situ_synthetic"], a = insitu_synthetic(cfg, out, say)
        arrays.update(a)
    if "real" in parts and cfg["real_sample"]:
        results["real_sample"], a = real_sample_part(say)
        arrays.update(a)
    results["seconds"] = time.perf_counter() - t0
    write_arrays(out / "curves.npz", arrays)
    figures = _plots(results, arrays, out)
    write_results(out / "results.json", results, float_digits=12)
    write_report(out, _report(results, figures))
    return results


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m validation.calibration_study", description=__doc__.split("\n\n")[0])
    p.add_argument("output", type=Path, help="output folder (results.json, report.md, plots)")
    p.add_argument("--quick", action="store_true", help="small images, 16 exposures, 4 sweeps")
    p.add_argument("--force", action="store_true", help="overwrite an existing results.json")
    p.add_argument("--radiance", choices=("static_lab", "chart"), default="static_lab",
                   help="radiance of the static stacks (default static_lab, falls back to the chart)")
    p.add_argument("--parts", default="static,insitu,real", help="comma-separated subset of static,insitu,real")
    args = p.parse_args(argv)
    parts = tuple(s.strip() for s in args.parts.split(",") if s.strip())
    command = "python -m validation.calibration_study " + " ".join(shlex.quote(a) for a in (argv or sys.argv[1:]))
    t0 = time.perf_counter()
    run_study(args.output, quick=args.quick, force=args.force, radiance_source=args.radiance, parts=parts,
              command=command, progress=lambda m: print(f"[{time.perf_counter() - t0:7.1f} s] {m}", flush=True))
    print(f"wrote {args.output / 'results.json'}, {args.output / 'report.md'}, {args.output / 'report.html'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
