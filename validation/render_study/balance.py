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
sets the spp of the albedo/normal pass (:class:`scenes.denoise.DenoiseSettings`).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from validation.common import ValidationError

__all__ = ["GOAL_TOLERANCE_POINTS", "parse_setting", "t_interval", "balance_at_pose", "noise_balance"]

#: Render-only repeatability may be this many points below sensor-only (the issue's goal).
GOAL_TOLERANCE_POINTS = 3.0


def parse_setting(text: str):
    """``"oidn-fast@2"`` / ``"oidn@8/32"`` / ``"off@64"`` -> (label, spp, denoise settings).

    Raises
    ------
    ValidationError
        Malformed text, unknown denoiser, spp or albedo/normal spp not a positive integer.
    """
    from scenes.denoise import resolve_denoise
    from scenes.errors import RenderError

    name, sep, rest = str(text).partition("@")
    spp_text, slash, aux_text = rest.partition("/")
    if not sep or not spp_text.isdigit() or int(spp_text) < 1 or (slash and not aux_text.isdigit()):
        raise ValidationError(f"render setting {text!r}: expected DENOISER@SPP or DENOISER@SPP/AUX_SPP, "
                              f"e.g. oidn-fast@2 or oidn@8/32")
    try:
        settings = resolve_denoise(name)
        if slash:
            settings = replace(settings, aux_spp=int(aux_text))
    except RenderError as exc:
        raise ValidationError(f"render setting {text!r}: {exc}") from None
    if slash and not settings.enabled:
        raise ValidationError(f"render setting {text!r}: an albedo/normal spp needs a denoiser")
    return str(text), int(spp_text), settings


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
                 render_per: str, cache_dir):
    """``(index, exposure_ms) -> radiance`` of the left camera: the study's shots, or still renders."""
    import scenes
    from scenes.walkshots import WalkShots, shot_time_s

    if render_per == "still":
        def still(index, exposure_ms):
            return scenes.render_with_info(scene, traj.pose(shot_time_s(index, _FPS)), width=width, height=height,
                                           spp=spp, seed=render_seed * 1_000_003 + 2 * index, fov_deg=fov_deg,
                                           denoise=settings, cache_dir=cache_dir)[0]
        return still
    shots = WalkShots(scene, traj, render=dict(width=width, height=height, spp=spp, fov_deg=fov_deg,
                                               cache_dir=cache_dir, variant=None, denoise=settings,
                                               render_seed=render_seed),
                      fps=_FPS, n_brackets=len(_BRACKETS_MS), max_window_ms=max(_BRACKETS_MS), baseline_m=0.0,
                      render_per=render_per)
    return lambda index, exposure_ms: shots.radiance(index, "left", exposure_ms)


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
    from validation.common import study_scene

    label, spp, settings = parse_setting(setting)
    if len(render_seeds) != 2 or render_seeds[0] == render_seeds[1]:
        raise ValidationError(f"need two distinct render seeds, got {list(render_seeds)}")
    if not sweeps:
        raise ValidationError("need at least one bracket sweep")
    if render_per not in ("cycle", "shot", "still"):
        raise ValidationError(f"render_per must be cycle, shot or still, got {render_per!r}")
    missing = [e for e in exposures_ms if float(e) not in _BRACKETS_MS]
    if missing:
        raise ValidationError(f"exposures {missing} are not brackets of the sweep ({', '.join(f'{b:g}' for b in _BRACKETS_MS)} ms)")
    scene = scenes.get_scene(study_scene(scene_key).scene, seed=walk_seed)
    traj = scene.trajectory((max(sweeps) + 1) * len(_BRACKETS_MS) / _FPS + 1.0)
    camera = synthetic_camera(scene, width, height)
    sources = [_shot_source(scene, traj, width=width, height=height, spp=spp, settings=settings,
                            fov_deg=camera.fov_x_deg, render_seed=int(r), render_per=render_per, cache_dir=cache_dir)
               for r in render_seeds]
    rows, seconds = [], []
    for sweep in sweeps:
        t0 = time.perf_counter()
        imgs = {float(e): [src(int(sweep) * len(_BRACKETS_MS) + _BRACKETS_MS.index(float(e)), float(e))
                           for src in sources] for e in exposures_ms}
        seconds.append((time.perf_counter() - t0) / len(sources))
        for e, (a, b) in imgs.items():
            rows.append({"sweep": int(sweep), "exposure_ms": e,
                         **balance_at_pose(a, b, scene, camera, exposure_ms=e, sensor_seeds=sensor_seeds)})
    out = {"setting": label, "scene": scene_key, "size": [int(width), int(height)], "spp": spp,
           "denoise": settings.key_material() if settings.enabled else {"name": "off"}, "render_per": render_per,
           "seconds_per_sweep": float(np.median(seconds)), "tolerance_points": tolerance,
           "per_pose": rows, "exposures": {}}
    for e in exposures_ms:
        sel = [r for r in rows if r["exposure_ms"] == float(e)]
        diff = t_interval([r["render_only"] - r["sensor_only"] for r in sel])
        out["exposures"][f"{float(e):g}"] = {
            "render_only": t_interval([r["render_only"] for r in sel]),
            "sensor_only": t_interval([r["sensor_only"] for r in sel]),
            "difference": diff, "met": bool(diff[0] >= -tolerance)}
    out["met"] = all(v["met"] for v in out["exposures"].values())
    return out
