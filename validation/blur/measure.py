"""The blur study's measurements (numpy; renders through :mod:`scenes`)."""

from __future__ import annotations

import time

import numpy as np

from validation.common import capture, rmse_dn, to_percent

__all__ = ["consistent_from_walk", "rate_percentiles_deg_s", "angular_rate_ratio", "fastest_instants", "reference_comparison",
           "cost_comparison", "sharpness", "sharpness_comparison", "source_and_live", "against_live", "walk_omega"]

_PERCENTILES = (50, 90, 99)


def rate_percentiles_deg_s(omega_rad_s: np.ndarray) -> dict:
    """p50, p90, p99 of |omega| in deg/s of (N, 3) rates."""
    speed = np.degrees(np.linalg.norm(np.asarray(omega_rad_s, dtype=np.float64), axis=1))
    return {f"p{q}": float(np.percentile(speed, q)) for q in _PERCENTILES}


def angular_rate_ratio(traj, walk_s: float, real_imu: str | None) -> dict:
    """The walk's |omega| percentiles (100 Hz over ``walk_s``), the real gyro's and their ratios."""
    from scenes.walks import angular_velocity, read_gyro_csv

    syn = rate_percentiles_deg_s(angular_velocity(traj, np.arange(0.0, walk_s, 0.01)))
    out = {"synthetic_deg_s": syn, "real_deg_s": None, "ratio": None, "real_imu": real_imu}
    if real_imu is not None:
        real = rate_percentiles_deg_s(read_gyro_csv(real_imu)[1])
        out.update(real_deg_s=real, ratio={k: syn[k] / real[k] for k in syn})
    return out


def fastest_instants(traj, walk_s: float, n: int, exposure_ms: float, *, min_gap_s: float = 0.3) -> list[float]:
    """Start times of the ``n`` exposure windows with the fastest mean turn, ``min_gap_s`` apart."""
    from scenes.walks import angular_velocity

    t = np.arange(0.5, walk_s - 1.0, 0.01)
    speed = np.linalg.norm(angular_velocity(traj, t + 0.5e-3 * exposure_ms), axis=1)
    chosen: list[float] = []
    for i in np.argsort(speed)[::-1]:
        if all(abs(t[i] - c) >= min_gap_s for c in chosen):
            chosen.append(float(t[i]))
        if len(chosen) == n:
            break
    return sorted(chosen)


def _dn(radiance, camera, exposure_ms):
    return capture(radiance, exposure_ms, camera, seed=0, noise=False)


def reference_comparison(scene, traj, t0_s: float, cfg, camera) -> dict:
    """Blurred shot (two render seeds) against a brute-force reference (two independent halves), in DN.

    The reference is the mean of ``reference_subinstants`` renders per half at the midpoints
    of the window, each at ``reference_spp``, raw; its own noise is half the RMS difference
    of the halves.  The method's noise is the RMS difference of its two seeds over sqrt 2.
    All in percent of the DN range, noiseless captures at ``exposure_ms``.
    """
    import scenes
    from scenes.blur import render_exposure, subinstant_times_s

    t1 = t0_s + 1e-3 * cfg.exposure_ms
    kw = dict(width=cfg.width, height=cfg.height, denoise="off", cache_dir=cfg.cache_dir,
              fov_deg=camera.fov_x_deg)
    times = subinstant_times_s(t0_s, t1, cfg.reference_subinstants)
    halves = []
    for h in range(2):
        acc = np.zeros((cfg.height, cfg.width, 3))
        for i, t in enumerate(times):
            acc += scenes.render(scene, traj.pose(t), spp=cfg.reference_spp, seed=cfg.seed + 1000 * (h + 1) + i, **kw)
        halves.append(acc / len(times))
    ref = (0.5 * (halves[0] + halves[1])).astype(np.float32)
    methods = [render_exposure(scene, traj.poses, t0_s, t1, spp=cfg.spp, seed=cfg.seed + s, **kw) for s in (1, 2)]
    sharp = scenes.render(scene, traj.pose(0.5 * (t0_s + t1)), spp=cfg.spp, seed=cfg.seed + 3, **kw)
    white, black = camera.white_level, camera.black_level
    pct = lambda v: float(to_percent(v, white, black))  # noqa: E731
    d_ref, d_h = _dn(ref, camera, cfg.exposure_ms), [_dn(h.astype(np.float32), camera, cfg.exposure_ms) for h in halves]
    d_m = [_dn(m[0], camera, cfg.exposure_ms) for m in methods]
    ref_noise = pct(rmse_dn(d_h[0], d_h[1])) / 2.0
    method_noise = pct(rmse_dn(d_m[0], d_m[1])) / np.sqrt(2.0)
    err = pct(rmse_dn(d_m[0], d_ref))
    expected = float(np.hypot(ref_noise, method_noise))
    return {"t0_s": t0_s, "blur_px": methods[0][1]["blur_px"], "n_subinstants": methods[0][1]["n_subinstants"],
            "by_subinstants": _by_subinstants(scene, traj, t0_s, cfg, kw, d_ref, camera),
            "by_interpolation": _by_interpolation(scene, traj, t0_s, cfg, kw, d_ref, ref_noise, camera),
            "error_percent": err, "reference_noise_percent": ref_noise, "method_noise_percent": method_noise,
            "expected_noise_percent": expected, "error_over_noise": err / expected if expected > 0 else None,
            "excess_percent": float(np.sqrt(max(err * err - expected * expected, 0.0))),
            "no_blur_error_percent": pct(rmse_dn(_dn(sharp, camera, cfg.exposure_ms), d_ref))}


def _by_subinstants(scene, traj, t0_s, cfg, kw, d_ref, camera) -> list[dict]:
    """Error against the reference and warp seconds for 1, 2, 4, ... sub-instants (one render, reused)."""
    from scenes.blur import ShotRenderer

    shot = ShotRenderer(scene, traj.poses, t0_s, cfg.exposure_ms, spp=cfg.spp, seed=cfg.seed + 1, **kw)
    rows = []
    for n in (1, 2, 4, 8, 16, 32):
        before = shot.info["warp_s"]
        img = shot.radiance(cfg.exposure_ms, n_subinstants_override=n)[0]
        err = rmse_dn(_dn(img, camera, cfg.exposure_ms), d_ref)
        rows.append({"n_subinstants": n, "error_percent": float(to_percent(err, camera.white_level,
                                                                           camera.black_level)),
                     "warp_s": shot.info["warp_s"] - before})
    return rows


def _by_interpolation(scene, traj, t0_s, cfg, kw, d_ref, ref_noise, camera) -> list[dict]:
    """Error against the reference, its noise and the ratio, per resampler of the warps (the same two renders)."""
    from scenes.blur import INTERPOLATIONS, ShotRenderer

    pct = lambda v: float(to_percent(v, camera.white_level, camera.black_level))  # noqa: E731
    rows = []
    for name, ss in [(n, 1) for n in INTERPOLATIONS] + [("linear", 2)]:
        shots = [ShotRenderer(scene, traj.poses, t0_s, cfg.exposure_ms, spp=cfg.spp, seed=cfg.seed + s,
                              supersample=ss, **kw) for s in (1, 2)]
        before = shots[0].info["warp_s"]
        d = [_dn(sh.radiance(cfg.exposure_ms, interpolation=name)[0], camera, cfg.exposure_ms) for sh in shots]
        warp_s = shots[0].info["warp_s"] - before
        err, noise = pct(rmse_dn(d[0], d_ref)), pct(rmse_dn(d[0], d[1])) / np.sqrt(2.0)
        expected = float(np.hypot(ref_noise, noise))
        rows.append({"interpolation": name if ss == 1 else f"{name}, supersampled {ss}x{ss}", "error_percent": err,
                     "method_noise_percent": noise, "expected_noise_percent": expected,
                     "error_over_noise": err / expected if expected > 0 else None, "warp_s": warp_s})
    return rows


def _cpu_s() -> float:
    """CPU seconds of this process (all its threads) and its waited-for children, user + system."""
    import resource

    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def median_rate_instant(traj, walk_s: float, exposure_ms: float) -> float:
    """Start time of an exposure window whose mean turn rate is the walk's median."""
    from scenes.walks import angular_velocity

    t = np.arange(0.5, walk_s - 1.0, 0.01)
    speed = np.linalg.norm(angular_velocity(traj, t + 0.5e-3 * exposure_ms), axis=1)
    return float(t[np.argmin(np.abs(speed - np.median(speed)))])


def cost_comparison(scene, traj, t0_s: float, cfg, camera) -> dict:
    """CPU and wall-clock seconds of a blurred shot and of a shot at rest, same size and spp, no cache (medians).

    ``render_cost_ratio`` is the ratio of CPU seconds (this process's threads and children,
    :func:`resource.getrusage`): on a machine shared with other jobs, wall time measures the
    other jobs as much as the render.  The wall-clock ratio and the load average are kept beside it.
    """
    import os

    import scenes
    from scenes.blur import render_exposure

    kw = dict(width=cfg.width, height=cfg.height, spp=cfg.spp, denoise=cfg.sharpness_denoise, cache_dir=False,
              fov_deg=camera.fov_x_deg)
    t1 = t0_s + 1e-3 * cfg.exposure_ms
    scenes.render(scene, traj.pose(t0_s), seed=99, **kw)  # warm-up: kernels compiled
    render_exposure(scene, traj.poses, t0_s, t1, seed=98, **kw)
    rest, moving, rest_cpu, moving_cpu, info = [], [], [], [], {}
    load = [os.getloadavg()[0]]
    for r in range(cfg.timing_repeats):
        t, c = time.perf_counter(), _cpu_s()
        scenes.render(scene, traj.pose(t0_s), seed=cfg.seed + 10 + r, **kw)
        rest.append(time.perf_counter() - t)
        rest_cpu.append(_cpu_s() - c)
        t, c = time.perf_counter(), _cpu_s()
        _, info = render_exposure(scene, traj.poses, t0_s, t1, seed=cfg.seed + 20 + r, **kw)
        moving.append(time.perf_counter() - t)
        moving_cpu.append(_cpu_s() - c)
    load.append(os.getloadavg()[0])
    rest_s, moving_s = float(np.median(rest)), float(np.median(moving))
    rest_c, moving_c = float(np.median(rest_cpu)), float(np.median(moving_cpu))
    return {"t0_s": t0_s, "at_rest_s": rest_s, "blurred_s": moving_s, "at_rest_cpu_s": rest_c, "blurred_cpu_s": moving_c,
            "render_cost_ratio": moving_c / rest_c, "render_cost_ratio_wall": moving_s / rest_s,
            "load_average_1min": load,
            "blur_px": info.get("blur_px"), "n_subinstants": info.get("n_subinstants"),
            "margin_px": info.get("margin_px"), "warp_s": info.get("warp_s"), "depth_s": info.get("depth_s")}


def sharpness(raw: np.ndarray) -> float:
    """95th percentile of the gradient magnitude over the median level, green plane of an RGGB mosaic."""
    g = 0.5 * (raw[0::2, 1::2].astype(np.float64) + raw[1::2, 0::2].astype(np.float64))
    gy, gx = np.gradient(g)
    level = float(np.median(g))
    return float(np.percentile(np.hypot(gx, gy), 95) / level) if level > 0 else float("nan")


def source_and_live(scene, traj, t0_s: float, cfg, camera):
    """One render of the shot at ``t0_s`` (a :class:`scenes.blur.ShotRenderer` at ``camera``'s size),
    captured noiseless over its ``source_ms`` window and its ``exposure_ms`` window.

    Returns ``(shot, source DN, live DN, info)``, ``info`` that of the live window.
    """
    from scenes.blur import ShotRenderer

    shot = ShotRenderer(scene, traj.poses, t0_s, cfg.exposure_ms, width=camera.width, height=camera.height,
                        spp=cfg.spp, seed=cfg.seed + 7, denoise=cfg.sharpness_denoise, cache_dir=cfg.cache_dir,
                        fov_deg=camera.fov_x_deg)
    src = _dn(shot.radiance(cfg.source_ms)[0], camera, cfg.source_ms)
    live_rad, info = shot.radiance(cfg.exposure_ms)
    return shot, src, _dn(live_rad, camera, cfg.exposure_ms), info


def against_live(live: np.ndarray, plain: np.ndarray, valid: np.ndarray, white: int):
    """``score(img) -> (sharpness, error %, RMS DN)`` of an emulated image against ``live``.

    The error is the sharpness's relative to live's; the RMS DN difference is taken over the
    pixels that the plain emulation ``plain`` keeps valid and that neither it nor live clips
    (None when there are none).
    """
    keep = valid & (live < white) & (plain < white)
    s_live = sharpness(live)

    def score(img: np.ndarray):
        s = sharpness(img)
        rms = float(np.sqrt(np.mean((img[keep].astype(np.float64) - live[keep]) ** 2))) if keep.any() else None
        return s, 100.0 * (s - s_live) / s_live, rms

    return score


def sharpness_comparison(scene, traj, t0_s: float, cfg, camera, consistent=None) -> dict:
    """Emulated ``exposure_ms`` (from the ``source_ms`` bracket of the same trigger) against live, by sharpness.

    At ``camera``'s size (the study passes one at ``cfg.sharpness_width`` x ``sharpness_height``);
    noiseless captures of one render, so that the two differ by the blur alone.  Beside the
    sharpness error, the RMS DN difference from the live frame over the pixels neither clips
    (``rms_plain_dn``, ``rms_consistent_dn``).

    ``consistent``: optional ``f(raw, source_ms, target_ms, response, extra_radiance_fn) -> raw``
    hook for blur-consistent emulation (:func:`consistent_from_walk`); None leaves that figure out.
    """
    from emulator.core.emulate import emulate

    shot, src, live, info = source_and_live(scene, traj, t0_s, cfg, camera)
    plain, valid = emulate(src, cfg.source_ms, cfg.exposure_ms, camera.response, return_mask=True)
    score = against_live(live, plain, valid, camera.response.white_level)
    s_plain, err_plain, rms_plain = score(plain)
    out = {"t0_s": t0_s, "size": [camera.width, camera.height], "blur_px": info["blur_px"], "live": sharpness(live),
           "emulated_plain": s_plain, "plain_error_percent": err_plain,
           "consistent_error_percent": None, "rms_plain_dn": rms_plain, "rms_consistent_dn": None}
    if consistent is not None:
        s_cons, err_cons, rms_cons = score(consistent(src, cfg.source_ms, cfg.exposure_ms, camera.response, shot))
        out.update(emulated_consistent=s_cons, consistent_error_percent=err_cons, rms_consistent_dn=rms_cons)
    return out


def walk_omega(traj):
    """The walk's angular velocity as :mod:`emulator.core.blur` takes it: ``omega(t_s) -> (N, 3)`` rad/s in
    camera axes (:func:`scenes.walks.angular_velocity`), times clamped to the walk."""
    from scenes.walks import angular_velocity

    def omega(t_s):
        return angular_velocity(traj, np.clip(np.atleast_1d(t_s), 0.0, traj.duration_s))

    return omega


def consistent_from_walk(traj, camera, *, placement: str | None = None, **emulate_kw):
    """The blur-consistent emulation of :mod:`emulator.core.blur` fed with the walk's own angular velocity.

    Returns ``f(raw, source_ms, target_ms, response, shot) -> raw`` for
    :func:`sharpness_comparison`: the gyro is :func:`walk_omega` of the walk, windows start at
    the trigger (``stamp="start"``, the synthetic convention), K is the synthetic camera's.
    ``placement`` (:func:`emulator.core.blur.blur_homographies`) and ``emulate_kw``
    (:func:`emulator.core.blur.emulate_blur_consistent`'s keywords) default to the emulator's defaults:
    tiled copies and the noise measured on the image, which on these noiseless captures finds
    little, so nearly all of the source is moved.
    """
    from emulator.core.blur import DEFAULT_PLACEMENT, blur_homographies, emulate_blur_consistent
    from scenes.camera import intrinsics_matrix

    k = intrinsics_matrix(camera.width, camera.height, camera.fov_x_deg)
    size = (camera.width, camera.height)
    omega = walk_omega(traj)
    placement = DEFAULT_PLACEMENT if placement is None else placement

    def consistent(raw, source_ms, target_ms, response, shot):
        hs, ws = blur_homographies(omega, k, size, shot.t0_s, source_ms, target_ms, stamp="start",
                                   placement=placement)
        return emulate_blur_consistent(raw, source_ms, target_ms, response, hs, ws, **emulate_kw)[0]

    return consistent
