"""Bracket-cycle capture: a radiance source -> a BorealHDR-layout recording plus ground truth.

The camera sweeps the brackets (default 1, 2, 4, 8, 16, 32 ms), one shot per frame period
(default 22 frames/s), each shot at its own timestamp; a stereo rig shoots both cameras at
the same instants, the right one ``baseline_m`` along the left camera's x axis.  For every
shot the source gives the radiance and pose of each camera at that instant (the scene is
sampled at the trigger instant: no motion blur within an exposure), and the camera model
(:func:`synth.capture`) turns it into a raw image.

Written layout (``emulator.io.borealhdr.load_sequence`` reads the first two lines and
ignores the rest; every file goes through :mod:`emulator.io`)::

    <seq>/camera_left/<exposure_ms>/<timestamp_ns>.png    16-bit PNG, raw Bayer DN
    <seq>/camera_right/<exposure_ms>/<timestamp_ns>.png   (stereo)
    <seq>/imu/imu.csv                  the walk's gyro and accelerometer (``imu=``; scenes.synthesize)
    <seq>/exposim.json                 levels, brackets, fps, baseline, camera, seed, source, ...
    <seq>/calibration/response.txt     the exact inverse response, one sample per DN (pcalib)
    <seq>/calibration/left.yaml        ROS camera_info (right.yaml for stereo: P[0,3] = -fx * B)
    <seq>/ground_truth/poses_left.txt  TUM: timestamp_s tx ty tz qx qy qz qw, camera-to-world
    <seq>/ground_truth/poses_right.txt (stereo)
    <seq>/ground_truth/radiance/camera_left/<timestamp_ns>.exr             (save_radiance)
    <seq>/ground_truth/captures_noiseless/camera_left/<exposure_ms>/<timestamp_ns>.png
    <seq>/ground_truth/captures_noisy/camera_left/<exposure_ms>/<timestamp_ns>.png
                                       (gt_exposures_ms; which of the two: gt_captures)

Poses are 4x4 camera-to-world in the camera frame x right, y down, z forward.  The whole
recording is written into a hidden staging folder beside ``out_dir`` and renamed into place
at the end, so an interrupted run leaves no dataset (and no file) under a final name; an
existing non-empty ``out_dir`` is replaced only with ``overwrite=True``, only if it is an
exposim dataset, and never when it holds files synth did not write (:mod:`synth.dataset`,
which also writes the description files and lists every file in ``exposim-files.json``).
"""

from __future__ import annotations

import functools
import math
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from emulator.io.borealhdr import CAMERA_FOLDERS, exposure_folder_name, write_frame, write_recording_metadata
from emulator.io.camera_info import write_camera_info
from emulator.io.exr import write_exr
from emulator.io.imu import IMU_FILE, write_imu
from emulator.io.pcalib import write_pcalib
from emulator.io.png import write_png16
from emulator.io.tum import write_tum
from synth.camera import Camera, check_exposure_ms
from synth.dataset import (
    camera_info,
    check_target,
    load_camera,
    new_staging,
    publish,
    recording_metadata,
    write_manifest,
)
from synth.errors import RadianceError, SourceError, SynthError
from synth.imaging import capture
from synth.presets import response_table
from synth.source import check_rig, describe_source, frame_getter, source_frame

__all__ = [
    "BRACKETS_MS",
    "FPS",
    "BASELINE_M",
    "GT_CAPTURES",
    "Shot",
    "shot_schedule",
    "capture_sequence",
    "load_camera",
    "camera_info",
    "GENERATOR",
]

#: The BorealHDR bracket set, ms (paper section V-A).
BRACKETS_MS: tuple[float, ...] = (1.0, 2.0, 4.0, 8.0, 16.0, 32.0)
#: Shots per second (paper: 22 frames/s).
FPS = 22.0
#: Stereo baseline, m (paper: 18 cm).
BASELINE_M = 0.18
#: Which ground-truth captures ``gt_captures`` asks for.
GT_CAPTURES = {"noiseless": ("noiseless",), "noisy": ("noisy",), "both": ("noiseless", "noisy")}
#: Name recorded in ``exposim.json``.
GENERATOR = "exposim.synth.capture_sequence"


@dataclass(frozen=True)
class Shot:
    """One trigger of the bracket sweep.

    Attributes
    ----------
    index : int
        Shot number from the start of the recording (0-based).
    timestamp_ns : int
        Trigger time, nanoseconds (the image file name).
    exposure_ms : float
        Exposure time, ms.
    cycle : int
        Sweep number (0-based; a recording that starts mid-sweep has a partial sweep 0).
    bracket_index : int
        Position of the exposure in the sorted bracket set.
    time_s : float
        Seconds since the recording start, ``(timestamp_ns - start_time_ns) / 1e9``: the
        instant the radiance source is asked for.
    """

    index: int
    timestamp_ns: int
    exposure_ms: float
    cycle: int
    bracket_index: int
    time_s: float


def _check_brackets(brackets_ms) -> tuple[float, ...]:
    try:
        values = tuple(check_exposure_ms(b, "brackets_ms") for b in brackets_ms)
    except TypeError:
        raise SynthError(f"brackets_ms must be a sequence of exposures in ms, got {brackets_ms!r}") from None
    if not values:
        raise SynthError("brackets_ms is empty")
    if any(b >= a for a, b in zip(values[1:], values[:-1])):
        raise SynthError(f"brackets_ms must be strictly increasing (one sweep, short to long), got {values}")
    return values


def shot_schedule(
    n_shots: int,
    *,
    brackets_ms=BRACKETS_MS,
    fps: float = FPS,
    start_bracket_index: int = 0,
    start_time_ns: int = 0,
) -> list[Shot]:
    """The shots of a bracket-cycling recording.

    Shot k is triggered at ``start_time_ns + round(k * 1e9 / fps)`` ns with exposure
    ``brackets_ms[(start_bracket_index + k) % n]``; ``start_bracket_index > 0`` starts
    mid-sweep.  Refuses an exposure longer than the frame period ``1000 / fps`` ms.
    """
    brackets = _check_brackets(brackets_ms)
    if isinstance(n_shots, bool) or not isinstance(n_shots, (int, np.integer)) or n_shots < 1:
        raise SynthError(f"the number of shots must be a positive integer, got {n_shots!r}")
    try:
        fps = float(fps)
    except (TypeError, ValueError):
        raise SynthError(f"fps must be a number of frames per second, got {fps!r}") from None
    if not (math.isfinite(fps) and fps > 0):
        raise SynthError(f"fps must be finite and positive, got {fps!r}")
    if brackets[-1] > 1000.0 / fps:
        raise SynthError(
            f"the longest bracket ({brackets[-1]:g} ms) exceeds the frame period at {fps:g} frames/s "
            f"({1000.0 / fps:.3g} ms)"
        )
    n = len(brackets)
    if isinstance(start_bracket_index, bool) or not isinstance(start_bracket_index, (int, np.integer)) or not (
        0 <= start_bracket_index < n
    ):
        raise SynthError(f"start_bracket_index must be an integer in [0, {n - 1}], got {start_bracket_index!r}")
    if isinstance(start_time_ns, bool) or not isinstance(start_time_ns, (int, np.integer)) or start_time_ns < 0:
        raise SynthError(f"start_time_ns must be a non-negative integer, got {start_time_ns!r}")
    shots = []
    for k in range(int(n_shots)):
        pos = int(start_bracket_index) + k
        offset_ns = int(round(k * 1e9 / fps))
        shots.append(Shot(k, int(start_time_ns) + offset_ns, brackets[pos % n], pos // n, pos % n, offset_ns * 1e-9))
    return shots


# ---------------------------------------------------------------------------- writer
def capture_sequence(
    source,
    out_dir: str | os.PathLike,
    camera: Camera,
    *,
    brackets_ms=BRACKETS_MS,
    fps: float = FPS,
    n_cycles: int | None = None,
    n_shots: int | None = None,
    start_bracket_index: int = 0,
    start_time_ns: int = 0,
    stereo: bool = True,
    baseline_m: float = BASELINE_M,
    seed: int = 0,
    noise: bool = True,
    gt_exposures_ms=(),
    gt_captures: str = "noiseless",
    gt_cameras=None,
    save_radiance: bool = False,
    overwrite: bool = False,
    progress=None,
    source_description=None,
    imu=None,
) -> Path:
    """Capture a bracket-cycling recording of a radiance source and write it with its ground truth.

    Parameters
    ----------
    source : callable or list
        ``source(timestamp_s, camera) -> (radiance, pose)`` with ``timestamp_s`` the
        seconds since the recording start (float), ``camera`` ``"left"`` or ``"right"``
        (a callable with ``exposure_aware = True`` is called as ``source(timestamp_s, camera,
        exposure_ms)`` and returns the radiance integrated over ``[t, t + exposure]``, also for
        each ground-truth exposure),
        ``radiance`` float32 (H, W, 3) or (H, W) in W m^-2 sr^-1 and ``pose`` a 4x4
        camera-to-world matrix (x right, y down, z forward).  Or a list with one entry per
        shot: ``(radiance, pose)``, or ``{"left": (radiance, pose), "right": (...)}`` for
        stereo.  A stereo source must place the right camera ``baseline_m`` along the left
        camera's x axis with the same orientation (checked to 1e-6).
    out_dir : path
        Dataset folder to create.
    camera : Camera
        The camera model (both cameras of a stereo rig are identical).
    brackets_ms : sequence of float
        One sweep, strictly increasing, ms.
    fps : float
        Shots per second; every bracket must fit in the frame period.
    n_cycles, n_shots : int or None
        Length: ``n_shots`` shots, or enough to end sweep ``n_cycles - 1`` (counting a
        partial first sweep when ``start_bracket_index > 0``), or for a list every frame.
    start_bracket_index : int
        Bracket of the first shot (> 0 starts mid-sweep, like the BorealHDR right camera).
    start_time_ns : int
        Timestamp of the first shot, ns (file names; TUM timestamps are these in seconds).
    stereo : bool
        Capture the right camera too.
    baseline_m : float
        Stereo baseline, m (written to ``right.yaml``).
    seed : int
        Base seed.  The noise of camera c (0 left, 1 right) at shot k comes from
        ``numpy.random.SeedSequence([seed, c, k])``; that of its noisy ground-truth
        capture at ``gt_exposures_ms[j]`` from ``SeedSequence([seed, c, k, 1 + j])``.
    noise : bool
        Noisy (default) or exact noiseless bracket captures.
    gt_exposures_ms : sequence of float
        Ground-truth captures at these exposures, at every shot's instant and pose.
    gt_captures : str
        ``"noiseless"`` (exact, ``ground_truth/captures_noiseless``), ``"noisy"``
        (``captures_noisy``, independent noise) or ``"both"``.
    gt_cameras : sequence of str or None
        The cameras that get ground-truth captures (default: every camera).
    save_radiance : bool
        Also write each shot's radiance as OpenEXR.
    overwrite : bool
        Replace an existing ``out_dir`` that holds an exposim dataset and nothing else
        (an empty folder is always used); a file synth did not write (or one changed since)
        is never deleted: :func:`synth.dataset.check_target` refuses, naming it.
    progress : callable or None
        Called as ``progress(shots_done, shots_total)`` after every shot.
    source_description : JSON-ready object or None
        Recorded in ``exposim.json``; default: ``source.describe()`` when it exists.
    imu : emulator.io.imu.ImuData or None
        The gyro and accelerometer of the walk, written as ``imu/imu.csv`` (BorealHDR format).

    Returns
    -------
    Path
        ``out_dir``.

    Raises
    ------
    OutputExistsError
        ``out_dir`` exists, is not empty and ``overwrite`` is False, or is not an exposim
        dataset, or holds files synth did not write (checked before any work and again
        before the final rename).
    SourceError, RadianceError, SynthError
        A bad source frame (named by shot, camera and timestamp) or bad arguments.
    """
    if not isinstance(camera, Camera):
        raise SynthError(f"camera must be a synth.Camera, got {type(camera).__name__}")
    out_dir = Path(out_dir)
    check_target(out_dir, overwrite)
    sides = ("left", "right") if stereo else ("left",)
    baseline_m = _check_baseline(baseline_m) if stereo else baseline_m
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise SynthError(f"seed must be a non-negative integer, got {seed!r}")
    if gt_captures not in GT_CAPTURES:
        raise SynthError(f"gt_captures must be one of {', '.join(GT_CAPTURES)}, got {gt_captures!r}")
    gt_exposures = tuple(check_exposure_ms(t, "gt_exposures_ms") for t in gt_exposures_ms)
    gt_sides = sides if gt_cameras is None else tuple(gt_cameras)
    if not gt_sides or not set(gt_sides) <= set(sides):
        raise SynthError(f"gt_cameras must name some of the recorded cameras ({', '.join(sides)}), got {gt_cameras!r}")
    brackets = _check_brackets(brackets_ms)
    get_frame, n_frames = frame_getter(source, stereo)
    n_shots = _count_shots(n_shots, n_cycles, n_frames, len(brackets), start_bracket_index)
    shots = shot_schedule(n_shots, brackets_ms=brackets, fps=fps, start_bracket_index=start_bracket_index,
                          start_time_ns=start_time_ns)

    staging = new_staging(out_dir)
    try:
        write = functools.partial(_write_shot, camera=camera, seed=seed, noise=noise, save_radiance=save_radiance,
                                  gt_kinds=GT_CAPTURES[gt_captures],
                                  gt_radiance=get_frame if getattr(source, "exposure_aware", False) else None)
        poses = _write_shots(staging, shots, sides, get_frame, write, baseline_m=baseline_m,
                             gt_sides=gt_sides, gt_exposures=gt_exposures, progress=progress)
        _write_ground_truth(staging, camera, shots, poses, imu=imu, baseline_m=baseline_m if stereo else 0.0)
        meta = recording_metadata(camera, shots, brackets, generator=GENERATOR,
                                  gt_captures_kinds=GT_CAPTURES[gt_captures], fps=fps, stereo=stereo,
                                  baseline_m=baseline_m, seed=seed, noise=noise, gt_exposures=gt_exposures,
                                  gt_cameras=[s for s in sides if s in gt_sides],
                                  save_radiance=save_radiance, start_time_ns=start_time_ns,
                                  start_bracket_index=start_bracket_index,
                                  source=describe_source(source, source_description),
                                  timestamps_note=getattr(source, "timestamps_note", None))
        write_recording_metadata(staging, meta)
        write_manifest(staging)
        publish(staging, out_dir, overwrite)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return out_dir


def _check_baseline(baseline_m) -> float:
    """The stereo baseline as a finite, positive float (m); anything else raises :class:`SynthError`."""
    try:
        baseline_m = float(baseline_m)
    except (TypeError, ValueError):
        raise SynthError(f"baseline_m must be a number of metres, got {baseline_m!r}") from None
    if not (math.isfinite(baseline_m) and baseline_m > 0):
        raise SynthError(f"baseline_m must be finite and positive, got {baseline_m!r}")
    return baseline_m


def _count_shots(n_shots, n_cycles, n_frames, n_brackets: int, start_bracket_index: int) -> int:
    """How many shots a capture takes: ``n_shots``, else enough to end sweep ``n_cycles - 1``, else every
    frame of a list source (``n_frames``); more shots than the list has frames raise :class:`SourceError`."""
    if n_shots is None:
        if n_cycles is not None:
            if isinstance(n_cycles, bool) or not isinstance(n_cycles, (int, np.integer)) or n_cycles < 1:
                raise SynthError(f"n_cycles must be a positive integer, got {n_cycles!r}")
            n_shots = int(n_cycles) * n_brackets - int(start_bracket_index)
        elif n_frames is not None:
            n_shots = n_frames
        else:
            raise SynthError("give n_cycles or n_shots for a callable source")
    if n_frames is not None and n_shots > n_frames:
        raise SourceError(f"{n_shots} shots need {n_shots} frames, the source list has {n_frames}")
    return n_shots


def _write_shots(staging: Path, shots, sides, get_frame, write, *, baseline_m: float, gt_sides, gt_exposures,
                 progress) -> dict[str, list]:
    """Ask the source for every shot of every camera, check the rig and write each (``write``: :func:`_write_shot`
    with the capture's settings); returns each camera's poses, in shot order."""
    poses = {side: [] for side in sides}
    for shot in shots:
        left_pose = None
        for c, side in enumerate(sides):
            where = f"shot {shot.index} ({side} camera, t = {shot.time_s:.6f} s)"
            radiance, pose = source_frame(get_frame, shot, side, where)
            if side == "left":
                left_pose = pose
            else:
                check_rig(left_pose, pose, baseline_m, where)
            poses[side].append(pose)
            write(staging, shot, side, c, radiance, where, gt_exposures=gt_exposures if side in gt_sides else ())
        if progress is not None:
            progress(shot.index + 1, len(shots))
    return poses


def _write_shot(staging: Path, shot, side: str, c: int, radiance, where: str, *, camera: Camera, seed: int,
                noise: bool, save_radiance: bool, gt_exposures: tuple, gt_kinds, gt_radiance) -> None:
    """Capture and write one shot of camera ``side`` (index ``c``), its radiance and its ground-truth captures.

    ``gt_radiance``: None (the ground truth sees the shot's radiance) or the exposure-aware
    frame getter, asked for each ground-truth exposure's own window.
    """
    try:
        raw = capture(radiance, shot.exposure_ms, camera,
                      seed=np.random.SeedSequence([seed, c, shot.index]), noise=noise)
    except RadianceError as exc:
        raise RadianceError(f"{where}: {exc}") from None
    write_frame(staging, side, shot.exposure_ms, shot.timestamp_ns, raw)
    folder = CAMERA_FOLDERS[side]
    if save_radiance:
        write_exr(staging / "ground_truth" / "radiance" / folder / f"{shot.timestamp_ns}.exr", radiance)
    for j, t in enumerate(gt_exposures):
        gt_rad = radiance if gt_radiance is None else gt_radiance(shot, side, t)[0]  # its own exposure window
        for kind in gt_kinds:
            gt = capture(gt_rad, t, camera, noise=kind == "noisy",
                         seed=np.random.SeedSequence([seed, c, shot.index, 1 + j]))
            write_png16(staging / "ground_truth" / f"captures_{kind}" / folder / exposure_folder_name(t)
                        / f"{shot.timestamp_ns}.png", gt)


def _write_ground_truth(staging: Path, camera: Camera, shots, poses: dict, *, imu, baseline_m: float) -> None:
    """The IMU, the ground-truth poses and the calibration (response table, camera info) of a recording."""
    sides = tuple(poses)
    if imu is not None:
        write_imu(staging.joinpath(*IMU_FILE), imu)
    gt_dir = staging / "ground_truth"
    for side in sides:
        write_tum(gt_dir / f"poses_{side}.txt", [s.timestamp_ns for s in shots], np.stack(poses[side]),
                  overwrite=False)
    calib = staging / "calibration"
    write_pcalib(calib / "response.txt", response_table(camera.response, camera.white_level))
    for side in sides:
        write_camera_info(calib / f"{side}.yaml", camera_info(camera, side, baseline_m))
