"""Render study: speed against error of raw and denoised renders, and realism vs real frames.

Run from the repository root::

    python -m validation.render_study OUT [--quick] [--scenes a,b] [--size WxH] [--spp 1,4,16]
                                          [--reference-spp N] [--texture-sizes 480x300,960x600]
                                          [--texture-spp S] [--texture-poses N] [--real PATH] [--force]

Per study scene (:data:`validation.common.STUDY_SCENES`), at the study size, for every spp
level, the raw path-traced estimate (``denoise="off"``) and the two denoised renders
(Open Image Denoise with albedo and normal, :mod:`scenes.denoise`: the default ``oidn`` and
the cheaper ``oidn-fast``) of one pose, each
against a raw reference of ``reference_spp`` samples (>= 1024 in the full study) at that
pose:

``time_s``
    Wall-clock seconds per frame, median over the renders after the first of each spp
    (the first compiles the kernels).  Raw: path tracing; denoised: path tracing plus the
    albedo/normal pass plus OIDN.
``rmse_pct``
    RMSE of noiseless synthetic-camera captures (BorealHDR response, 12 bit) against the
    reference's, in percent of the DN range (DESIGN.md), mean over ``error_exposures_ms``
    and the render seeds.
``bright_rel_err``, ``bright_halo``
    The hard case (sun disk, ice glints): over the brightest 0.1 % of the reference's
    pixels (luminance), the relative RMS luminance error; and in the ring of pixels within
    ``halo_px`` of them, mean luminance over the reference's minus 1 (positive: energy
    smeared out of the core).  The reference itself is the bound.
``repeat_seeds``
    SIFT keypoint repeatability (:func:`scenes.image_stats.keypoint_repeatability`,
    1.5 px) between two renders of the pose with different render seeds (same sensor
    noise draw, so the figure measures the renderer).
``repeat_walk``
    The same between consecutive frames of the scene's walk (one bracket cycle, 273 ms,
    apart): keypoints of frame A are moved into frame B through the exact depth and poses
    (Mitsuba's depth AOV), keypoints that leave the image or see the sky are dropped.
``flicker_pct``, ``flicker_ratio``
    Static camera: mean absolute change of the noiseless 8 ms capture between consecutive
    frames (renders with the frame seeds a static trajectory uses), percent of the DN
    range; and its ratio to the change the sensor's own noise makes between two frames of
    the reference (a ratio well below 1: the camera would not see the renderer's flicker).
``kp_per_mp``, ``median_gradient``
    Of the 8 ms frame with sensor noise (:func:`scenes.image_stats.synthetic_gray8`),
    beside the real frames' at the same size (``real``).

Texture targets (issue 13): for the texture scenes, denoised renders at ``texture_spp`` of
``texture_poses`` walk poses at every ``texture_sizes`` size: SIFT keypoints per megapixel,
median gradient and seed repeatability against the real BorealHDR frames of the 8 ms
bracket at the same size (both cameras; full-resolution grey then ``INTER_AREA``).

Speed-up: for every denoised spp, the time the raw estimate needs for the same error,
interpolated on the raw curve in log-log (extrapolated beyond its last two points when the
denoised error is below every raw one: flagged), over the denoised time.

Writes ``OUT/results.json``, ``OUT/report.md`` (the table) and ``OUT/time_vs_error.png``;
refuses to overwrite an earlier ``results.json`` without ``force``.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from emulator.commands.progress import add_quiet, bars_enabled
from emulator.commands import argtypes
from emulator.errors import ExposimError
from emulator.io.files import prepare_output, write_results, write_text
from emulator.report.html import write_report
from validation.common import SHOT_INTERVAL_MS, ValidationError, provenance, study_scene, to_percent

__all__ = ["RenderStudyConfig", "CONFIGS", "run_render_study", "render_study_table", "speedups", "main",
           "add_arguments", "config_from_args", "run_from_args", "print_summary",
           "DEFAULT_REAL_SEQUENCE", "TARGET_TOLERANCE", "TARGET_REPEATABILITY"]


def _shared_folder() -> Path:
    """``../shared`` beside the repository; from a git worktree the first ``shared/data`` further up."""
    repo = Path(__file__).resolve().parents[1]
    for parent in repo.parents:
        if (parent / "shared" / "data").is_dir():
            return parent / "shared"
    return repo.parent / "shared"


#: The shared BorealHDR sample (beside the repository, never copied into it).
DEFAULT_REAL_SEQUENCE = _shared_folder() / "data" / "borealhdr_sample" / "backpack_2023-09-25-15-05-03"
#: Texture statistics must be within this fraction of the real frames' (issue 13).
TARGET_TOLERANCE = 0.25
#: Keypoint repeatability target between two renders of one pose (issue 13).
TARGET_REPEATABILITY = 0.80
#: Render paths compared: the raw estimate and every named denoiser (:data:`scenes.denoise.DENOISERS`).
_MODES = ("off", "oidn", "oidn-fast")
_DENOISED = _MODES[1:]


@dataclass(frozen=True)
class RenderStudyConfig:
    """What the render study measures (see the module docstring)."""

    scenes: tuple = ("forest_winter", "sun_glare")
    width: int = 480
    height: int = 300
    spp_levels: tuple = (1, 2, 4, 8, 16, 32, 64)
    reference_spp: int = 1024
    exposure_ms: float = 8.0
    error_exposures_ms: tuple = (1.0, 8.0, 32.0)
    seeds: tuple = (1, 2, 3)
    walk_step_s: float = 6 * SHOT_INTERVAL_MS / 1000.0
    halo_px: int = 3
    texture_scenes: tuple = ("forest_winter",)
    texture_sizes: tuple = ((480, 300), (960, 600))
    texture_spp: int = 16
    texture_poses: int = 3
    texture_pose_step_s: float = 3.0
    real_sequence: str | None = str(DEFAULT_REAL_SEQUENCE)
    cache_dir: str | None = None

    def __post_init__(self) -> None:
        for key in self.scenes + self.texture_scenes:
            study_scene(key)
        if self.width < 16 or self.height < 16:
            raise ValidationError(f"study size must be at least 16x16, got {self.width}x{self.height}")
        if not self.spp_levels or any(int(s) < 1 for s in self.spp_levels):
            raise ValidationError(f"spp levels must be >= 1, got {self.spp_levels!r}")
        if self.reference_spp <= max(self.spp_levels):
            raise ValidationError(f"reference_spp ({self.reference_spp}) must exceed every spp level")
        if len(self.seeds) < 3 or len(set(self.seeds)) != len(self.seeds):
            raise ValidationError(f"need at least three distinct render seeds, got {self.seeds!r}")
        if self.texture_poses < 1 or self.texture_spp < 1:
            raise ValidationError("texture_poses and texture_spp must be >= 1")


#: ``full``: the issue's settings; ``quick``: a pipeline check in a few minutes on 2 cores.
CONFIGS = {
    "full": RenderStudyConfig(),
    "quick": RenderStudyConfig(scenes=("forest_winter",), width=120, height=75, spp_levels=(1, 4, 16),
                               reference_spp=256, texture_sizes=((240, 150),), texture_spp=4, texture_poses=1),
}


# ------------------------------------------------------------------------------------------ measures
def _luminance(img: np.ndarray) -> np.ndarray:
    return img[..., 0] * 0.2126 + img[..., 1] * 0.7152 + img[..., 2] * 0.0722


def bright_errors(img: np.ndarray, ref: np.ndarray, *, fraction: float = 0.001, halo_px: int = 3) -> dict:
    """Error in the brightest ``fraction`` of the reference's pixels, and the smear around them.

    Returns ``bright_rel_err`` (relative RMS luminance error over those pixels) and
    ``bright_halo`` (mean luminance over the reference's, minus 1, in the ring within
    ``halo_px`` pixels of them; NaN-free: 0 when the ring is empty).
    """
    import cv2

    y, yr = _luminance(img).astype(np.float64), _luminance(ref).astype(np.float64)
    n = max(1, int(round(fraction * yr.size)))
    thresh = np.partition(yr.ravel(), yr.size - n)[yr.size - n]
    core = yr >= thresh
    rel = float(np.sqrt(np.mean(((y[core] - yr[core]) / np.maximum(yr[core], 1e-12)) ** 2)))
    k = 2 * int(halo_px) + 1
    ring = cv2.dilate(core.astype(np.uint8), np.ones((k, k), np.uint8)).astype(bool) & ~core
    halo = float(y[ring].mean() / max(yr[ring].mean(), 1e-12) - 1.0) if ring.any() else 0.0
    return {"bright_rel_err": rel, "bright_halo": halo}


def walk_repeatability(points_a, depth_a: np.ndarray, pose_a, pose_b, points_b, *, width: int, height: int,
                       fov_deg: float, radius_px: float = 1.5) -> float:
    """Repeatability of frame A's keypoints in frame B through the exact depth and poses.

    Keypoints of A are lifted to 3-D with A's depth (ray distance, metres; 0 = sky),
    projected into B; those that land outside B or see the sky are dropped.  Returns the
    fraction of the rest with a keypoint of B within ``radius_px`` (NaN when none is left).
    """
    import scenes
    from scenes.image_stats import keypoint_repeatability

    pa = np.asarray(points_a, dtype=np.float64).reshape(-1, 2)
    if pa.shape[0] == 0:
        return float("nan")
    fx, fy, cx, cy = scenes.intrinsics(width, height, fov_deg)
    iu = np.clip(np.round(pa[:, 0]).astype(int), 0, width - 1)
    iv = np.clip(np.round(pa[:, 1]).astype(int), 0, height - 1)
    d = depth_a[iv, iu].astype(np.float64)
    rays = np.stack([(pa[:, 0] - cx) / fx, (pa[:, 1] - cy) / fy, np.ones(len(pa))], -1)
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    pts = rays * d[:, None] @ np.asarray(pose_a)[:3, :3].T + np.asarray(pose_a)[:3, 3]
    uv = scenes.project(pts, pose_b, width, height, fov_deg)
    ok = (d > 0) & np.all(np.isfinite(uv), axis=1) & (uv[:, 0] >= 0) & (uv[:, 0] <= width - 1) & \
        (uv[:, 1] >= 0) & (uv[:, 1] <= height - 1)
    if not ok.any():
        return float("nan")
    return keypoint_repeatability(uv[ok], points_b, radius_px)


def speedups(rows: list[dict]) -> list[dict]:
    """For each denoised row: the raw time for the same error (log-log on the raw curve) / denoised time."""
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        raw = sorted((r for r in rows if r["scene"] == scene and r["denoise"] == "off"), key=lambda r: r["time_s"])
        if len(raw) < 2:
            continue
        lt = np.log([r["time_s"] for r in raw])
        le = np.log([max(r["rmse_pct"], 1e-12) for r in raw])
        for r in rows:
            if r["scene"] != scene or r["denoise"] == "off":
                continue
            e = np.log(max(r["rmse_pct"], 1e-12))
            extrapolated = bool(e < le.min() or e > le.max())
            if not extrapolated:
                # raw error falls with time: walk the segments, interpolate on the first that brackets e
                t_eq = None
                for i in range(len(raw) - 1):
                    lo, hi = sorted((le[i], le[i + 1]))
                    if lo <= e <= hi and le[i] != le[i + 1]:
                        t_eq = lt[i] + (e - le[i]) * (lt[i + 1] - lt[i]) / (le[i + 1] - le[i])
                        break
                if t_eq is None:
                    extrapolated = True
            if extrapolated:
                i0, i1 = (len(raw) - 2, len(raw) - 1) if e < le.min() else (0, 1)
                slope = (le[i1] - le[i0]) / (lt[i1] - lt[i0]) if lt[i1] != lt[i0] else -0.5
                slope = slope if slope < 0 else -0.5  # never extrapolate a flat or rising curve
                t_eq = lt[i1] + (e - le[i1]) / slope
            t_raw = float(np.exp(t_eq))
            out.append({"scene": scene, "spp": r["spp"], "denoise": r["denoise"], "denoised_time_s": r["time_s"],
                        "denoised_rmse_pct": r["rmse_pct"], "raw_time_same_error_s": t_raw,
                        "speedup": t_raw / r["time_s"], "extrapolated": extrapolated})
    return out


# ------------------------------------------------------------------------------------------ the study
def _real_stats(sequence, size, exposure_ms) -> dict | None:
    from scenes.image_stats import image_stats, real_frames_gray8

    if sequence is None or not Path(sequence).is_dir():
        return None
    frames = real_frames_gray8(sequence, exposure_ms=exposure_ms, size=tuple(size))
    st = [image_stats(g) for _, _, g in frames]
    return {"kp_per_mp": float(np.mean([s.keypoints_per_mp for s in st])),
            "median_gradient": float(np.mean([s.median_gradient for s in st])),
            "n_frames": len(st), "per_frame": [s.to_dict() for s in st]}


def _within(value, real) -> bool | None:
    if real is None or value is None:
        return None
    return bool(abs(value / real - 1.0) <= TARGET_TOLERANCE)


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
    out["kp_met"] = _within(kp, out["real_kp_per_mp"])
    out["gradient_met"] = _within(grad, out["real_median_gradient"])
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
            reals[key] = _real_stats(config.real_sequence, key, config.exposure_ms)
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
    _plot(results, folder / "time_vs_error.png")
    write_report(folder, render_study_table(results) + "\n")
    return results


def total_steps(config: RenderStudyConfig) -> int:
    """Progress-bar length of :func:`run_render_study`."""
    per_scene = 1 + len(config.spp_levels) * (len(config.seeds) + 1)
    return len(config.scenes) * per_scene + len(config.texture_scenes) * len(config.texture_sizes) * \
        config.texture_poses


# ------------------------------------------------------------------------------------------ report
def _f(v, fmt="{:.3g}") -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "-"
    return fmt.format(v)


def _yes(v) -> str:
    return "-" if v is None else ("yes" if v else "**no**")


def render_study_table(results: dict) -> str:
    """The study's markdown report: the per-scene table, texture targets and speed-ups."""
    cfg = results["provenance"]["config"]
    real = (results.get("real") or {}).get(f"{cfg['width']}x{cfg['height']}")
    lines = [f"# Render study: raw vs denoised (OIDN) at {cfg['width']}x{cfg['height']}", "",
             f"Command: `{results['provenance']['experiment']}`", "",
             "Error: RMSE of noiseless captures at " + ", ".join(f"{e:g}" for e in cfg["error_exposures_ms"]) +
             " ms vs a raw reference, % of the DN range. Bright: brightest 0.1 % of the reference's pixels "
             "(relative RMS error; halo: mean luminance over the reference's - 1 within "
             f"{cfg['halo_px']} px). Repeatability: SIFT, 1.5 px. Flicker: static camera, mean |change| of the "
             f"noiseless {cfg['exposure_ms']:g} ms capture between frames, % of DN range (ratio: to the sensor "
             "noise's own frame-to-frame change). kp/MP and gradient at "
             f"{cfg['exposure_ms']:g} ms with sensor noise" +
             ("" if real is None else f"; real frames: {real['kp_per_mp']:.0f} kp/MP, gradient "
                                      f"{real['median_gradient']:.1f}") + ".", ""]
    for key, m in results["scenes"].items():
        lines += [f"## {key}", "",
                  f"Reference {m['reference_spp']} spp ("
                  f"{'from the render cache' if m.get('reference_cached') else format(m['reference_time_s'], '.0f') + ' s'}, "
                  f"{m['reference_dynamic_range_db']:.0f} dB, halo {m['reference_bright_halo']:+.3f} vs itself, "
                  f"{m['reference_kp_per_mp']:.0f} kp/MP); sensor frame-to-frame change "
                  f"{m['sensor_change_pct']:.3f} %." + (f" **OIDN fell back**: {m['fallback']}" if m['fallback']
                                                        else ""), "",
                  "| spp | denoise | time s | error % | bright err | halo | repeat seeds | repeat walk | "
                  "flicker % | flicker/sensor | kp/MP | gradient |",
                  "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in (r for r in results["rows"] if r["scene"] == key):
            lines.append(f"| {r['spp']} | {r['denoise_applied']} | {_f(r['time_s'])} | {_f(r['rmse_pct'])} | "
                         f"{_f(r['bright_rel_err'])} | {_f(r['bright_halo'], '{:+.3f}')} | "
                         f"{_f(r['repeat_seeds'], '{:.2f}')} | {_f(r['repeat_walk'], '{:.2f}')} | "
                         f"{_f(r['flicker_pct'])} | {_f(r['flicker_ratio'], '{:.2f}')} | "
                         f"{_f(r['kp_per_mp'], '{:.0f}')} | {_f(r['median_gradient'], '{:.1f}')} |")
        lines.append("")
    if results["speedups"]:
        lines += ["## Speed-up of the denoiser (raw time for the same error / denoised time)", "",
                  "| scene | denoiser | spp | denoised s | error % | raw s for that error | speed-up | target >= 10 |",
                  "|---|---|---:|---:|---:|---:|---:|---|"]
        for s in results["speedups"]:
            lines.append(f"| {s['scene']} | {s.get('denoise', 'oidn')} | {s['spp']} | {_f(s['denoised_time_s'])} | {_f(s['denoised_rmse_pct'])} | "
                         f"{_f(s['raw_time_same_error_s'])}{' (extrapolated)' if s['extrapolated'] else ''} | "
                         f"{_f(s['speedup'])} | {_yes(s['speedup'] >= 10)} |")
        lines.append("")
    if results["texture"]:
        lines += [f"## Texture vs real frames (denoised, {cfg['exposure_ms']:g} ms; target +-"
                  f"{100 * TARGET_TOLERANCE:.0f} %, repeatability >= {TARGET_REPEATABILITY:.2f})", "",
                  "| scene | size | spp | kp/MP | real | ratio | met | gradient | real | ratio | met | "
                  "repeat seeds | met |", "|---|---|---:|---:|---:|---:|---|---:|---:|---:|---|---:|---|"]
        for t in results["texture"]:
            lines.append(f"| {t['scene']} | {t['width']}x{t['height']} | {t['spp']} | {t['kp_per_mp']:.0f} | "
                         f"{_f(t['real_kp_per_mp'], '{:.0f}')} | {_f(t['kp_ratio'], '{:.2f}')} | {_yes(t['kp_met'])} | "
                         f"{t['median_gradient']:.1f} | {_f(t['real_median_gradient'], '{:.1f}')} | "
                         f"{_f(t['gradient_ratio'], '{:.2f}')} | {_yes(t['gradient_met'])} | "
                         f"{t['repeat_seeds']:.2f} | {_yes(t['repeat_met'])} |")
        lines.append("")
    lines.append(f"Total {results['timings']['total_s'] / 60:.1f} min.")
    return "\n".join(lines)


def _plot(results: dict, path: Path) -> None:
    from emulator.report.figures import new_figure, save

    keys = list(results["scenes"])
    fig, axes = new_figure(len(keys), 5.0, 4.0)
    for ax, key in zip(axes, keys):
        for mode, style in (("off", "o-"), ("oidn", "s-"), ("oidn-fast", "^-")):
            rs = sorted((r for r in results["rows"] if r["scene"] == key and r["denoise"] == mode),
                        key=lambda r: r["spp"])
            if not rs:
                continue
            x = [r["time_s"] for r in rs]
            y = [max(r["rmse_pct"], 1e-6) for r in rs]
            ax.loglog(x, y, style, label={"off": "raw", "oidn": "denoised (OIDN)",
                                          "oidn-fast": "denoised (OIDN fast)"}[mode])
            for r, xi, yi in zip(rs, x, y):
                ax.annotate(str(r["spp"]), (xi, yi), textcoords="offset points", xytext=(3, 3), fontsize=7)
        ax.set_title(key)
        ax.set_xlabel("time per frame, s")
        ax.set_ylabel("RMSE vs reference, % of DN range")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    save(fig, path, dpi=110)


# ------------------------------------------------------------------------------------------ command line




def _sizes_text(sizes) -> str:
    return ",".join(f"{w}x{h}" for w, h in sizes)


def add_arguments(p: argparse.ArgumentParser, *, output_option: bool = False) -> None:
    """The study's options on ``p`` (``python -m validation.render_study`` and ``exposim validate render``).

    Every help text names the full study's default and the ``--quick`` value; ``output_option``:
    ``-o/--output DIR`` instead of a positional folder.
    """
    full, quick = CONFIGS["full"], CONFIGS["quick"]

    def both(fmt, attr):
        a, b = getattr(full, attr), getattr(quick, attr)
        return f"(default {fmt(a)}; --quick {fmt(b)})"

    csv = lambda v: ",".join(str(x) for x in v)  # noqa: E731
    out_help = "output folder (results.json, report.md, time_vs_error.png)"
    if output_option:
        p.add_argument("-o", "--output", type=Path, required=True, help=out_help)
    else:
        p.add_argument("output", type=Path, help=out_help)
    p.add_argument("--quick", action="store_true",
                   help=f"pipeline check: {csv(quick.scenes)} at {quick.width}x{quick.height}, spp "
                        f"{csv(quick.spp_levels)}, {quick.reference_spp}-spp reference (a few minutes)")
    p.add_argument("--scenes", help="comma-separated study scenes " + both(csv, "scenes"))
    p.add_argument("--size", type=argtypes.size, help=f"study size WxH (default {full.width}x{full.height}; "
                                              f"--quick {quick.width}x{quick.height})")
    p.add_argument("--spp", type=argtypes.ints, help="comma-separated spp levels " + both(csv, "spp_levels"))
    p.add_argument("--reference-spp", type=int, help="spp of the raw reference " + both(str, "reference_spp"))
    p.add_argument("--texture-scenes", help="comma-separated scenes for the texture targets, '' for none " +
                                            both(csv, "texture_scenes"))
    p.add_argument("--texture-sizes", help="comma-separated WxH sizes for the texture targets " +
                                           both(_sizes_text, "texture_sizes"))
    p.add_argument("--texture-spp", type=int, help="spp of the denoised texture renders " +
                                                   both(str, "texture_spp"))
    p.add_argument("--texture-poses", type=int, help="walk poses per texture size " + both(str, "texture_poses"))
    p.add_argument("--real", type=Path, help=f"real BorealHDR sequence (default {DEFAULT_REAL_SEQUENCE})")
    p.add_argument("--cache-dir", dest="cache", metavar="DIR",
                   help="render cache for the reference ('off': none; default $EXPOSIM_CACHE "
                        "or ~/.cache/exposim/renders)")
    p.add_argument("--cache", dest="cache", help=argparse.SUPPRESS)  # old spelling
    p.add_argument("--force", action="store_true", help="overwrite an existing results.json")
    add_quiet(p)


def config_from_args(args: argparse.Namespace) -> RenderStudyConfig:
    """The :class:`RenderStudyConfig` of parsed :func:`add_arguments` options (raises ValidationError)."""
    changes: dict = {}
    if args.scenes:
        changes["scenes"] = tuple(s.strip() for s in args.scenes.split(",") if s.strip())
    if args.size:
        changes["width"], changes["height"] = args.size
    if args.spp:
        changes["spp_levels"] = args.spp
    if args.reference_spp is not None:
        changes["reference_spp"] = args.reference_spp
    if args.texture_scenes is not None:
        changes["texture_scenes"] = tuple(s.strip() for s in args.texture_scenes.split(",") if s.strip())
    if args.texture_sizes:
        try:
            changes["texture_sizes"] = tuple(argtypes.size(s) for s in args.texture_sizes.split(",") if s.strip())
        except argparse.ArgumentTypeError as exc:
            raise ValidationError(f"--texture-sizes: {exc}") from None
    if args.texture_spp is not None:
        changes["texture_spp"] = args.texture_spp
    if args.texture_poses is not None:
        changes["texture_poses"] = args.texture_poses
    if args.real is not None:
        changes["real_sequence"] = str(args.real)
    if args.cache is not None:
        changes["cache_dir"] = args.cache
    return replace(CONFIGS["quick" if args.quick else "full"], **changes)


def run_from_args(args: argparse.Namespace, command: str) -> dict:
    """Run the study of parsed :func:`add_arguments` options with a progress bar; return the results."""
    config = config_from_args(args)
    from tqdm import tqdm

    with tqdm(total=total_steps(config), desc="render study", unit="step", disable=not bars_enabled(args.quiet),
              file=sys.stderr) as bar:
        return run_render_study(args.output, config, force=args.force, progress=bar.update, command=command)


def print_summary(results: dict, output: Path) -> None:
    """The table and the written files, on stdout (command lines only)."""
    print(render_study_table(results))
    print(f"wrote {output / 'results.json'}, {output / 'report.md'}, {output / 'report.html'}, {output / 'time_vs_error.png'}")


def main(argv=None) -> int:
    """``python -m validation.render_study`` (also ``exposim validate render -o OUT``)."""
    p = argparse.ArgumentParser(prog="python -m validation.render_study",
                                description=__doc__.split("\n\n")[0])
    add_arguments(p)
    args = p.parse_args(argv)
    argv_list = sys.argv[1:] if argv is None else list(argv)
    command = "python -m validation.render_study " + " ".join(shlex.quote(a) for a in argv_list)
    try:
        results = run_from_args(args, command)
    except (ExposimError, FileNotFoundError, NotADirectoryError) as exc:
        print(f"render_study: {exc}", file=sys.stderr)
        return 1
    print_summary(results, args.output)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
