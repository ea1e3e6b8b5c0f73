"""Running the calibration study: static stacks, in situ on synthetic recordings, the real sample, the output folder."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from emulator.calibration import (
    CalibrationResult,
    calibrate_from_recording,
    calibrate_stack,
    cross_bracket_error,
    fit_inverse_response,
    response_error,
)
from emulator.io.pcalib import read_response
from emulator.io.stack import write_stack
from emulator.core.response import CameraResponse
from emulator.report.html import write_report
from validation.calibration_study.config import BRACKETS_MS, CONFIGS, DN_RANGE, PRESETS, SHOT_INTERVAL_S
from validation.calibration_study.measure import (
    capture_image as _capture,
    capture_stack,
    code_curve_error,
    codes_to_dn_curve,
    curve_error,
    electrons_per_ms,
    emulation_check,
    opencv_curves,
    stack_exposures,
    study_radiance,
)
from validation.calibration_study.report import calibration_plots, calibration_markdown
from validation.common import make_camera, provenance

__all__ = ["static_part", "borealhdr_check", "insitu_synthetic", "real_sample_part", "run_study"]


# ---------------------------------------------------------------------------- part 1-3: stacks
def static_part(cfg: dict, radiance: np.ndarray, out: Path, progress) -> tuple[dict, dict]:
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
    path = Path(__file__).resolve().parents[3] / "shared" / "data" / "borealhdr_sample" / "calibration" / \
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

    root = Path(__file__).resolve().parents[3] / "shared" / "data" / "borealhdr_sample"
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


# ---------------------------------------------------------------------------- driver
def run_study(out, *, quick: bool = False, force: bool = False, radiance_source: str = "static_lab",
              parts=("static", "insitu", "real"), command: str = "", progress=None) -> dict:
    """Run the study into folder ``out``; returns the results dict (also written to results.json)."""
    from emulator.io.files import prepare_output, write_arrays, write_results, write_text

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
    figures = calibration_plots(results, arrays, out)
    write_results(out / "results.json", results, float_digits=12)
    write_report(out, calibration_markdown(results, figures))
    return results
