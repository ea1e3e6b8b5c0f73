"""Render a scene along a trajectory and write a BorealHDR-layout dataset through ``synth``.

This is the glue between the two synthetic layers: Mitsuba radiance (``scenes.render``,
cached on disk) at every shot's own timestamp and pose, captured by a
:class:`synth.Camera` (``synth.capture_sequence``), so motion between brackets is real.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from emulator.errors import ExposimError
from scenes.camera import DEFAULT_SATURATE_MS
from scenes.adaptive import AdaptiveSampling, as_adaptive
from scenes.denoise import effective_denoise
from scenes.walks import CAMERA_FROM_IMU, DEFAULT_WALK
from scenes.walkshots import WalkShots

__all__ = ["synthesize"]


def synthesize(
    scene,
    out_dir,
    *,
    n_cycles: int = 4,
    width: int = 160,
    height: int = 100,
    spp: int = 16,
    camera="borealhdr",
    saturate_ms: float = DEFAULT_SATURATE_MS,
    brackets_ms=(1.0, 2.0, 4.0, 8.0, 16.0, 32.0),
    fps: float = 22.0,
    stereo: bool = True,
    baseline_m: float | None = None,
    seed: int = 0,
    render_seed: int = 0,
    noise: bool = True,
    gt_exposures_ms=(),
    gt_captures: str = "noiseless",
    gt_cameras=None,
    save_radiance: bool = False,
    start_time_ns: int = 1_700_000_000_000_000_000,
    speed_mps: float | None = None,
    walk: str | None = None,
    blur: bool = True,
    render_per: str = "shot",
    integrate: bool = True,
    margin_step_px: int = 1,
    max_window_ms: float | None = None,
    imu_rate_hz: float = 100.0,
    cache_dir=None,
    variant: str | None = None,
    denoise=None,
    adaptive=None,
    overwrite: bool = False,
    progress=None,
    scheduler: str | None = None,
    render_progress=None,
) -> Path:
    """Synthesise a bracketed recording of ``scene`` with exact ground truth.

    Parameters
    ----------
    scene : scenes.Scene or str
        The scene (a name takes default parameters and seed 0).
    out_dir : path
        Dataset folder to create (refused if it exists, unless ``overwrite``).
    n_cycles : int
        Number of full bracket sweeps (6 shots each at 22 frames/s: 273 ms per cycle).
    width, height : int
        Image size in pixels (the camera preset is resized; intrinsics follow the FOV).
    spp : int
        Render samples per pixel.
    camera : str or synth.Camera
        A preset name or a camera; its ``radiance_scale`` is set so that the scene's
        reference radiance (white surface facing the sun) saturates at ``saturate_ms``.
    speed_mps : float, optional
        Walking speed (default: the trajectory's 2 km/h).
    walk : str, optional
        The walk (:func:`scenes.walks.make_walk`): ``"borealhdr"`` (default: turns like the
        BorealHDR backpack), ``"gentle"`` or ``"replay:PATH"``.
    blur : bool
        Integrate every capture over its own exposure window ``[t, t + exposure]`` along the
        walk (:class:`scenes.blur.ShotRenderer`: one render per shot and camera at the middle
        of the longest window, warped to the sub-instants the predicted blur asks for); a
        shot at rest is one plain render.  False: the scene at the trigger instant (no blur).
        Static scenes never blur.
    render_per : str
        With ``blur``: ``"shot"`` (one render per shot and camera) or ``"cycle"`` (one render
        per bracket sweep and camera, at the sweep's middle with a margin for the sweep's
        motion, warped to every shot's sub-instants: a sixth of the renders, so six times the
        spp at the same cost; render noise then moves with the scene within a sweep).
    integrate : bool
        With ``blur``: False samples every shot at its trigger instant from the same warped
        renders (no exposure-time blur, same render noise: the sharp twin of a blurred walk).
    margin_step_px : int
        With ``blur``: round every render's margin up to a multiple of this many pixels, so the
        walk's renders share a few image sizes (each new size costs a kernel compilation).
    max_window_ms : float, optional
        With ``blur``: the longest exposure window every shot's render is sized for (default:
        the longest bracket or ground-truth exposure).  A live capture longer than that gets a
        render of its own, so a closed loop whose exposures reach beyond the brackets (AE clamp
        ranges reach 50 ms) renders less when its walk is sized for its range.
    imu_rate_hz : float
        Rate of the walk's gyro and accelerometer written as ``imu/imu.csv`` (IMU frame x
        forward, y left, z up: :data:`scenes.walks.CAMERA_FROM_IMU`; a static camera reads zero rates and
        gravity; 0: none).
    denoise : str or scenes.denoise.DenoiseSettings, optional
        ``"oidn"``: low-spp render denoised by Open Image Denoise; ``"off"``: the raw
        path-traced estimate (see :func:`scenes.render`).  Default (None): ``"oidn"``, or
        ``$EXPOSIM_DENOISE`` when set.  When OIDN cannot run
        here, a :class:`scenes.denoise.DenoiserUnavailableWarning` says why, every frame
        is the raw estimate and the dataset's description records the reason.
    adaptive : str or scenes.adaptive.AdaptiveSampling, optional
        A spatially adaptive sample count for every render (``"x16:20%@32ms"``,
        :mod:`scenes.adaptive`); recorded in the description only when set.
    scheduler : str, optional
        ``"local"`` or ``"tcp://HOST:PORT"``: render every shot first as a Dask task
        (:mod:`scenes.parallel`), then capture; the renders land in the same cache
        entries and the dataset has the same bytes as without a scheduler (None: render
        shot by shot while capturing).
    render_progress : callable, optional
        With a scheduler: called with 1 after each rendered shot.
    Other parameters go to :func:`synth.capture_sequence` (noise, ground-truth captures and their cameras,
    radiance EXRs) and :func:`scenes.render` (cache, variant).

    Returns
    -------
    Path of the written dataset.
    """
    from scenes.variant import choose_variant
    import synth
    from scenes import trajectory as tr

    scene, cam = _scene_and_camera(scene, camera, width, height, n_cycles, saturate_ms)
    baseline = tr.BASELINE_M if baseline_m is None else float(baseline_m)

    n_shots = n_cycles * len(brackets_ms)
    duration_s = n_shots / fps + 1.0
    walk_kwargs = {} if speed_mps is None else {"speed_mps": float(speed_mps)}
    traj = scene.trajectory(duration_s, walk=walk, **walk_kwargs)
    imu = None if not imu_rate_hz else _imu_of(traj, n_shots / fps + 0.1, imu_rate_hz, start_time_ns)
    blur = bool(blur) and not scene.is_static
    if render_per not in ("shot", "cycle"):
        raise ExposimError(f"render_per must be 'shot' or 'cycle', got {render_per!r}")
    render_variant = variant or choose_variant()
    settings, fallback = effective_denoise(denoise)
    adaptive = as_adaptive(adaptive)
    render = dict(width=width, height=height, spp=spp, fov_deg=cam.fov_x_deg, cache_dir=cache_dir,
                  variant=render_variant, denoise=settings, adaptive=adaptive)
    shots = WalkShots(scene, traj, render=dict(render, render_seed=render_seed), fps=fps, n_brackets=len(brackets_ms),
                      max_window_ms=_window_ms(brackets_ms, gt_exposures_ms, max_window_ms), baseline_m=baseline,
                      render_per=render_per, integrate=integrate, margin_step_px=margin_step_px)
    source, blurred_source, render_job, shot_renderer, prefetched = _providers(
        scene, traj, shots, baseline_m=baseline, render_seed=render_seed, render=render)
    if scheduler is not None:
        job_of = (lambda t, side, idx: shot_renderer(t, side).render_job()) if blur else render_job
        _prefetch(job_of, prefetched, keep=not blur, scheduler=scheduler, cache_dir=cache_dir, n_shots=n_shots,
                  brackets_ms=brackets_ms, fps=fps, start_time_ns=start_time_ns, stereo=stereo,
                  progress=render_progress)
    description = _description(scene, cam, shots, width=width, height=height, spp=spp, render_seed=render_seed,
                               variant=render_variant, denoise=settings, fallback=fallback, adaptive=adaptive,
                               blur=blur, render_per=render_per, saturate_ms=saturate_ms, speed_mps=speed_mps,
                               walk=walk, imu=imu, imu_rate_hz=imu_rate_hz)
    return synth.capture_sequence(
        blurred_source if blur else source, out_dir, cam, brackets_ms=tuple(brackets_ms), fps=fps, n_cycles=n_cycles,
        stereo=stereo, baseline_m=baseline, seed=seed, noise=noise, gt_exposures_ms=tuple(gt_exposures_ms),
        gt_captures=gt_captures, gt_cameras=gt_cameras, save_radiance=save_radiance, overwrite=overwrite,
        progress=progress, start_time_ns=start_time_ns, source_description=description, imu=imu,
    )


def _scene_and_camera(scene, camera, width: int, height: int, n_cycles: int, saturate_ms: float):
    """The scene (a name takes its defaults) and the camera resized to ``width`` x ``height`` and scaled to
    saturate on the scene's reference radiance at ``saturate_ms``, the arguments checked."""
    from scenes.base import get_scene
    import synth

    if isinstance(scene, str):
        scene = get_scene(scene)
    if n_cycles < 1:
        raise ExposimError(f"n_cycles must be >= 1, got {n_cycles}")
    if not (math.isfinite(saturate_ms) and saturate_ms > 0):
        raise ExposimError(f"saturate_ms must be finite and positive, got {saturate_ms!r}")
    cam = synth.Camera.preset(camera, width=width, height=height) if isinstance(camera, str) else camera
    return scene, cam.replace(width=width, height=height).saturating_at(scene.reference_radiance, saturate_ms)


def _window_ms(brackets_ms, gt_exposures_ms, max_window_ms) -> float:
    longest = max(list(brackets_ms) + list(gt_exposures_ms))
    if max_window_ms is None:
        return float(longest)
    if not (isinstance(max_window_ms, (int, float)) and math.isfinite(max_window_ms) and max_window_ms >= longest):
        raise ExposimError(f"max_window_ms must be a number >= the longest exposure ({longest:g} ms), "
                           f"got {max_window_ms!r}")
    return float(max_window_ms)


def _providers(scene, traj, shots: WalkShots, *, baseline_m: float, render_seed: int, render: dict):
    """The radiance providers of one synthesis and what serves them.

    Returns ``(source, blurred_source, render_job, shot_renderer, prefetched)``: ``source``
    renders the scene at a shot's trigger instant (or takes the shot's image from
    ``prefetched``, keyed by rounded timestamp and camera); ``blurred_source`` integrates
    over the shot's exposure window (:class:`scenes.walkshots.WalkShots`);
    ``render_job(t, camera, index)`` is the :func:`scenes.render` arguments of one shot and
    ``shot_renderer(t, camera)`` the :class:`scenes.blur.ShotRenderer` of a blurred one.
    Shots are numbered in the order they are first asked for.
    """
    from scenes.render import render as render_radiance
    from scenes import trajectory as tr

    shot_index: dict[float, int] = {}
    prefetched: dict = {}

    def render_job(timestamp_s: float, camera_name: str, idx: int) -> dict:
        """The :func:`scenes.render` arguments of one shot (serial and Dask paths alike)."""
        pose = traj.pose(timestamp_s)
        if camera_name == "right":
            pose = tr.stereo_right(pose, baseline_m)
        frame_seed = (int(render_seed) * 1_000_003 + 2 * idx + (camera_name == "right")) % (1 << 32)
        return dict(scene=scene, pose=pose, width=render["width"], height=render["height"], spp=render["spp"],
                    seed=frame_seed, fov_deg=render["fov_deg"], cache_dir=render["cache_dir"],
                    variant=render["variant"], denoise=render["denoise"], adaptive=render["adaptive"])

    def shot_renderer(timestamp_s: float, camera_name: str):
        """The :class:`scenes.blur.ShotRenderer` serving one shot (or its whole cycle) and camera."""
        return shots.renderer(shot_index.setdefault(round(timestamp_s, 9), len(shot_index)), camera_name)

    def blurred_source(timestamp_s: float, camera_name: str, exposure_ms: float):
        idx = shot_index.setdefault(round(timestamp_s, 9), len(shot_index))
        pose = shots.poses(camera_name)(np.array([timestamp_s]))[0]
        return shots.radiance(idx, camera_name, exposure_ms), pose

    blurred_source.exposure_aware = True
    blurred_source.timestamps_note = ("trigger instant of each shot = start of its exposure; every capture "
                                      "integrates the radiance over [t, t + exposure] along the trajectory "
                                      "(scenes.blur); poses are at the trigger instant")
    if not shots.integrate:
        blurred_source.timestamps_note = ("trigger instant of each shot; the scene is sampled there (no motion "
                                          "blur), warped from the walk's renders (scenes.blur)")

    def source(timestamp_s: float, camera_name: str):
        idx = shot_index.setdefault(round(timestamp_s, 9), len(shot_index))
        job = render_job(timestamp_s, camera_name, idx)
        radiance = prefetched.pop((round(timestamp_s, 9), camera_name), None)
        if radiance is None:
            radiance = render_radiance(**job)
        return radiance, np.asarray(job["pose"], dtype=np.float64)

    return source, blurred_source, render_job, shot_renderer, prefetched


def _prefetch(job_of, prefetched: dict, *, keep: bool, scheduler: str, cache_dir, n_shots: int, brackets_ms,
              fps: float, start_time_ns: int, stereo: bool, progress) -> None:
    """Render every shot first as a Dask task (:func:`scenes.parallel.render_many`).

    ``job_of(t, camera, index)`` gives a shot's render arguments.  The renders land in the
    cache; without a cache folder and with ``keep``, they go into ``prefetched`` for the
    capture to take.
    """
    from scenes.cache import resolve_cache_dir
    from scenes.parallel import check_scheduler, render_many
    from synth.sequence import shot_schedule

    check_scheduler(scheduler)
    folder = resolve_cache_dir(cache_dir)
    schedule = shot_schedule(n_shots, brackets_ms=brackets_ms, fps=fps, start_time_ns=start_time_ns)
    keys = [(s.time_s, side, s.index) for s in schedule for side in (("left", "right") if stereo
                                                                      else ("left",))]
    jobs = []
    for t, side, idx in keys:
        job = job_of(t, side, idx)
        job["cache_dir"] = False if folder is None else folder  # explicit: a worker decides nothing
        jobs.append(job)
    for (t, side, _), image in zip(keys, render_many(jobs, scheduler=scheduler, progress=progress)):
        if folder is None and keep:  # no cache to read them back from: keep them for the capture
            prefetched[(round(t, 9), side)] = image


def _description(scene, cam, shots: WalkShots, *, width: int, height: int, spp: int, render_seed: int, variant: str,
                 denoise, fallback, adaptive: AdaptiveSampling | None, blur: bool, render_per: str, saturate_ms: float,
                 speed_mps, walk, imu, imu_rate_hz: float) -> dict:
    """The dataset's source description (``exposim.json``): scene, render settings, trajectory, IMU."""
    return {
        "generator": "scenes.synthesize",
        "scene": scene.key_material(),
        "scene_description": scene.description,
        "render": {"width": width, "height": height, "spp": spp, "render_seed": render_seed,
                   "variant": variant, "fov_deg": cam.fov_x_deg,
                   "denoise": denoise.key_material(), "denoise_fallback": fallback,
                   # only when set: the descriptions of earlier datasets stay as they were
                   **({} if adaptive is None else {"adaptive": adaptive.text}),
                   "exposure_integration": ("none (trigger instant)" if not blur else
                                            f"scenes.blur (warped sub-instants of one render per {render_per})"
                                            if shots.integrate else
                                            f"none (trigger instant, warped from one render per {render_per})"),
                   "blur_shots": shots.describe() if blur else None},
        "saturate_ms": saturate_ms,
        "trajectory": {"static": scene.is_static, "speed_mps": speed_mps,
                       "walk": None if scene.is_static else (walk or DEFAULT_WALK)},
        "imu": _imu_description(imu, imu_rate_hz),
    }


def _imu_description(imu, rate_hz: float) -> dict | None:
    """The ``imu`` entry of the dataset's description (None: no IMU written)."""
    if imu is None:
        return None
    return {"file": "imu/imu.csv", "rate_hz": float(rate_hz),
            "frame": "x forward, y left, z up (rigid with the left camera)",
            "camera_from_imu": CAMERA_FROM_IMU.tolist()}


def _imu_of(traj, end_s: float, rate_hz: float, start_time_ns: int):
    """The walk's IMU samples (:func:`scenes.walks.imu_samples`) on the recording's clock."""
    from emulator.io.imu import ImuData
    from scenes.walks import imu_samples

    t, gyro, acc = imu_samples(traj, rate_hz, t1_s=min(end_s, traj.duration_s))
    stamps = int(start_time_ns) + np.round(t * 1e9).astype(np.int64)
    return ImuData(timestamp_ns=stamps, gyro_rad_s=gyro, acc_m_s2=acc, ros_time_ns=stamps.copy())
