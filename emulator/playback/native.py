"""The native-rate image provider: every recorded frame is a tick (``exposim run --rate native``).

At cycle rate (:class:`~emulator.playback.emulated.EmulatedProvider`) a method proposes once
per bracket sweep.  Here it proposes after every recorded frame of the first camera, at the
recorder's own rate, with an exposure latency of ``config.latency_frames`` (default 1): a
proposal made after reading frame k is first used at frame ``k + 1 + latency``.  It is the
same closed loop (:func:`~emulator.playback.loop.closed_loop`); only the images differ:

* frame k's image at the applied exposure ``t`` comes from frame k's own bracket or from a
  frame within one recorder cycle each side (:data:`emulator.core.native.WINDOW_CYCLES`; the
  frames present for every camera), chosen by :func:`emulator.core.native.native_select` (time
  offset against upward ratio and clipping);
* the source is emulated at ``t`` as at cycle rate (lookup table, then ``--blur consistent``'s
  hook, then ``--noise consistent``'s noise, each seeded by the source frame) and, when it is
  another frame, moved to frame k's instant by the rotation the gyro measured between the
  two (:func:`emulator.core.native.warp_to_instant`): from the middle of the window the emulated
  image stands for to the middle of frame k's window at ``t`` (frame k's window starts where
  its recorded shot started; the timestamp convention is the blur model's,
  :data:`emulator.core.blur.DEFAULT_STAMP`, or the trigger for a synthetic recording);
* without an IMU (or a camera calibration) the neighbour is used as it is, and one warning
  says so;
* opt-in (the defaults keep the runs as they were): ``warp="flow"`` moves a neighbour by the
  rotation and then by the optical flow between the frames on either side of frame k
  (:func:`emulator.core.native.flow_velocity`; frame k's own image never informs its flow),
  ``warp="flow-sharp"`` (``exposim run``'s default) does so only where the median move is at least
  :data:`emulator.core.native.SHARP_MOTION_PX`, and
  ``blur_stops_per_px`` makes the selector weigh the motion blur a candidate's window carries
  beyond the target's (:func:`emulator.core.native.native_select`);
* a tick made with ``hidden=True`` (:meth:`NativeProvider.tick`) leaves frame k's own shots out of
  its candidates: the leave-one-out check, ``exposim validate native``.

Each step carries a :class:`NativeInfo` (``MethodStep.native``): the recorder cycle of
the frame, whether it is the frame the benchmarks use (the cycle's first shot present for
every camera: the instant of the native-rate live condition), the source frame's offset and
timestamp and the warp's angle.  Frames are decoded once each (a sliding window of them is
kept), and methods with the same target in a frame share one image.  The frames' index and the
ticks are :mod:`emulator.playback.native_ticks`.
"""

from __future__ import annotations

import math
import threading
import warnings

import numpy as np

from emulator.autoexposure.isolation import readonly_view
from emulator.core.blur import DEFAULT_STAMP, window_blur, as_angular_velocity, exposure_window_s, rotation_homography
from emulator.core.dataset import CAMERAS
from emulator.core.gyro import GYRO_HOLE_S
from emulator.core.native import (BLUR_STOPS_PER_PX, MOTION_STOPS_PER_FRAME, NATIVE_RATE, SATURATION_LIMIT,
                                  SHARP_MOTION_PX, WARP_MODES, WARP_RESAMPLE, WINDOW_CYCLES, flow_velocity,
                                  median_motion_px, radiance_gray, rotation_between, warp_to_instant, warp_with_flow)
from emulator.errors import CalibrationError, PlaybackError
from emulator.io.runcsv import NATIVE_COLUMNS
from emulator.playback.config import RunConfig, provides_rate
from emulator.playback.emulated import METHOD_CAMERA, CycleImages
from emulator.playback.motion import find_camera_calibration, recording_motion
from emulator.playback.native_ticks import NativeInfo, NativeTick, RecordedFrames
from emulator.playback.records import RunStats

__all__ = ["NativeProvider", "NativeInfo", "NativeTick", "NativeWarpWarning", "recording_stamp"]


class NativeWarpWarning(UserWarning):
    """A native-rate run on a recording without a gyro (or calibration): neighbour frames are not warped."""


def recording_stamp(sequence) -> str:
    """Where a frame's timestamp lies in its window: the trigger (``start``) for a synthetic recording
    (its ``exposim.json`` says so), else the blur model's default (docs/blur.md)."""
    note = str((getattr(sequence, "metadata", None) or {}).get("timestamps", ""))
    return "start" if note.startswith("trigger instant") else DEFAULT_STAMP


@provides_rate(NATIVE_RATE)
class NativeProvider:
    """A recording's frames as ticks, each emulated from its own or a nearby frame's bracket.

    Parameters
    ----------
    sequence, config, response, cameras, noise, stats, blur
        As :class:`~emulator.playback.emulated.EmulatedProvider` (``config.latency_frames``
        is the latency; its selector plays no part).
    motion : "auto", RecordingMotion or None
        The gyro and intrinsics of the warp: "auto" (default) the blur hook's, else the
        recording's own (:func:`emulator.playback.motion.recording_motion`, timestamps by
        :func:`recording_stamp`); None: no warp.
    warp : bool or {"none", "rotation", "flow"}
        False or "none": neighbour frames are used unwarped even where the gyro is known (the
        warp's share of the error is measured so); True or "rotation" (default): the gyro's
        rotation; "flow": the rotation, then the optical flow between the frames on either side of
        frame k; "flow-sharp": as "flow" where the median move is at least
        :data:`emulator.core.native.SHARP_MOTION_PX`, else none (:data:`emulator.core.native.WARP_MODES`).
    motion_stops_per_frame, saturation_limit : float
        The native selector's weight of one frame of offset and its clipping margin
        (:data:`emulator.core.native.MOTION_STOPS_PER_FRAME`, :data:`emulator.core.native.SATURATION_LIMIT`).
    blur_stops_per_px : float or None
        None (default): the selector leaves blur out; a number: it is blur-aware, with this weight
        per pixel of predicted excess blur (:data:`emulator.core.native.BLUR_STOPS_PER_PX`).
    """

    #: Frames are decoded on demand and memoised per frame, so ticks are independent (see EmulatedProvider).
    ticks_ahead = 2
    #: What a tick is (progress, reports), and the columns it adds to ``exposures.csv``.
    unit = "frames"
    columns = NATIVE_COLUMNS

    @classmethod
    def for_run(cls, sequence, config: RunConfig, response, *, noise=None, stats=None, blur=None):
        """The provider of a native-rate run (:meth:`RunConfig.provider_for`): ``config``'s warp, and the
        blur-aware selector's weight where ``config.native_blur_aware``."""
        return cls(sequence, config, response, noise=noise, stats=stats, blur=blur, warp=config.warp_mode,
                   blur_stops_per_px=BLUR_STOPS_PER_PX if config.native_blur_aware else None)

    def __init__(self, sequence, config: RunConfig, response, *, cameras=None, noise=None,
                 stats: RunStats | None = None, blur=None, motion="auto", warp: bool | str = True,
                 motion_stops_per_frame: float = MOTION_STOPS_PER_FRAME,
                 saturation_limit: float = SATURATION_LIMIT, blur_stops_per_px: float | None = None) -> None:
        self.sequence = sequence
        self.response = response
        self.white, self.black = int(sequence.white_level), int(sequence.black_level)
        if cameras is None:
            cams = tuple(c for c in CAMERAS if c in sequence.cameras)
            cameras = ((METHOD_CAMERA,) + tuple(c for c in cams if c != METHOD_CAMERA)) if METHOD_CAMERA in cams \
                else cams
        self.cameras = tuple(cameras)
        self.noise, self.blur = noise, blur
        self.skip_partial = bool(getattr(config, "skip_partial", False))
        self.stats = stats if stats is not None else RunStats()
        self.latency_ticks = int(getattr(config, "latency_frames", 1))
        self.motion_stops_per_frame = float(motion_stops_per_frame)
        self.saturation_limit = float(saturation_limit)
        self.frames = RecordedFrames(sequence, self.cameras)
        if self.latency_ticks >= len(self.frames):  # no proposal would ever be used: refused, not ranked
            raise PlaybackError(f"latency_frames {self.latency_ticks}: must be below the recording's frame count "
                                f"({len(self.frames)} frames at native rate; --latency-frames)")
        self.window = WINDOW_CYCLES * max(1, len(sequence.brackets))
        mode = {True: "rotation", False: "none"}.get(warp, warp) if isinstance(warp, bool) else str(warp)
        if mode not in WARP_MODES:
            raise PlaybackError(f"native warp must be one of {', '.join(WARP_MODES)}, got {warp!r}")
        self.warp_mode = mode
        self.blur_stops_per_px = None if blur_stops_per_px is None else float(blur_stops_per_px)
        needs_motion = mode != "none" or self.blur_stops_per_px is not None
        self.motion = self._motion(motion) if needs_motion else None
        self.warp = mode != "none" and self.motion is not None  #: neighbours are moved (a gyro and a mode)
        self._velocity: dict = {}
        self._blur: dict = {}
        self._images: dict = {}
        self._not_covered: set = set()  # frames whose neighbour went unwarped: the gyro does not cover them
        self._lock = threading.Lock()
        self._shapes: dict = {}

    def _motion(self, motion):
        if motion is None or motion != "auto":
            return motion
        if self.blur is not None:
            return self.blur.motion
        why = None
        if getattr(self.sequence, "imu", None) is None:
            why = "no imu/imu.csv"
        else:
            try:
                return recording_motion(self.sequence, stamp=recording_stamp(self.sequence))
            except CalibrationError as exc:  # none found, or one that cannot be read: say which
                why = "no camera calibration (left.yaml)" if find_camera_calibration(self.sequence) is None \
                    else f"invalid camera calibration ({exc})"
        warnings.warn(f"{self.sequence.path}: {why}; at native rate a neighbour frame is used without undoing the "
                      "camera's rotation since its instant", NativeWarpWarning, stacklevel=2)
        return None

    def run_json(self) -> dict:
        """What ``run.json`` records of this provider: :meth:`describe` under ``native``."""
        return {NATIVE_RATE: self.describe()}

    def finish_run_json(self, run_json: dict) -> None:
        """Add what the run found out to ``run.json``'s native record (:meth:`gyro_coverage`)."""
        coverage = self.gyro_coverage()
        if coverage and isinstance(run_json.get(NATIVE_RATE), dict):
            run_json[NATIVE_RATE].update(coverage)

    def describe(self) -> dict:
        """What ``run.json`` records under ``native``."""
        return {"latency_frames": self.latency_ticks, "window_frames": self.window, "n_frames": len(self.frames),
                "motion_stops_per_frame": self.motion_stops_per_frame, "saturation_limit": self.saturation_limit,
                "warp": ("rotation from the gyro" if self.warp else "none"),
                **({"warp_resample": WARP_RESAMPLE, "stamp": self.motion.stamp} if self.warp else {}),
                **({"warp_mode": self.warp_mode} if self.warp_mode in ("flow", "flow-sharp") else {}),
                **({"sharp_motion_px": SHARP_MOTION_PX} if self.warp and self.warp_mode == "flow-sharp" else {}),
                **({"blur_stops_per_px": self.blur_stops_per_px} if self.blur_stops_per_px is not None else {}),
                "benchmarked_frames": sorted(k for k in self.frames.benchmarked if k is not None)}

    @property
    def tick_indices(self) -> list[int]:
        return list(range(len(self.frames)))

    def images(self, j: int) -> CycleImages:
        """The decoded images of frame ``j``'s cycle (each bracket decoded once)."""
        cycle = self.frames.cycles[j]
        with self._lock:
            hit = self._images.get(cycle.index)
            if hit is None:
                hit = self._images[cycle.index] = CycleImages(cycle, self.white, self.black, self.stats, self.noise,
                                                               self._shapes, self.blur)
            return hit

    def _forget(self, k: int) -> None:
        """Drop the decoded cycles no tick from ``k`` on can reach (a dropped one is decoded again if asked)."""
        oldest = self.frames.cycles[max(0, k - self.window - self.ticks_ahead - 2)].index
        with self._lock:
            for c in [c for c in self._images if c < oldest]:
                del self._images[c]
            for key in [key for key in self._velocity if key[1] < k - self.window - self.ticks_ahead - 2]:
                del self._velocity[key]

    def _window_s(self, j: int, exposure_ms: float) -> tuple[float, float]:
        """The window (s, the gyro's clock) of an image of ``exposure_ms`` stamped at frame ``j``'s timestamp."""
        return exposure_window_s(self.motion.t_s(self.frames.timestamps[j]), exposure_ms, self.motion.stamp)

    def rotation(self, j: int, k: int, source_ms: float, target_ms: float):
        """The camera's rotation from the middle of the window frame ``j``'s image stands for (``source_ms``)
        to the middle of frame ``k``'s window at ``target_ms`` (which starts where frame k's shot started)."""
        a, b = self._window_s(j, source_ms)
        start = self._window_s(k, self.frames.exposures[k])[0]
        return rotation_between(self.motion.omega, 0.5 * (a + b), start + target_ms * 5e-4)

    def emulate(self, camera: str, j: int, k: int, ratio: float, table, target_ms: float):
        """Frame ``j``'s bracket emulated at ``ratio`` for frame ``k``: ``(image, inside_fraction, warp_deg)``."""
        e = self.frames.exposures[j]
        out = self.images(j)._emulate(camera, e, ratio, table, self.stats)  # the cycle rate's emulation
        if j == k:
            return readonly_view(out), 1.0, 0.0
        blurred = self.blur is not None and target_ms > e  # the emulated image stands for the target's window
        R, H, disp = self._geometry(camera, j, k, target_ms if blurred else e, target_ms, out.shape)
        if R is None:
            return readonly_view(out), 1.0, math.nan
        angle = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(R) - 1.0) / 2.0))))
        if disp is not None:
            warped, inside = warp_with_flow(out, H, disp, self.response)
        else:  # the rotation warp; also the flow warp's where frame k lacks a neighbour on one side
            warped, inside = warp_to_instant(out, H, self.response)
        return readonly_view(warped), inside, angle

    def gyro_coverage(self) -> dict:
        """What ``run.json`` adds under ``native`` after the run: how many frames used a neighbour without
        a warp because the gyro does not cover the rotation, and one line saying so (none: nothing)."""
        n = len(self._not_covered)
        if self.motion is None or not n:
            return {}
        return {"frames_not_warped": n, "gyro_note": (
            f"{n} of {len(self.frames)} frames used a neighbour frame without a warp: the gyro does not cover the "
            f"rotation (its record ends early, its stamps are in another unit, or a hole over {GYRO_HOLE_S:g} s)")}

    def geometry(self, camera: str, j: int, k: int, source_ms: float, target_ms: float, shape):
        """How :meth:`emulate` moves frame ``j``'s image (of ``shape``, standing for ``source_ms``) to frame ``k``:
        ``(H, displacement)`` (:func:`emulator.core.native.instant_maps`), ``(None, None)`` where it is not moved."""
        return self._geometry(camera, j, k, source_ms, target_ms, shape)[1:]

    def _geometry(self, camera: str, j: int, k: int, source_ms: float, target_ms: float, shape):
        """``(R, H, displacement)`` of :meth:`geometry`; ``(None, None, None)`` where the image is not moved."""
        if j == k or self.motion is None or self.warp_mode == "none":
            return None, None, None
        R = self.rotation(j, k, source_ms, target_ms)
        if R is None:  # the gyro does not cover it (ends early, another clock, a hole): no warp, counted
            self._not_covered.add(k)
            return None, None, None
        K, _ = self.motion.K(camera, (shape[1], shape[0]))
        disp = self.displacement(camera, j, k, source_ms, target_ms) if self.warp_mode != "rotation" else None
        H = rotation_homography(K, R)
        if self.warp_mode == "flow-sharp":  # decided on the first camera's move, so a stereo pair is warped alike
            lead = self.cameras[0]
            if camera != lead:
                H_lead = rotation_homography(self.motion.K(lead, (shape[1], shape[0]))[0], R)
                moved = median_motion_px(H_lead, self.displacement(lead, j, k, source_ms, target_ms), shape)
            else:
                moved = median_motion_px(H, disp, shape)
            if moved < SHARP_MOTION_PX:
                return None, None, None
        return R, H, disp

    def _middle_s(self, j: int, exposure_ms: float) -> float:
        a, b = self._window_s(j, exposure_ms)
        return 0.5 * (a + b)

    def displacement(self, camera: str, j: int, k: int, source_ms: float, target_ms: float):
        """The flow warp's motion of frame ``j``'s image (standing for ``source_ms``) to frame ``k``'s instant after
        the rotation: the image velocity at frame k (:meth:`velocity`) times the time between the two, or None."""
        v = self.velocity(camera, k)
        if v is None:
            return None
        t_k = self._window_s(k, self.frames.exposures[k])[0] + target_ms * 5e-4
        return v * np.float32(t_k - self._middle_s(j, source_ms))

    def velocity(self, camera: str, k: int):
        """Image velocity at frame ``k`` (full-resolution px/s on the binned grid) from the nearest frames before and
        after it present on every camera, each turned to frame k's instant (never frame k's own image); None
        where one side has none or the gyro does not cover them.  Memoised per camera and frame."""
        key = (camera, k)
        with self._lock:
            if key in self._velocity:
                return self._velocity[key]
        fr = self.frames
        before = [j for j in range(max(0, k - self.window), k) if fr.complete[j]]
        after = [j for j in range(k + 1, min(len(fr), k + self.window + 1)) if fr.complete[j]]
        v = None
        if before and after:
            a, b, e_k = before[-1], after[0], fr.exposures[k]
            grays, Hs = [], []
            for j in (a, b):
                raw = self.images(j).get(camera, fr.exposures[j])[0]
                R = self.rotation(j, k, fr.exposures[j], e_k)
                if R is None:
                    break
                K, _ = self.motion.K(camera, (raw.shape[1], raw.shape[0]))
                grays.append(radiance_gray(raw, fr.exposures[j], self.response))
                Hs.append(rotation_homography(K, R))
            if len(grays) == 2:
                dt = self._middle_s(b, fr.exposures[b]) - self._middle_s(a, fr.exposures[a])
                v = flow_velocity(grays[0], Hs[0], grays[1], Hs[1], dt)
        with self._lock:
            self._velocity[key] = v
        return v

    def excess_blur_px(self, j: int, k: int, target_ms: float) -> float:
        """Predicted blur of frame ``j``'s window beyond a capture of ``target_ms`` at frame ``k`` (px, largest over
        the image's 3x3 grid, the first camera; 0 without a gyro, or where it does not cover the windows)."""
        if self.motion is None:
            return 0.0
        cam = self.cameras[0]
        shape = self._shapes.get("shape")
        K, size = self.motion.K(cam, None if shape is None else (shape[0][1], shape[0][0]))
        omega = as_angular_velocity(self.motion.omega)

        def blur(key, t0, t1):
            with self._lock:
                hit = self._blur.get(key)
            if hit is None:
                hit = window_blur(omega, K, size, t0, t1).max_px
                with self._lock:
                    self._blur[key] = hit
            return hit

        e = self.frames.exposures[j]
        src = blur(("src", j), *self._window_s(j, e))
        start = self._window_s(k, self.frames.exposures[k])[0]
        tgt = blur(("tgt", k, float(target_ms)), start, start + target_ms * 1e-3)
        out = src - tgt
        return float(out) if math.isfinite(out) else 0.0

    def tick(self, k: int, *, hidden: bool = False) -> NativeTick:
        """Frame ``k``'s tick; ``hidden``: without frame k's own shots (on any camera) among its sources."""
        self._forget(k)
        return NativeTick(self, k, hidden)

    def ticks(self):
        for k in range(len(self.frames)):
            yield self.tick(k)
