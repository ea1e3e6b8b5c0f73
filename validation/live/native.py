"""The native-rate live loop of issue 22: the live camera as a camera.

A camera that runs its AE at its own frame rate (the BorealHDR recorder's 22 fps by
default), with an exposure latency (``latency_frames``, default 1: a proposal made after
reading frame k is first used for frame k + 2), each shot timestamped at mid-exposure.  It
is the one closed loop of ``exposim run`` (:func:`emulator.playback.closed_loop`) over a
:class:`emulator.playback.LiveRateProvider`; only the capture is this module's.

**Frame grid.** Frame k starts at the recording's first shot plus ``k / frame_rate_hz``. At
the recorder's rate, frame k is the recorder's shot k: the per-shot radiance the recorder
rendered serves the live frame (cache hits), over the frame's own window. A rate whose
frames do not start on the recorder's shots (e.g. 30 fps on a 22 fps recording) is refused
(:class:`~validation.live.config.LiveError`): the radiance exists only at those instants.

**Window convention.** :class:`~emulator.playback.LiveRateProvider` passes the mid-exposure
instant ``start + exposure / 2``; the radiance of a synthetic walk
(:func:`scenes.walkshots.walk_radiance`, ``exposure_aware``) integrates over ``[t, t +
exposure]`` from the shot at ``t``. The capture here passes it the frame start ``t = mid -
exposure / 2`` (exact in ns, the provider's own rounding undone), so the frame integrates
over ``[start, start + exposure]``, the window a cycle-rate live shot at that instant and
exposure integrates over.

**What the study compares.** The AE runs on every frame; the study's metrics (feature
matches between consecutive images, VO over the run folder) are computed on one image per
recorder cycle in every condition, so that the conditions differ in how the AE ran (rate,
latency, emulation) and not in how many or how spaced the benchmarked images are. Per
recorder cycle :func:`native_rate_loop` therefore yields the frame that starts at the
cycle's fixed instant (its first shot, the instant of the ``cycle-rate live`` condition),
relabelled with the cycle index (``every_frame=True`` yields every frame instead, with
``cycle`` the frame index). The yielded step's ``timestamp_ns`` is that frame's
mid-exposure stamp, its ``target_ms`` the exposure the camera applied (queued
``latency_frames`` + 1 frames earlier), its ``next_ms`` the proposal made after reading it.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Iterator
from dataclasses import replace

import numpy as np

from validation.live.config import FIXED_INSTANT_BRACKET_INDEX, LiveError
from validation.live.loops import live_setup, make_shoot
from emulator.cells import median_finite

__all__ = ["NATIVE_FRAME_RATE_HZ", "NATIVE_LATENCY_FRAMES", "GRID_TOLERANCE_NS", "EMULATED_NATIVE_RUN", "shot_timestamps",
           "window_start_shoot", "native_rate_loop", "per_cycle", "cycle_picks", "native_provider", "emulated_native_loop",
           "native_image_errors"]

#: Frame rate of the native-rate live camera: the BorealHDR recorder's.
NATIVE_FRAME_RATE_HZ = 22.0
#: Frames a proposal waits before the camera applies it (issue 22's default).
NATIVE_LATENCY_FRAMES = 1
#: A frame starts "on" a recorder shot when within this many ns of it (float rounding of the grids).
GRID_TOLERANCE_NS = 1_000


def shot_timestamps(sequence, camera: str = "left") -> list[int]:
    """Sorted timestamps (ns) of every shot of ``camera`` in the recording."""
    ts = {int(f.timestamp_ns) for cycle in sequence.cycles for f in cycle.frames.get(camera, {}).values()}
    return sorted(ts)


def _nearest(sorted_ts: list[int], t: int) -> int:
    i = bisect.bisect_left(sorted_ts, t)
    best = min((sorted_ts[j] for j in (i - 1, i) if 0 <= j < len(sorted_ts)), key=lambda s: abs(s - t))
    return int(best)


def window_start_shoot(shoot: Callable, shots_ns: list[int]) -> Callable:
    """Wrap a ``shoot(t, camera, exposure_ms, index)`` whose ``t`` is a window start for a provider
    that passes mid-exposure instants: ``t = mid - exposure / 2`` (the provider's ns rounding undone),
    snapped onto the recorder's shot ``shots_ns`` (:class:`LiveError` when it is not on one)."""
    shots_ns = sorted(int(t) for t in shots_ns)

    def shoot_mid(mid_ns: int, camera: str, exposure_ms: float, index: int) -> np.ndarray:
        start = int(mid_ns) - int(round(float(exposure_ms) * 1e6 / 2.0))
        on = _nearest(shots_ns, start)
        if abs(on - start) > GRID_TOLERANCE_NS:
            raise LiveError(f"frame {index} starts at {start} ns, {abs(on - start)} ns from the recorder's nearest "
                            "shot: no radiance there (choose a frame rate whose frames fall on the recorder's shots)")
        return shoot(on, camera, exposure_ms, index)

    return shoot_mid


def native_rate_loop(sequence, radiance: Callable, camera, methods, *, seed: int = 0, noise: bool = True,
                     initial_ms: float | None = None, selector: str | None = None, response=None,
                     range_ms=None, mode: str | None = None, config=None,
                     latency_frames: int = NATIVE_LATENCY_FRAMES, frame_rate_hz: float = NATIVE_FRAME_RATE_HZ,
                     every_frame: bool = False) -> Iterator:
    """The native-rate live loop over a synthetic recording (see the module notes).

    Parameters
    ----------
    sequence : emulator.core.dataset.Sequence or path
        The bracketed recording of the walk: its shot instants are the frame grid, its cycles
        the instants whose frames are yielded.
    radiance : callable
        ``radiance(t, camera)`` at the recorder's shot instants (:class:`~validation.live.loops.DatasetRadiance`)
        or an ``exposure_aware`` ``radiance(t, camera, exposure_ms)`` integrating over ``[t, t + exposure]``
        (:func:`scenes.walkshots.walk_radiance`); ``t`` is always a frame start.
    camera : synth.Camera
        The recording's camera (its levels must be the recording's).
    methods : names or AE method instances
        As :func:`emulator.playback.iter_run` takes them.
    seed, noise
        Capture noise (:func:`validation.live.loops.make_shoot`; the tick is the frame index).
    initial_ms, selector, response, range_ms, mode, config
        As :func:`validation.live.loops.iter_live` (the selector plays no part: no brackets).
    latency_frames : int
        Exposure latency in frames (default 1).
    frame_rate_hz : float
        The camera's frame rate (default 22, the recorder's); its frames must start on recorder shots.
    every_frame : bool
        Yield every frame (``cycle`` = frame index) instead of one per recorder cycle.

    Yields
    ------
    emulator.playback.CycleStep
        Images kept (left and right where the recording is stereo). Methods that failed at a
        frame not yielded are named in the next yielded step's ``failed``.
    """
    from emulator.core.dataset import CAMERAS
    from emulator.errors import PlaybackError
    from dataclasses import replace

    from emulator.playback import LiveRateProvider, closed_loop
    from emulator.playback.workers import start_methods

    if isinstance(latency_frames, bool) or not isinstance(latency_frames, (int, np.integer)) or latency_frames < 0:
        raise LiveError(f"latency_frames must be an integer >= 0, got {latency_frames!r}")
    try:
        rate = float(frame_rate_hz)
    except (TypeError, ValueError):
        raise LiveError(f"frame_rate_hz must be a number, got {frame_rate_hz!r}") from None
    if not (np.isfinite(rate) and rate > 0):
        raise LiveError(f"frame_rate_hz must be finite and positive, got {frame_rate_hz!r}")
    seq, cfg, response = live_setup(sequence, camera, config, response, initial_ms=initial_ms, range_ms=range_ms,
                                    selector=selector, mode=mode)
    cams = tuple(c for c in CAMERAS if c in seq.cameras)
    shots_ns = shot_timestamps(seq, cams[0])
    if not shots_ns:
        raise LiveError(f"{seq.path if hasattr(seq, 'path') else 'recording'}: no shots")
    start_ns, last_ns = shots_ns[0], shots_ns[-1]
    n_frames = int(np.floor((last_ns - start_ns) * rate / 1e9 + 1e-6)) + 1
    # in worker processes, as every loop of the study runs its methods (fixed freezes one exposure in flight)
    built = start_methods(methods, replace(cfg, rate="native", latency_frames=int(latency_frames)), response)
    shoot = window_start_shoot(make_shoot(radiance, camera, cams, seed=seed, noise=noise), shots_ns)
    try:
        provider = LiveRateProvider(shoot, n_frames=n_frames, white_level=int(seq.white_level),
                                    black_level=int(seq.black_level), start_ns=start_ns, frame_rate_hz=rate,
                                    latency_frames=int(latency_frames), cameras=cams)
    except PlaybackError as exc:
        raise LiveError(str(exc)) from None
    off = [k for k in range(n_frames)
           if abs(_nearest(shots_ns, provider.frame_start_ns(k)) - provider.frame_start_ns(k)) > GRID_TOLERANCE_NS]
    if off:
        raise LiveError(f"frame_rate_hz {rate:g}: frame {off[0]} (and {len(off) - 1} more) does not start on a shot "
                        "of the recording; use the recorder's rate or an integer fraction of it")
    loop = closed_loop(provider, built, cfg, want_right=len(cams) > 1, keep_images=True)
    if every_frame:
        return loop
    # the frame that starts at each cycle's fixed instant (nearest frame start), frame -> cycle index
    pick: dict[int, int] = {}
    for cycle in seq.cycles:
        avail = cycle.available(cams)  # as LiveCycleProvider(instant="fixed")
        if not avail:
            continue
        t = int(cycle.frames[cams[0]][avail[min(FIXED_INSTANT_BRACKET_INDEX, len(avail) - 1)]].timestamp_ns)
        k = int(np.clip(round((t - start_ns) * rate / 1e9), 0, n_frames - 1))
        pick.setdefault(k, cycle.index)
    return _per_cycle(loop, pick)


def _per_cycle(loop, pick: dict[int, int]) -> Iterator:
    failed: dict[str, str] = {}
    for cs in loop:
        failed.update(cs.failed)
        ci = pick.get(cs.cycle)
        if ci is None:
            continue  # a frame between cycle instants: its images are dropped here
        yield replace(cs, cycle=ci, steps={m: replace(st, cycle=ci) for m, st in cs.steps.items()}, failed=failed)
        failed = {}


# ============================================================================ emulated native
#: Run name of the emulated native-rate condition (``exposim run --rate native`` on the walk's recording).
EMULATED_NATIVE_RUN = "emulated-native"


def per_cycle(frames, pick: dict[int, int]) -> list:
    """The steps of the frames ``pick`` names (frame -> cycle index), relabelled with the cycle index; methods
    that failed at a frame not picked are named in the next picked step's ``failed``."""
    return list(_per_cycle(iter(frames), pick))


def cycle_picks(provider) -> dict[int, int]:
    """Frame -> recorder cycle of the frames the benchmarks use (the native live condition's instants)."""
    return {k: int(provider.frames.cycles[k].index) for k in sorted(provider.frames.benchmarked) if k is not None}


def native_provider(seq, response, config, *, warp: bool = True, **kw):
    """The native-rate image provider of a synthetic walk: the walk's gyro (no offset to remove),
    timestamps at the trigger, the synthetic camera's intrinsics (its calibration files); ``kw``:
    :class:`~emulator.playback.NativeProvider`'s (the selector's weight)."""
    from emulator.playback.motion import recording_motion
    from emulator.playback import NativeProvider

    motion = recording_motion(seq, stamp="start", remove_bias=False) if warp and seq.imu is not None else None
    return NativeProvider(seq, config, response, motion=motion, warp=warp, **kw)


def emulated_native_loop(seq, methods, response, config) -> tuple[object, list]:
    """The emulated native-rate closed loop of ``methods`` on a walk's recording: ``(provider, every frame's
    CycleStep with images)``."""
    from dataclasses import replace

    from emulator.playback import closed_loop
    from emulator.playback.workers import start_methods

    provider = native_provider(seq, response, config)
    # in worker processes, as every loop of the study runs its methods (fixed freezes one exposure in flight)
    built = start_methods(methods, replace(config, latency_frames=provider.latency_ticks), response)
    return provider, list(closed_loop(provider, built, config, want_right=True, keep_images=True))


def native_image_errors(seq, live_frames, response, config, names, **kw) -> dict:
    """Per method: native emulation of each frame at the exposure the native live camera applied, against
    that live frame (open loop: the same target, so the error is the emulation's and not the trajectory's).

    Per frame the RMSE (% of the DN range) over the pixels the emulation can give (the source's validity
    mask, moved with the image, inside the view) with the warp and without (the same selection), the
    source offset and the warp angle; ``rmse_percent_all`` counts every pixel in view, those the source
    lost to clipping included; ``rmse_percent_own_bracket`` is frame k's own bracket emulated at the same
    exposure over the pixels both it and the source can give (the error of an instant with no motion to
    undo, on the frames a neighbour served; the same as ``rmse_percent`` on the others).  Returns
    ``{method: {"rmse_percent", "rmse_percent_unwarped", "rmse_percent_all", "rmse_percent_own_bracket",
    "source_offset", "warp_deg"}}`` (lists, one entry per frame)."""
    import cv2

    from emulator.core.blur import rotation_homography
    from emulator.core.emulate import validity_mask

    warped, plain = native_provider(seq, response, config, **kw), native_provider(seq, response, config, warp=False, **kw)
    white, black = int(seq.white_level), int(seq.black_level)
    out = {m: {"rmse_percent": [], "rmse_percent_unwarped": [], "rmse_percent_all": [], "rmse_percent_own_bracket": [],
               "source_offset": [], "warp_deg": []} for m in names}
    live_by = {cs.cycle: cs for cs in live_frames}
    for tick_w, tick_p in zip(warped.ticks(), plain.ticks()):
        cs = live_by.get(tick_w.index)
        if cs is None:
            continue
        for m in names:
            lv = cs.steps.get(m)
            if lv is None or tick_w.skipped:
                continue
            target = float(lv.target_ms)
            a, b = tick_w.shot(target), tick_p.shot(target)
            j = tick_w.index + a.native.source_offset
            src = warped.frames.cycles[j].frames["left"][a.bracket_ms].load()
            mask = validity_mask(src, a.ratio, response)
            rm, inside = mask, np.ones_like(mask)
            if a.native.source_offset and warped.motion is not None and np.isfinite(a.native.warp_deg):
                R = warped.rotation(j, tick_w.index, a.bracket_ms, target)
                K, _ = warped.motion.K("left", (src.shape[1], src.shape[0]))
                rm, inside = (cv2.warpPerspective(x.astype(np.uint8), rotation_homography(K, R),
                                                  (src.shape[1], src.shape[0]), flags=cv2.INTER_NEAREST,
                                                  borderMode=cv2.BORDER_CONSTANT, borderValue=0) > 0
                              for x in (mask, inside))
            live = lv.left.astype(np.float64)
            own, own_mask = a.left, rm
            if a.native.source_offset:
                k, e = tick_w.index, warped.frames.exposures[tick_w.index]
                table, valid = response.lut(target / e)
                raw = warped.images(k).get("left", e)[0]
                own, own_mask = warped.images(k).emulated("left", e, target / e, table, warped.stats), rm & valid[raw]
            for key, img, msk in (("rmse_percent", a.left, rm), ("rmse_percent_unwarped", b.left, mask),
                                  ("rmse_percent_all", a.left, inside), ("rmse_percent_own_bracket", own, own_mask)):
                d = img.astype(np.float64)[msk] - live[msk]
                out[m][key].append(100.0 * float(np.sqrt(np.mean(d * d))) / (white - black) if d.size else math.nan)
            out[m]["source_offset"].append(int(a.native.source_offset))
            out[m]["warp_deg"].append(float(a.native.warp_deg))
    return out


#: Goals for native emulation against the native live frame at the same instant (480x300).
GOAL_NATIVE_RMSE_PERCENT = 3.0
GOAL_WARP_CUT = 0.5


def _over_walks(values: list, seed) -> dict:
    """Mean over walks of one figure, with a bootstrap 95 % interval over walks (None with fewer than 2)."""
    a = np.asarray([v for v in values if v is not None and np.isfinite(v)], dtype=np.float64)
    if not a.size:
        return {"estimate": None, "ci95": None, "n_walks": 0}
    ci = None
    if a.size >= 2:
        rng = np.random.default_rng(seed)
        boots = a[rng.integers(0, a.size, (2000, a.size))].mean(axis=1)
        ci = [float(np.percentile(boots, 2.5)), float(np.percentile(boots, 97.5))]
    return {"estimate": float(a.mean()), "ci95": ci, "n_walks": int(a.size)}


def native_emulation_summary(per_walk: dict, names, *, seed: int = 0) -> dict | None:
    """results.json's ``native_emulation``: per walk and method, the median image error of native emulation
    against the native live frame at the same instant (with and without the warp), the median exposure
    log2 error of the emulated native loop against the native live loop, how often a neighbour frame served
    and the warp's share of the error; over walks, each walk's median over its frames and methods, averaged,
    with a bootstrap interval over walks, against the goals."""
    walks = {w: d for w, d in per_walk.items() if d}
    if not walks:
        return None
    table: dict = {}
    pooled = {"rmse": [], "unwarped": [], "cut": [], "all": [], "cut_nb": [], "cut_nb_excess": [], "cut_perfect": [],
              "nb_rmse": [], "nb_unwarped": [], "nb_own": []}
    for w, per in walks.items():
        table[w] = {}
        allw, allu, alla, nbw, nbu, nbo, perfect = [], [], [], [], [], [], []
        for m in names:
            d = per.get(m) or {}
            rw, ru = median_finite(d.get("rmse_percent", [])), median_finite(d.get("rmse_percent_unwarped", []))
            off = np.asarray(d.get("source_offset", []))
            table[w][m] = {"image_rmse_percent_median": rw, "image_rmse_percent_median_unwarped": ru,
                           "exposure_log2_error_median": median_finite(d.get("exposure_log2_error", [])),
                           "neighbour_fraction": float(np.mean(off != 0)) if off.size else None,
                           "warp_share_of_error": (1.0 - rw / ru) if rw is not None and ru else None,
                           "frames": int(off.size)}
            allw += list(d.get("rmse_percent", []))
            allu += list(d.get("rmse_percent_unwarped", []))
            alla += list(d.get("rmse_percent_all", []))
            nb = off != 0
            # a perfect warp: every neighbour frame without error, the frames served by their own bracket as they are
            perfect += [0.0 if n else x for x, n in zip(d.get("rmse_percent", []), nb)]
            nbw += list(np.asarray(d.get("rmse_percent", []), dtype=float)[nb]) if off.size else []
            nbu += list(np.asarray(d.get("rmse_percent_unwarped", []), dtype=float)[nb]) if off.size else []
            nbo += list(np.asarray(d.get("rmse_percent_own_bracket", []), dtype=float)[nb]) if off.size else []
        mw, mu = median_finite(allw), median_finite(allu)
        pooled["all"].append(median_finite(alla))
        w_nb, u_nb, o_nb = median_finite(nbw), median_finite(nbu), median_finite(nbo)
        pooled["cut_nb"].append((1.0 - w_nb / u_nb) if w_nb is not None and u_nb else None)
        pooled["cut_nb_excess"].append((u_nb - w_nb) / (u_nb - o_nb) if None not in (w_nb, u_nb, o_nb) and u_nb > o_nb
                                       else None)
        for key, v in (("nb_rmse", w_nb), ("nb_unwarped", u_nb), ("nb_own", o_nb)):
            pooled[key].append(v)
        pooled["rmse"].append(mw)
        pooled["unwarped"].append(mu)
        pooled["cut"].append((1.0 - mw / mu) if mw is not None and mu else None)
        mp = median_finite(perfect)
        pooled["cut_perfect"].append((1.0 - mp / mu) if mp is not None and mu else None)
    rmse = _over_walks(pooled["rmse"], [seed, 32, 1])
    cut = _over_walks(pooled["cut"], [seed, 32, 2])
    return {
        "definition": "per frame, the left image of native emulation at the exposure the native live camera applied, "
                      "against that live frame (RMSE over the pixels the source can give, % of the DN range); per walk "
                      "the median over frames and methods; over walks the mean with a bootstrap 95 % interval",
        "per_walk": table,
        "median_image_rmse_percent": {**rmse, "goal_at_most": GOAL_NATIVE_RMSE_PERCENT,
                                      "met": None if rmse["estimate"] is None else bool(
                                          (rmse["ci95"] or [rmse["estimate"]] * 2)[1] <= GOAL_NATIVE_RMSE_PERCENT)},
        "median_image_rmse_percent_unwarped": _over_walks(pooled["unwarped"], [seed, 32, 3]),
        "median_image_rmse_percent_every_pixel": _over_walks(pooled["all"], [seed, 32, 4]),
        "warp_cut_fraction_neighbour_frames": _over_walks(pooled["cut_nb"], [seed, 32, 5]),
        "neighbour_frames": {"median_image_rmse_percent": _over_walks(pooled["nb_rmse"], [seed, 32, 6]),
                             "median_image_rmse_percent_unwarped": _over_walks(pooled["nb_unwarped"], [seed, 32, 7]),
                             "median_image_rmse_percent_own_bracket": _over_walks(pooled["nb_own"], [seed, 32, 8])},
        "warp_cut_fraction_of_excess_neighbour_frames": _over_walks(pooled["cut_nb_excess"], [seed, 32, 9]),
        "warp_cut_fraction_perfect_warp": _over_walks(pooled["cut_perfect"], [seed, 32, 10]),
        "warp_cut_fraction": {**cut, "goal_at_least": GOAL_WARP_CUT,
                              "met": None if cut["estimate"] is None else bool(
                                  (cut["ci95"] or [cut["estimate"]] * 2)[0] >= GOAL_WARP_CUT)},
    }


def native_markdown(results: dict) -> str:
    """The report's section on emulated native rate (empty when it did not run)."""
    ne = results.get("native_emulation")
    if not ne:
        return ""
    r, u, c = ne["median_image_rmse_percent"], ne["median_image_rmse_percent_unwarped"], ne["warp_cut_fraction"]

    def iv(d, spec=".2f"):
        if d["estimate"] is None:
            return "-"
        ci = d["ci95"]
        return format(d["estimate"], spec) + (f" [{ci[0]:{spec}}, {ci[1]:{spec}}]" if ci else " (one walk: no interval)")

    lines = ["", "## Emulated at the camera's own rate", "",
             "Each recorded frame is emulated from its own bracket or a nearby frame's, turned to its instant with "
             "the gyro. Definition: " + ne["definition"] + ".", "",
             f"- median image error {iv(r)} % of range (goal: at most {r['goal_at_most']:g} %; "
             f"{'met' if r['met'] else 'not met' if r['met'] is not None else 'not measured'})",
             f"- the same selection without the warp: {iv(u)} %",
             f"- counting every pixel in view (those the source lost to clipping too): "
             f"{iv(ne['median_image_rmse_percent_every_pixel'])} %",
             f"- on the frames a neighbour served, share of the error the warp removes: "
             f"{iv(ne['warp_cut_fraction_neighbour_frames'])}; share of what the motion adds there (the error above "
             f"the frame's own bracket at the same exposure) the warp removes: "
             f"{iv(ne.get('warp_cut_fraction_of_excess_neighbour_frames') or {'estimate': None})}",
             f"- share of the median error the warp removes, over every frame: {iv(c)} (goal: at least "
             f"{c['goal_at_least']:g}; "
             f"{'met' if c['met'] else 'not met' if c['met'] is not None else 'not measured'}); a perfect warp "
             f"(every neighbour frame without error) would remove "
             f"{iv(ne.get('warp_cut_fraction_perfect_warp') or {'estimate': None})}", "",
             "| walk | method | error % | unwarped % | warp's share | exposure log2 error | neighbour served |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: |"]
    f = lambda v, s=".2f": "-" if v is None else format(v, s)  # noqa: E731
    for w, per in ne["per_walk"].items():
        for m, d in per.items():
            lines.append(f"| {w} | {m} | {f(d['image_rmse_percent_median'])} | "
                         f"{f(d['image_rmse_percent_median_unwarped'])} | {f(d['warp_share_of_error'])} | "
                         f"{f(d['exposure_log2_error_median'], '.3f')} | {f(d['neighbour_fraction'])} |")
    return "\n".join(lines) + "\n"
