"""Running the render study: per scene rows, texture targets, the output folder."""

from __future__ import annotations

import tempfile
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from emulator.io.files import prepare_output, write_results
from emulator.report.html import write_report
from validation.common import provenance, study_scene, to_percent
from validation.render_study.config import (
    CONFIGS,
    RenderStudyConfig,
    TARGET_REPEATABILITY,
    TARGET_TOLERANCE,
    DENOISED as _DENOISED,
    MODES as _MODES,
)
from validation.render_study.measure import real_stats, within_real, bright_errors, speedups, walk_repeatability
from validation.render_study.report import plot_render_study, render_study_table

__all__ = ["run_render_study", "total_steps"]


def _scene_rows(key: str, config: RenderStudyConfig, tmp_cache: Path, tick, real) -> tuple[list[dict], dict]:
    import scenes
    from scenes.image_stats import image_stats, keypoint_points, keypoint_repeatability, synthetic_camera, \
        synthetic_gray8
    from synth import capture

    spec = study_scene(key)
    scene = spec.build()
    t0 = float(spec.pose_time_s or 0.0)
    traj = scene.trajectory(t0 + config.walk_step_s + 1.0)
    pose_a, pose_b = traj.pose(t0), traj.pose(t0 + config.walk_step_s)
    w, h, fov = config.width, config.height, scenes.DEFAULT_FOV_DEG
    kw = dict(width=w, height=h, fov_deg=fov)
    cam = synthetic_camera(scene, w, h)
    white, black = cam.white_level, cam.black_level

    t = time.perf_counter()
    ref, ref_info = scenes.render_with_info(scene, pose_a, spp=config.reference_spp, seed=1000, denoise="off",
                                            cache_dir=False if config.cache_dir == "off" else config.cache_dir, **kw)
    ref_s = time.perf_counter() - t
    tick()
    depth_a = scenes.render_depth(scene, pose_a, spp=4, **kw)
    ref_caps = {e: capture(ref, e, cam, seed=0, noise=False).astype(np.float64) for e in config.error_exposures_ms}
    sensor_change = float(np.mean(np.abs(capture(ref, config.exposure_ms, cam, seed=0).astype(np.float64)
                                         - capture(ref, config.exposure_ms, cam, seed=1).astype(np.float64))))
    sensor_change_pct = to_percent(sensor_change, white, black)

    rows = []
    for spp in config.spp_levels:
        images = {m: [] for m in _MODES}
        times = {m: [] for m in _MODES}
        fallback = None
        frames = [(pose_a, s) for s in config.seeds] + [(pose_b, max(config.seeds) + 1)]
        for pose, seed in frames:
            raw, info = scenes.render_with_info(scene, pose, spp=int(spp), seed=int(seed), denoise="off",
                                                cache_dir=tmp_cache, **kw)
            times["off"].append(info["render_s"])
            images["off"].append(raw)
            for mode in _DENOISED:
                den, dinfo = scenes.render_with_info(scene, pose, spp=int(spp), seed=int(seed), denoise=mode,
                                                     cache_dir=tmp_cache, **kw)
                fallback = fallback or dinfo["fallback"]
                times[mode].append(info["render_s"] + dinfo["aux_s"] + dinfo["denoise_s"])
                images[mode].append(den)
            tick()
        for mode in _MODES:
            imgs = images[mode]
            stat_a = imgs[: len(config.seeds)]
            errs = [to_percent(float(np.sqrt(np.mean((capture(img, e, cam, seed=0, noise=False).astype(np.float64)
                                                      - ref_caps[e]) ** 2))), white, black)
                    for img in stat_a for e in config.error_exposures_ms]
            bright = [bright_errors(img, ref, halo_px=config.halo_px) for img in stat_a]
            grays = [synthetic_gray8(img, scene, exposure_ms=config.exposure_ms, seed=0, camera=cam) for img in imgs]
            pts = [keypoint_points(g) for g in grays]
            noiseless = [capture(img, config.exposure_ms, cam, seed=0, noise=False).astype(np.float64)
                         for img in stat_a]
            flicker = float(np.mean([np.mean(np.abs(b - a)) for a, b in zip(noiseless[:-1], noiseless[1:])]))
            st = image_stats(grays[0])
            rows.append({
                "scene": key, "spp": int(scenes.effective_spp(int(spp))), "denoise": mode,
                "denoise_applied": "off" if (mode != "off" and fallback) else mode,
                "time_s": float(np.median(times[mode][1:])),
                "rmse_pct": float(np.mean(errs)),
                "bright_rel_err": float(np.mean([b["bright_rel_err"] for b in bright])),
                "bright_halo": float(np.mean([b["bright_halo"] for b in bright])),
                "repeat_seeds": keypoint_repeatability(pts[0], pts[1]),
                "repeat_walk": walk_repeatability(pts[0], depth_a, pose_a, pose_b, pts[-1], width=w, height=h,
                                                  fov_deg=fov),
                "flicker_pct": to_percent(flicker, white, black),
                "flicker_ratio": float(flicker / max(sensor_change, 1e-12)),
                "kp_per_mp": st.keypoints_per_mp, "median_gradient": st.median_gradient,
            })
    ref_bright = bright_errors(ref, ref, halo_px=config.halo_px)
    meta = {"reference_spp": int(scenes.effective_spp(config.reference_spp)), "reference_time_s": ref_s,
            "reference_cached": bool(ref_info["cache_hit"]),
            "reference_dynamic_range_db": float(scenes.dynamic_range_db(ref)),
            "sensor_change_pct": sensor_change_pct, "reference_bright_halo": ref_bright["bright_halo"],
            "pose_time_s": t0, "walk_step_s": config.walk_step_s, "fallback": fallback,
            "reference_kp_per_mp": image_stats(synthetic_gray8(ref, scene, exposure_ms=config.exposure_ms, seed=0,
                                                               camera=cam)).keypoints_per_mp}
    return rows, meta


def _texture(key: str, config: RenderStudyConfig, size, tmp_cache: Path, tick, real) -> dict:
    import scenes
    from scenes.image_stats import image_stats, keypoint_points, keypoint_repeatability, synthetic_gray8

    spec = study_scene(key)
    scene = spec.build()
    t0 = float(spec.pose_time_s or 0.0)
    times = [t0 + i * config.texture_pose_step_s for i in range(config.texture_poses)]
    traj = scene.trajectory(max(times) + 1.0)
    w, h = (int(v) for v in size)
    per_pose = []
    for ts in times:
        pose = traj.pose(ts)
        a, info = scenes.render_with_info(scene, pose, width=w, height=h, spp=config.texture_spp,
                                          seed=config.seeds[0], denoise="oidn", cache_dir=tmp_cache)
        b = scenes.render(scene, pose, width=w, height=h, spp=config.texture_spp, seed=config.seeds[1],
                          denoise="oidn", cache_dir=tmp_cache)
        ga = synthetic_gray8(a, scene, exposure_ms=config.exposure_ms, seed=0)
        gb = synthetic_gray8(b, scene, exposure_ms=config.exposure_ms, seed=0)
        st = image_stats(ga)
        per_pose.append({"t_s": ts, "kp_per_mp": st.keypoints_per_mp, "median_gradient": st.median_gradient,
                         "mean_gray": st.mean_gray, "denoise": info["denoise"],
                         "repeat_seeds": keypoint_repeatability(keypoint_points(ga), keypoint_points(gb))})
        tick()
    kp = float(np.mean([p["kp_per_mp"] for p in per_pose]))
    grad = float(np.mean([p["median_gradient"] for p in per_pose]))
    rep = float(np.mean([p["repeat_seeds"] for p in per_pose]))
    out = {"scene": key, "width": w, "height": h, "spp": int(scenes.effective_spp(config.texture_spp)),
           "kp_per_mp": kp, "median_gradient": grad, "repeat_seeds": rep, "poses": per_pose,
           "real_kp_per_mp": None if real is None else real["kp_per_mp"],
           "real_median_gradient": None if real is None else real["median_gradient"]}
    out["kp_ratio"] = None if real is None else kp / real["kp_per_mp"]
    out["gradient_ratio"] = None if real is None else grad / real["median_gradient"]
    out["kp_met"] = within_real(kp, out["real_kp_per_mp"])
    out["gradient_met"] = within_real(grad, out["real_median_gradient"])
    out["repeat_met"] = bool(rep >= TARGET_REPEATABILITY)
    return out


def run_render_study(output, config: RenderStudyConfig | None = None, *, force: bool = False, progress=None,
                     command: str = "") -> dict:
    """Run the study, write ``results.json``, ``report.md`` and ``time_vs_error.png``; return the results.

    ``progress``: optional callable ``(n_done_increment)`` (a tqdm ``update``).
    """
    config = config or CONFIGS["full"]
    folder = prepare_output(output, force=force)
    tick = (lambda n=1: progress(n)) if progress is not None else (lambda n=1: None)
    t_start = time.perf_counter()
    reals: dict = {}

    def real_at(size):
        key = tuple(int(v) for v in size)
        if key not in reals:
            reals[key] = real_stats(config.real_sequence, key, config.exposure_ms)
        return reals[key]

    rows, meta, textures = [], {}, []
    with tempfile.TemporaryDirectory(prefix="exposim-render-study-") as tmp:
        real_main = real_at((config.width, config.height))
        for key in config.scenes:
            r, m = _scene_rows(key, config, Path(tmp) / key, tick, real_main)
            rows += r
            meta[key] = m
        for key in config.texture_scenes:
            for size in config.texture_sizes:
                textures.append(_texture(key, config, size, Path(tmp) / f"tex-{key}", tick, real_at(size)))
    results = {
        "provenance": provenance(command or "validation.render_study", asdict(config)),
        "rows": rows,
        "scenes": meta,
        "speedups": speedups(rows),
        "texture": textures,
        "real": {f"{w}x{h}": (None if v is None else {k: v[k] for k in ("kp_per_mp", "median_gradient", "n_frames")})
                 for (w, h), v in reals.items()},
        "targets": {"tolerance": TARGET_TOLERANCE, "repeatability": TARGET_REPEATABILITY},
        "timings": {"total_s": time.perf_counter() - t_start},
    }
    write_results(folder / "results.json", results, float_digits=12)
    plot_render_study(results, folder / "time_vs_error.png")
    write_report(folder, render_study_table(results) + "\n")
    return results


def total_steps(config: RenderStudyConfig) -> int:
    """Progress-bar length of :func:`run_render_study`."""
    per_scene = 1 + len(config.spp_levels) * (len(config.seeds) + 1)
    return len(config.scenes) * per_scene + len(config.texture_scenes) * len(config.texture_sizes) * \
        config.texture_poses
