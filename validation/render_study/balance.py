"""Render noise against sensor noise, as the feature metrics see them.

The measure (issue "verdicts v2", item 6): at each of a few walk poses of a scene, two renders
with different render seeds, each captured by the synthetic camera at an exposure with a few
sensor-noise draws.

``render_only``
    SIFT keypoint repeatability (:func:`scenes.image_stats.keypoint_repeatability`, 1.5 px)
    between the two renders captured with the same sensor-noise draw: what the renderer
    changes between two frames of one pose.
``sensor_only``
    The same between two sensor-noise draws of one render: what the camera's own noise
    changes.

Both are means over the sensor draws (render-only: each draw; sensor-only: consecutive pairs
of draws, on each of the two renders), in percent. The goal is met at an exposure when the
mean over the poses of ``render_only - sensor_only`` is at least ``-tolerance`` points (render
noise no worse for features than sensor noise, within 3 points). Intervals are Student-t 95 %
intervals over the poses.

A setting is ``DENOISER@SPP``, e.g. ``oidn-fast@2`` or ``oidn@8``; ``DENOISER@SPP/AUX`` also
sets the spp of the albedo/normal pass (:class:`scenes.denoise.DenoiseSettings`); the whole form,
with light weights and adaptive sampling, is :mod:`scenes.presets`'.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from validation.common import ValidationError, study_scene

__all__ = ["GOAL_TOLERANCE_POINTS", "parse_setting", "t_interval", "balance_at_pose", "noise_balance", "pareto_table", "radiance_bias"]

#: Render-only repeatability may be this many points below sensor-only (the issue's goal).
GOAL_TOLERANCE_POINTS = 3.0


def parse_setting(text: str):
    """``"oidn-fast@2"`` / ``"oidn@8/32"`` / ``"off@64"`` / ``"oidn@64/1024+sun=16"`` / a preset name
    -> (label, spp, denoise settings); the whole preset is :func:`scenes.presets.parse_setting`.

    Raises
    ------
    ValidationError
        Malformed text, unknown denoiser or light, spp or albedo/normal spp not a positive integer.
    """
    preset = _preset(text)
    return str(text), preset.spp, preset.denoise


def _preset(text: str):
    from scenes.errors import RenderError
    from scenes.presets import parse_setting as parse_preset

    try:
        return parse_preset(text)
    except RenderError as exc:
        msg = str(exc)
        raise ValidationError(msg if repr(str(text)) in msg else f"render setting {text!r}: {msg}") from None


def t_interval(values) -> tuple[float, float, float]:
    """(mean, low, high): Student-t 95 % interval of the mean (NaN bounds for fewer than two values)."""
    from scipy import stats

    v = np.asarray([x for x in values if np.isfinite(x)], dtype=float)
    if v.size == 0:
        return float("nan"), float("nan"), float("nan")
    m = float(v.mean())
    if v.size < 2:
        return m, float("nan"), float("nan")
    half = float(stats.t.ppf(0.975, v.size - 1) * v.std(ddof=1) / np.sqrt(v.size))
    return m, m - half, m + half


def balance_at_pose(render_a: np.ndarray, render_b: np.ndarray, scene, camera, *, exposure_ms: float,
                    sensor_seeds) -> dict:
    """Render-only and sensor-only repeatability (percent) of two renders of one pose at one exposure."""
    from scenes.image_stats import keypoint_points, keypoint_repeatability, synthetic_gray8

    seeds = [int(s) for s in sensor_seeds]
    if len(seeds) < 2:
        raise ValidationError(f"need at least two sensor-noise seeds, got {seeds}")
    pts = {(r, s): keypoint_points(synthetic_gray8(img, scene, exposure_ms=exposure_ms, seed=s, camera=camera))
           for r, img in (("a", render_a), ("b", render_b)) for s in seeds}
    render_only = [keypoint_repeatability(pts["a", s], pts["b", s]) for s in seeds]
    sensor_only = [keypoint_repeatability(pts[r, s], pts[r, t]) for r in "ab" for s, t in zip(seeds, seeds[1:])]
    return {"render_only": 100.0 * float(np.mean(render_only)), "sensor_only": 100.0 * float(np.mean(sensor_only)),
            "keypoints": float(np.mean([len(p) for p in pts.values()]))}


#: Shots per bracket sweep, the sweep's brackets (ms) and the recorder's frame rate (the study's schedule).
_BRACKETS_MS = (1.0, 2.0, 4.0, 8.0, 16.0, 32.0)
_FPS = 22.0


def _shot_source(scene, traj, *, width: int, height: int, spp: int, settings, fov_deg: float, render_seed: int,
                 render_per: str, cache_dir, adaptive=None):
    """``(index, exposure_ms) -> (radiance, cache_hit)`` of the left camera: the study's shots, or still renders;
    ``cache_hit``: the shot's render was read from the render cache (its seconds are not a render's)."""
    import scenes
    from scenes.walkshots import WalkShots, shot_time_s

    if render_per == "still":
        def still(index, exposure_ms):
            img, info = scenes.render_with_info(scene, traj.pose(shot_time_s(index, _FPS)), width=width,
                                                height=height, spp=spp, seed=render_seed * 1_000_003 + 2 * index,
                                                fov_deg=fov_deg, denoise=settings, cache_dir=cache_dir,
                                                adaptive=adaptive)
            return img, bool(info["cache_hit"])
        return still
    shots = WalkShots(scene, traj, render=dict(width=width, height=height, spp=spp, fov_deg=fov_deg,
                                               cache_dir=cache_dir, variant=None, denoise=settings,
                                               render_seed=render_seed,
                                               **({} if adaptive is None else {"adaptive": adaptive})),
                      fps=_FPS, n_brackets=len(_BRACKETS_MS), max_window_ms=max(_BRACKETS_MS), baseline_m=0.0,
                      render_per=render_per)
    def shot(index, exposure_ms):
        # the exposures are brackets of the sweep, all within max_window_ms: the sweep's own renderer serves them
        img = shots.radiance(index, "left", exposure_ms)
        return img, bool(shots.renderer(index, "left").info["cache_hit"])
    return shot


def noise_balance(setting: str, *, scene_key: str = "forest_winter", width: int = 480, height: int = 300,
                  exposures_ms=(8.0, 32.0), sweeps=(0, 11, 22, 33, 44), walk_seed: int = 0,
                  render_per: str = "cycle", render_seeds=(1, 2), sensor_seeds=(0, 1, 2, 3),
                  tolerance: float = GOAL_TOLERANCE_POINTS, cache_dir=None) -> dict:
    """The measure of the module docstring for one render setting.

    The frames are the study's own: at each of ``sweeps`` (bracket sweeps of the walk of scene
    seed ``walk_seed``, 273 ms each), the left camera's shot of each bracket in ``exposures_ms``,
    integrated over its exposure window (``render_per="cycle"``: one render per sweep warped to
    its shots, the live study's setting; ``"shot"``: one render per shot) or ``"still"`` (a plain
    render at the shot's trigger instant, no warp, no blur).  Two walks with render seeds
    ``render_seeds`` give the two renders.

    Returns
    -------
    dict
        ``setting``, ``spp``, ``denoise`` (its settings), ``render_per``, ``seconds_per_sweep``
        (wall seconds of the renders, warps included, per sweep and camera: median over the
        sweeps that were not all cache hits; None when all were), ``per_pose`` rows and, per
        exposure (key ``"8"``, ``"32"``...), ``render_only``, ``sensor_only`` and ``difference``
        as (mean, low, high) over the sweeps, and ``met``.
    """
    import scenes
    from scenes.image_stats import synthetic_camera

    preset = _preset(setting)
    label, spp, settings = str(setting), preset.spp, preset.denoise
    if len(render_seeds) != 2 or render_seeds[0] == render_seeds[1]:
        raise ValidationError(f"need two distinct render seeds, got {list(render_seeds)}")
    if not sweeps:
        raise ValidationError("need at least one bracket sweep")
    if render_per not in ("cycle", "shot", "still"):
        raise ValidationError(f"render_per must be cycle, shot or still, got {render_per!r}")
    missing = [e for e in exposures_ms if float(e) not in _BRACKETS_MS]
    if missing:
        raise ValidationError(f"exposures {missing} are not brackets of the sweep ({', '.join(f'{b:g}' for b in _BRACKETS_MS)} ms)")
    spec = study_scene(scene_key)
    scene = preset.scene(scenes.get_scene(spec.scene, seed=walk_seed, **dict(spec.params)))
    traj = scene.trajectory((max(sweeps) + 1) * len(_BRACKETS_MS) / _FPS + 1.0)
    camera = synthetic_camera(scene, width, height)
    sources = [_shot_source(scene, traj, width=width, height=height, spp=spp, settings=settings,
                            fov_deg=camera.fov_x_deg, render_seed=int(r), render_per=render_per, cache_dir=cache_dir,
                            adaptive=preset.adaptive)
               for r in render_seeds]
    rows, seconds = [], []
    for sweep in sweeps:
        t0 = time.perf_counter()
        got = {float(e): [src(int(sweep) * len(_BRACKETS_MS) + _BRACKETS_MS.index(float(e)), float(e))
                          for src in sources] for e in exposures_ms}
        if not all(hit for pair in got.values() for _, hit in pair):  # a sweep read from the cache times nothing
            seconds.append((time.perf_counter() - t0) / len(sources))
        imgs = {e: [img for img, _ in pair] for e, pair in got.items()}
        for e, (a, b) in imgs.items():
            rows.append({"sweep": int(sweep), "exposure_ms": e,
                         **balance_at_pose(a, b, scene, camera, exposure_ms=e, sensor_seeds=sensor_seeds)})
    out = {"setting": label, "scene": scene_key, "size": [int(width), int(height)], "spp": spp,
           "denoise": settings.key_material() if settings.enabled else {"name": "off"}, "render_per": render_per,
           **({"emitter_weights": dict(preset.emitter_weights)} if preset.emitter_weights else {}),
           **({"adaptive": preset.adaptive.key_material()} if preset.adaptive is not None else {}),
           "seconds_per_sweep": float(np.median(seconds)) if seconds else None,
           "sweeps_timed": len(seconds), "tolerance_points": tolerance,
           "goal": "the whole 95 % interval of the difference at or above -tolerance_points",
           "per_pose": rows, "exposures": {}}
    for e in exposures_ms:
        sel = [r for r in rows if r["exposure_ms"] == float(e)]
        diff = t_interval([r["render_only"] - r["sensor_only"] for r in sel])
        out["exposures"][f"{float(e):g}"] = {
            "render_only": t_interval([r["render_only"] for r in sel]),
            "sensor_only": t_interval([r["sensor_only"] for r in sel]),
            "difference": diff, "met": _whole_interval_at_least(diff, -tolerance)}
    out["met"] = all(v["met"] for v in out["exposures"].values())
    return out


def _whole_interval_at_least(interval, floor: float) -> bool:
    """True when the (mean, low, high) interval's low end is finite and at or above ``floor``."""
    low = interval[1]
    return bool(low is not None and np.isfinite(low) and low >= floor)


def _cell(v) -> str:
    m, lo, hi = v
    if lo is None or hi is None or not (np.isfinite(lo) and np.isfinite(hi)):
        return f"{m:+.1f}"
    return f"{m:+.1f} [{lo:+.1f}, {hi:+.1f}]"


def pareto_table(results) -> str:
    """Markdown table of :func:`noise_balance` results: per scene and setting, the difference (points) at each
    exposure, whether the whole interval meets the goal, seconds per sweep and the ratio to the baseline; the
    settings on each scene's Pareto front (no other setting both cheaper and closer at every exposure) marked."""
    rows = list(results)
    exposures = sorted({e for r in rows for e in r["exposures"]}, key=float)
    bias = any("radiance" in r for r in rows)
    head = ["scene", "setting"] + [f"{e} ms: render-only minus sensor-only" for e in exposures] + [
        "whole interval >= -3"] + (["mean radiance vs reference, % (sun disk excluded)"] if bias else []) + [
        "s per sweep", "x baseline", "Pareto"]
    out = ["| " + " | ".join(head) + " |", "|" + " --- |" * 2 + " ---: |" * (len(head) - 2)]

    def worst(r):
        return min(r["exposures"][e]["difference"][0] for e in exposures)

    for r in rows:
        peers = [q for q in rows if q["scene"] == r["scene"] and q is not r]
        timed = [q for q in peers if q["seconds_per_sweep"] is not None]
        front = r["seconds_per_sweep"] is not None and not any(  # a setting read from the cache has no seconds
            q["seconds_per_sweep"] <= r["seconds_per_sweep"] and worst(q) >= worst(r) and (
                q["seconds_per_sweep"] < r["seconds_per_sweep"] or worst(q) > worst(r)) for q in timed)
        whole = all(_whole_interval_at_least(r["exposures"][e]["difference"], -r["tolerance_points"])
                    for e in exposures)
        ratio = r.get("ratio_to_baseline")
        out.append("| " + " | ".join([r["scene"], f"`{r['setting']}`"]
                                     + [_cell(r["exposures"][e]["difference"]) for e in exposures]
                                     + ["yes" if whole else "no"]
                                     + ([_cell(r["radiance"]["difference_percent_sun_excluded"])
                                         if "radiance" in r else ""] if bias else [])
                                     + ["cached" if r["seconds_per_sweep"] is None else f"{r['seconds_per_sweep']:.2f}",
                                        "" if ratio is None else f"{ratio:.2f}",
                                        "front" if front else ""]) + " |")
    return "\n".join(out)


def radiance_bias(setting: str, *, scene_key: str = "forest_winter", reference: str = "off@256", width: int = 480,
                  height: int = 300, sweeps=(0, 22, 44), walk_seed: int = 0, cache_dir=None,
                  reference_cache_dir=None) -> dict:
    """Mean radiance of a render setting against a deep reference, at the walk's poses.

    At each of ``sweeps`` (the pose of the sweep's first shot, a still render), the mean
    luminance (Rec. 709) of the setting's render (render seed 1) and of the reference's
    (render seed 2, e.g. raw at 256 spp, whose mean over the frame carries well under 0.1 %
    of Monte Carlo error), over the whole frame and without the pixels above the denoiser's
    pass-through level (:data:`scenes.denoise.PASSTHROUGH_RADIANCE` times the scene's reference
    radiance: the sun disk and its glints, whose few pixels carry most of a frame's mean and
    its Monte Carlo error where the sun is in view).  ``reference_cache_dir``: where the reference renders are cached
    (default ``cache_dir``).

    Returns
    -------
    dict
        ``setting``, ``reference``, ``scene``, ``per_pose`` (sweep, both means, relative
        difference in percent, the same without the sun disk, how many pixels that leaves out),
        ``difference_percent`` and ``difference_percent_sun_excluded`` (mean, low, high: Student-t
        95 % over the poses), ``seconds`` (the setting's render, median over the poses).
    """
    import scenes
    from scenes.dynamic_range import luminance
    from scenes.image_stats import synthetic_camera
    from scenes.walkshots import shot_time_s

    test, ref = _preset(setting), _preset(reference)
    spec = study_scene(scene_key)
    base = scenes.get_scene(spec.scene, seed=walk_seed, **dict(spec.params))
    traj = base.trajectory((max(sweeps) + 1) * len(_BRACKETS_MS) / _FPS + 1.0)
    fov = synthetic_camera(base, width, height).fov_x_deg
    from scenes.denoise import PASSTHROUGH_RADIANCE

    bright = PASSTHROUGH_RADIANCE * float(base.reference_radiance)
    rows, seconds = [], []
    for sweep in sweeps:
        pose = traj.pose(shot_time_s(int(sweep) * len(_BRACKETS_MS), _FPS))
        means, lums = [], []
        for preset, seed, folder in ((test, 1, cache_dir),
                                     (ref, 2, cache_dir if reference_cache_dir is None else reference_cache_dir)):
            t0 = time.perf_counter()
            img = scenes.render(preset.scene(base), pose, width=width, height=height, spp=preset.spp, seed=seed,
                                fov_deg=fov, denoise=preset.denoise, cache_dir=folder, adaptive=preset.adaptive)
            if preset is test:
                seconds.append(time.perf_counter() - t0)
            lums.append(luminance(img))
            means.append(float(np.mean(lums[-1])))
        keep = np.maximum(*lums) < bright  # the sun disk and its glints: the denoiser passes them through raw
        dim = [float(np.mean(x[keep])) for x in lums]
        rows.append({"sweep": int(sweep), "mean": means[0], "reference_mean": means[1],
                     "difference_percent": 100.0 * (means[0] / means[1] - 1.0),
                     "sun_excluded_pixels": int(keep.size - keep.sum()),
                     "difference_percent_sun_excluded": 100.0 * (dim[0] / dim[1] - 1.0)})
    return {"setting": str(setting), "reference": str(reference), "scene": scene_key, "size": [width, height],
            "per_pose": rows, "difference_percent": t_interval([r["difference_percent"] for r in rows]),
            "difference_percent_sun_excluded": t_interval([r["difference_percent_sun_excluded"] for r in rows]),
            "seconds": float(np.median(seconds))}
