"""The leave-one-frame-out measurements of native emulation on a real recording (no file I/O but the frames).

Each recorded frame k of the first camera is hidden in turn: a tick of the native provider made with
``hidden=True`` (:meth:`emulator.playback.native.NativeProvider.tick`) has none of frame k's shots (on any
camera) among its candidates, and the flow warp never reads frame k (it reads the neighbours on either
side).  Frame k is then emulated at its own recorded exposure, as the native provider would serve an AE
method that asked for it, and compared with the real frame k:

* image error: RMSE in % of the DN range over the pixels the source can give (its validity mask moved
  with the image, inside the view);
* motion left: the median length of the optical flow (OpenCV's DIS, on 2x2 binned grey) from the
  emulated image to the real one over those pixels, full-resolution px;
* SIFT good matches: ratio-test matches (as ``bench features``) between the emulated and the real
  image whose keypoints lie within :data:`GOOD_MATCH_PX` of each other (the two should coincide);

by the camera's motion class at frame k (:func:`motion_class`: mean gyro rate over a frame interval
each side) and warp mode (:data:`emulator.core.native.WARP_MODES`).
"""

from __future__ import annotations

import dataclasses
import math
import time

import cv2
import numpy as np

__all__ = ["GOOD_MATCH_PX", "MOTION_CLASSES", "motion_class", "crop_sequence", "frame_rate_deg_s", "compare",
           "leave_one_out"]

#: A match between the emulated and the real frame is good when its keypoints lie this close (px).
GOOD_MATCH_PX = 3.0
#: Motion classes by the gyro's mean rate at the frame, deg/s: (name, lower bound), upper bound the next's.
MOTION_CLASSES = (("rest", 0.0), ("slow", 3.0), ("turning", 8.0))


def motion_class(rate_deg_s: float) -> str:
    """``"rest"`` (< 3 deg/s), ``"slow"`` (3-8) or ``"turning"`` (>= 8); ``"unknown"`` for NaN (no gyro)."""
    if not math.isfinite(rate_deg_s):
        return "unknown"
    return [name for name, lo in MOTION_CLASSES if rate_deg_s >= lo][-1]


def crop_sequence(sequence, motion, size):
    """``sequence`` with every frame cropped to its centre ``size`` = (width, height) (even offsets, so the
    Bayer phase stays), and ``motion`` with the intrinsics of the crop.  ``size`` None: both as they are."""
    if size is None:
        return sequence, motion
    first = next(fr for c in sequence.cycles for cam in c.frames.values() for fr in cam.values())
    full_h, full_w = first.load().shape
    w, h = min(int(size[0]), full_w), min(int(size[1]), full_h)
    x0, y0 = ((full_w - w) // 4) * 2, ((full_h - h) // 4) * 2

    def cut(frame):
        reader = frame.reader
        return dataclasses.replace(frame, reader=lambda f: reader(f)[y0:y0 + h, x0:x0 + w], cache_path=None)

    cycles = [dataclasses.replace(c, frames={cam: {e: cut(fr) for e, fr in shots.items()}
                                             for cam, shots in c.frames.items()}) for c in sequence.cycles]
    cropped = dataclasses.replace(sequence, cycles=cycles)
    if motion is None:
        return cropped, None
    intrinsics = {}
    for cam, (K, calib) in motion.intrinsics.items():
        K = motion.K(cam, (full_w, full_h))[0].copy()  # at the recorded size, then shifted to the crop
        K[0, 2] -= x0
        K[1, 2] -= y0
        intrinsics[cam] = (K, (w, h))
    return cropped, dataclasses.replace(motion, intrinsics=intrinsics)


def frame_rate_deg_s(motion, t_s: float, interval_s: float) -> float:
    """Mean angular rate of the gyro (deg/s) over ``interval_s`` each side of ``t_s`` (NaN without a gyro)."""
    if motion is None or not motion.omega.covers(t_s - interval_s, t_s + interval_s):
        return math.nan
    tt = np.linspace(t_s - interval_s, t_s + interval_s, 41)
    return float(np.degrees(np.linalg.norm(motion.omega(tt), axis=1).mean()))


def _binned8(image: np.ndarray, white: int, black: int) -> np.ndarray:
    f = image.astype(np.float32)
    hh, ww = (f.shape[0] // 2) * 2, (f.shape[1] // 2) * 2
    f = 0.25 * (f[0:hh:2, 0:ww:2] + f[1:hh:2, 0:ww:2] + f[0:hh:2, 1:ww:2] + f[1:hh:2, 1:ww:2])
    return np.clip((f - black) * (255.0 / (white - black)), 0, 255).round().astype(np.uint8)


def compare(emulated: np.ndarray, real: np.ndarray, mask: np.ndarray, *, white: int, black: int,
            real_features=None) -> dict:
    """Image error (% of range, over ``mask``), motion left (px) and SIFT good matches of ``emulated`` against
    ``real`` (both DN Bayer images of one exposure).  ``real_features``: the real frame's SIFT, if known."""
    from emulator.core.gray import bayer_to_gray8
    from emulator.metrics.features import detect_sift, match_descriptors

    d = emulated.astype(np.float64)[mask] - real.astype(np.float64)[mask]
    rmse = 100.0 * float(np.sqrt(np.mean(d * d))) / (white - black) if d.size else math.nan
    a, b = _binned8(emulated, white, black), _binned8(real, white, black)
    flow = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM).calc(a, b, None)
    m2 = mask[0::2, 0::2][: a.shape[0], : a.shape[1]]
    length = 2.0 * np.linalg.norm(flow, axis=2)[m2]
    left = float(np.median(length)) if length.size else math.nan
    fr = real_features if real_features is not None else detect_sift(
        bayer_to_gray8(real, white_level=white, black_level=black))
    fe = detect_sift(bayer_to_gray8(emulated, white_level=white, black_level=black))
    good = 0
    if len(fe) >= 2 and len(fr) >= 2:
        pairs = match_descriptors(fe.descriptors, fr.descriptors)
        if len(pairs):
            gap = np.linalg.norm(fe.points[pairs[:, 0]] - fr.points[pairs[:, 1]], axis=1)
            good = int((gap <= GOOD_MATCH_PX).sum())
    return {"rmse_percent": rmse, "valid_fraction": float(mask.mean()), "motion_left_px": left,
            "sift_good_matches": good, "sift_keypoints_emulated": len(fe), "sift_keypoints_real": len(fr)}


def leave_one_out(providers: dict, frames, response, *, progress=None) -> list[dict]:
    """One row per (hidden frame, warp mode): ``providers`` maps a warp mode to a
    :class:`~emulator.playback.native.NativeProvider` of the recording (the same selection in each);
    ``frames``: the frame indices to hide.  ``progress(line)`` hears one line per frame."""
    from emulator.core.blur import exposure_window_s
    from emulator.core.emulate import validity_mask
    from emulator.core.gray import bayer_to_gray8
    from emulator.metrics.features import detect_sift
    from emulator.core.native import move_mask

    first = next(iter(providers.values()))
    fr, white, black = first.frames, first.white, first.black
    lead = first.cameras[0]
    interval = float(np.median(np.diff(fr.timestamps))) * 1e-9 if len(fr) > 1 else 0.0
    motion = next((p.motion for p in providers.values() if p.motion is not None), None)
    rows = []
    for p in providers.values():  # warm-up, untimed: the response's tables are built once per process
        if frames:
            p.tick(frames[0], hidden=True).shot(fr.exposures[frames[0]])
    for n, k in enumerate(frames):
        e = fr.exposures[k]
        real = first.images(k).get(lead, e)[0]
        rate = math.nan if motion is None else frame_rate_deg_s(
            motion, 0.5 * sum(exposure_window_s(motion.t_s(fr.timestamps[k]), e, motion.stamp)), interval)
        feats = detect_sift(bayer_to_gray8(real, white_level=white, black_level=black))
        order = list(providers.items())
        for mode, p in order[n % len(order):] + order[: n % len(order)]:  # one-off costs (tables) spread over modes
            tick = p.tick(k, hidden=True)
            if tick.skipped or not tick.sources:
                continue
            for j in tick.sources:  # decoded before the clock starts: the time is the selection's and the warp's
                p.images(j).get(lead, fr.exposures[j])
            t0 = time.process_time()
            shot = tick.shot(e)
            cpu = time.process_time() - t0
            j = k + shot.native.source_offset
            src = p.images(j).get(lead, shot.bracket_ms)[0]
            H, disp = p.geometry(lead, j, k, shot.bracket_ms, e, src.shape)
            mask = move_mask(validity_mask(src, shot.ratio, response), H, disp)
            row = {"frame": int(k), "timestamp_ns": int(fr.timestamps[k]), "exposure_ms": float(e),
                   "rate_deg_s": rate, "motion_class": motion_class(rate), "warp": mode,
                   "source_offset": int(shot.native.source_offset), "source_ms": float(shot.bracket_ms),
                   "ratio": float(shot.ratio), "warp_deg": float(shot.native.warp_deg),
                   "flow_used": bool(disp is not None), "cpu_s": cpu,
                   **compare(shot.left, real, mask, white=white, black=black, real_features=feats)}
            rows.append({key: (None if isinstance(v, float) and not math.isfinite(v) else v) for key, v in row.items()})
        if progress is not None:
            done = sorted((r for r in rows if r["frame"] == k), key=lambda r: list(providers).index(r["warp"]))
            progress(f"frame {n + 1}/{len(frames)} (#{k}, {e:g} ms, {rate:.1f} deg/s): "
                     + ", ".join(f"{r['warp']} {r['rmse_percent'] or math.nan:.2f} % from {r['source_offset']:+d}"
                                 for r in done))
    return rows
