"""Run the blur study and write ``results.json`` and ``report.md``."""

from __future__ import annotations

import platform
from pathlib import Path

import numpy as np

from validation.blur import measure
from validation.blur.config import BlurConfig, default_real_imu
from validation.blur.report import report_markdown
from validation.blur.versus import run_versus
from validation.common import Progress, make_camera, provenance
from emulator.cells import median_finite

__all__ = ["run_study", "summarise"]

#: Goals of issue 21.
RENDER_COST_RATIO_GOAL = 1.5
ANGULAR_RATE_RATIO_RANGE = (0.85, 1.15)
#: Consistent emulation's error over plain emulation's, at most (it "at least halves" it).
HALVING_GOAL = 0.5


def summarise(rows_ref, cost, rates, rows_sharp, cost_median=None) -> dict:
    """The headline figures of results.json from the per-instant rows."""
    ratio = rates.get("ratio")
    return {
        "reference_error_percent": median_finite([r.get("error_percent") for r in rows_ref]),
        "reference_noise_percent": median_finite([r.get("expected_noise_percent") for r in rows_ref]),
        "reference_error_over_noise": median_finite([r.get("error_over_noise") for r in rows_ref]),
        "reference_no_blur_error_percent": median_finite([r.get("no_blur_error_percent") for r in rows_ref]),
        "reference_error_over_noise_by_interpolation": {
            name: median_finite(x.get("error_over_noise") for row in rows_ref for x in row.get("by_interpolation", [])
                                if x["interpolation"] == name)
            for name in dict.fromkeys(x["interpolation"] for row in rows_ref for x in row.get("by_interpolation", []))},
        "render_cost_ratio": cost["render_cost_ratio"],
        "render_cost_ratio_median_rate": None if cost_median is None else cost_median["render_cost_ratio"],
        "render_cost_ratio_goal": RENDER_COST_RATIO_GOAL,
        "angular_rate_ratio": ratio,
        "angular_rate_within_goal": (None if ratio is None else
                                     all(ANGULAR_RATE_RATIO_RANGE[0] <= v <= ANGULAR_RATE_RATIO_RANGE[1]
                                         for v in ratio.values())),
        "sharpness_error_plain_percent": median_finite([r.get("plain_error_percent") for r in rows_sharp]),
        "sharpness_error_consistent_percent": median_finite([r.get("consistent_error_percent") for r in rows_sharp]),
        **_halving(rows_sharp),
    }


def _halving(rows_sharp) -> dict:
    """Median |sharpness error| and RMS image error of each emulation, and consistent over plain (goal <= 0.5)."""
    out = {}
    for key, plain, cons in (("sharpness_abs_error", "plain_error_percent", "consistent_error_percent"),
                             ("image_rms_error", "rms_plain_dn", "rms_consistent_dn")):
        pairs = [(abs(r[plain]), abs(r[cons])) for r in rows_sharp
                 if r.get(plain) is not None and r.get(cons) is not None]
        p = float(np.median([a for a, _ in pairs])) if pairs else None
        c = float(np.median([b for _, b in pairs])) if pairs else None
        unit = "percent" if key.startswith("sharpness") else "dn"
        out[f"{key}_plain_{unit}"] = p
        out[f"{key}_consistent_{unit}"] = c
        out[f"{key}_ratio"] = (c / p) if pairs and p else None
    out["consistent_halves_error_goal"] = HALVING_GOAL
    return out


def run_study(config: BlurConfig, out_dir, *, command: str = "", force: bool = False, progress=None,
              consistent=None) -> dict:
    """Measure, write ``results.json`` and ``report.md`` into ``out_dir``; return the results.

    ``consistent``: the blur-consistent emulation hook of :func:`measure.sharpness_comparison`
    (default: :func:`measure.consistent_from_walk`, :mod:`emulator.core.blur` fed the walk's gyro).
    """
    import scenes
    from emulator.io.files import prepare_output, write_results, write_text

    out = prepare_output(Path(out_dir), force=force)
    tick = Progress(progress)
    real_imu = config.real_imu or default_real_imu()
    scene = scenes.get_scene(config.scene, seed=config.seed)
    traj = scene.trajectory(config.walk_s + 1.0, walk=config.walk)
    camera = make_camera("borealhdr", width=config.width, height=config.height).saturating_at(
        scene.reference_radiance, 1.0)
    camera_sharp = make_camera("borealhdr", width=config.sharpness_width, height=config.sharpness_height).saturating_at(
        scene.reference_radiance, 1.0)
    if consistent is None:
        try:
            consistent = measure.consistent_from_walk(traj, camera_sharp)
        except ImportError:  # an exposim without emulator.core.blur: the figure stays null
            consistent = None
    rates = measure.angular_rate_ratio(traj, config.walk_s, real_imu)
    tick(1)
    instants = measure.fastest_instants(traj, config.walk_s, config.n_instants, config.exposure_ms)
    rows_ref, rows_sharp = [], []
    for t0 in instants:
        rows_ref.append(measure.reference_comparison(scene, traj, t0, config, camera))
        rows_sharp.append(measure.sharpness_comparison(scene, traj, t0, config, camera_sharp, consistent))
        tick(1)
    cost = measure.cost_comparison(scene, traj, instants[0], config, camera)
    cost_median = measure.cost_comparison(
        scene, traj, measure.median_rate_instant(traj, config.walk_s, config.exposure_ms), config, camera)
    tick(1)
    versus_result = None
    if config.versus_walks > 0:
        versus_result = run_versus(out, config, tick=tick)
    results = {
        **summarise(rows_ref, cost, rates, rows_sharp, cost_median),
        "consistent_hook": "validation.blur.run_study(consistent=f): f(raw, source_ms, target_ms, response, "
                           "shot_renderer) -> raw; not measured here (the realblur side's emulation)"
                           if consistent is None else "measured",
        "instants_s": instants,
        "reference": rows_ref,
        "cost": cost,
        "cost_median_rate": cost_median,
        "angular_rate": rates,
        "sharpness": rows_sharp,
        "live_versus_emulated": versus_result,
        "machine": {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
                    "variant": scenes.choose_variant()},
        "provenance": provenance(command, config.as_dict()),
    }
    write_results(out / "results.json", results, float_digits=12)
    write_text(out / "report.md", report_markdown(results))
    return results
