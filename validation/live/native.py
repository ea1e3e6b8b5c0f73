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
from collections.abc import Callable, Iterator
from dataclasses import replace

import numpy as np

from validation.live.config import FIXED_INSTANT_BRACKET_INDEX, LiveError

__all__ = ["NATIVE_FRAME_RATE_HZ", "NATIVE_LATENCY_FRAMES", "GRID_TOLERANCE_NS", "shot_timestamps",
           "window_start_shoot", "native_rate_loop"]

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
    sequence : emulator.dataset.Sequence or path
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
    from emulator.autoexposure.methodset import build_methods
    from emulator.dataset import CAMERAS
    from emulator.errors import PlaybackError
    from emulator.playback import LiveRateProvider, closed_loop
    from validation.live.loops import live_setup, make_shoot

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
    built = build_methods(methods, mode=cfg.mode, response=response, options=cfg.options)
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
