"""Live image providers: each method's own camera shoots at the method's exposure.

The emulator cannot make a live shot itself (it has no scene); the caller passes a
``shoot`` function, e.g. the synthetic camera over a walk's radiance
(:mod:`validation.live`)::

    shoot(timestamp_ns: int, camera: str, exposure_ms: float, index: int) -> numpy.ndarray

returning the raw image (``uint16``, (H, W), DN) that ``camera`` captures with
``exposure_ms`` over the window centred on ``timestamp_ns``; ``index`` is the tick (cycle
or frame) for seeding.  Within one tick the providers call ``shoot`` once per (camera,
exposure): two methods asking the same exposure get the same (read-only) image, as two
methods with the same target share one emulated image.

Two providers, both driven by :func:`emulator.playback.loop.closed_loop`:

* :class:`LiveCycleProvider`: one shot per bracket cycle of a recording, at the instant of
  the bracket the emulator would select for the method's target (``instant="selected"``)
  or of a fixed bracket of the cycle (``instant="fixed"``): the cycle-rate live loop.
* :class:`LiveRateProvider`: a camera running at its own frame rate (default the
  recorder's 22 fps), frame k starting at ``start_ns + k / frame_rate_hz``, each shot
  timestamped at mid-exposure (``start + exposure / 2``), and an exposure latency of
  ``latency_frames`` (default 1): a proposal made after reading frame k is first used for
  frame ``k + 1 + latency_frames``; frames in between keep the exposures already queued.
  The method reads every frame.  Use it for native-rate live runs::

      from emulator.playback import LiveRateProvider, RunConfig, closed_loop
      provider = LiveRateProvider(shoot, n_frames=220, white_level=4094, black_level=0)
      for cs in closed_loop(provider, {"m": method}, RunConfig(), keep_images=True):
          ...  # cs.cycle is the frame index; cs.steps["m"].timestamp_ns the mid-exposure instant

A live shot's :class:`~emulator.playback.loop.Shot` has ``ratio`` 1, ``valid_fraction`` 1 and
``bracket_saturated_fraction`` equal to its own saturated fraction; ``bracket_ms`` is the
bracket whose instant was used (cycle rate) or the exposure itself (native rate).
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np

from emulator.core.dataset import CAMERAS
from emulator.errors import PlaybackError
from emulator.playback.config import RunConfig
from emulator.playback.loop import Shot
from emulator.core.select import saturated_fraction, select

__all__ = ["LiveCycleProvider", "LiveRateProvider", "INSTANTS", "BOREALHDR_FRAME_RATE_HZ"]

#: Frame rate of the BorealHDR recorder (one shot every ~46 ms).
BOREALHDR_FRAME_RATE_HZ = 22.0
#: Where a cycle-rate live shot is taken: at the selected bracket's instant, or at a fixed bracket's.
INSTANTS = ("selected", "fixed")


class _Shots:
    """The shots of one tick, one per (camera, exposure, instant); thread-safe."""

    def __init__(self, shoot: Callable, index: int, white: int, black: int) -> None:
        self.shoot, self.index, self.white, self.black = shoot, index, white, black
        self._lock = threading.Lock()
        self._locks: dict = {}
        self._data: dict = {}

    def get(self, timestamp_ns: int, camera: str, exposure_ms: float) -> tuple[np.ndarray, float]:
        key = (int(timestamp_ns), camera, float(exposure_ms))
        with self._lock:
            lock = self._locks.setdefault(key, threading.Lock())
        with lock:
            hit = self._data.get(key)
            if hit is None:
                img = np.asarray(self.shoot(int(timestamp_ns), camera, float(exposure_ms), self.index))
                if img.dtype != np.uint16 or img.ndim != 2:
                    raise PlaybackError(f"shoot() must return a (H, W) uint16 raw image, got {img.dtype} {img.shape}")
                img.setflags(write=False)
                hit = (img, saturated_fraction(img, white_level=self.white, black_level=self.black))
                self._data[key] = hit
            return hit


def _shot(shots: _Shots, cameras, timestamp_ns: int, exposure_ms: float, bracket_ms: float, want_right: bool,
          missing: dict) -> Shot:
    left, sat = shots.get(timestamp_ns, cameras[0], exposure_ms)
    shot = Shot(timestamp_ns=int(timestamp_ns), exposure_ms=float(exposure_ms), bracket_ms=float(bracket_ms), ratio=1.0,
                left=left, saturated_fraction=sat, valid_fraction=1.0, bracket_saturated_fraction=sat,
                missing_left_ms=tuple(missing.get(cameras[0], ())),
                missing_right_ms=tuple(missing.get(cameras[1], ())) if len(cameras) > 1 else ())
    if want_right and len(cameras) > 1:
        shot.right, shot.saturated_fraction_right = shots.get(timestamp_ns, cameras[1], exposure_ms)
        shot.valid_fraction_right = 1.0
    return shot


class _CycleTick:
    def __init__(self, provider: "LiveCycleProvider", cycle) -> None:
        p = self.provider = provider
        self.cycle = cycle
        self.index = cycle.index
        self.missing = {c: cycle.missing(c) for c in p.cameras}
        self.avail = cycle.available(p.cameras)
        self.skipped = None if self.avail else "no bracket present for every camera"
        self.shots = _Shots(p.shoot, cycle.index, p.white, p.black)
        self._raws: dict = {}
        self._lock = threading.Lock()

    def _bracket_saturation(self, e: float) -> float:
        with self._lock:
            if e not in self._raws:
                raw = self.cycle.frames[self.provider.cameras[0]][e].load()
                self._raws[e] = saturated_fraction(raw, white_level=self.provider.white, black_level=self.provider.black)
            return self._raws[e]

    def shot(self, target_ms: float, want_right: bool = False) -> Shot:
        p = self.provider
        if p.instant == "selected":
            sats = {e: (lambda e=e: self._bracket_saturation(e)) for e in self.avail}
            key = select(p.selector, target_ms, sats, white_level=p.white, black_level=p.black)
        else:
            key = self.avail[min(p.fixed_bracket_index, len(self.avail) - 1)]
        ts = int(self.cycle.frames[p.cameras[0]][key].timestamp_ns)
        return _shot(self.shots, p.cameras, ts, target_ms, key, want_right, self.missing)


class LiveCycleProvider:
    """Live shots once per bracket cycle of ``sequence`` (see the module notes).

    ``sequence`` gives the cycles, their shot instants and (``instant="selected"``) the
    brackets the selector looks at (``config.selector``); ``fixed_bracket_index`` picks the
    bracket of ``instant="fixed"`` among the brackets present.
    """

    latency_ticks = 0

    def __init__(self, sequence, shoot: Callable, config: RunConfig, *, instant: str = "selected",
                 fixed_bracket_index: int = 0, cameras=None) -> None:
        if instant not in INSTANTS:
            raise PlaybackError(f"instant must be one of {', '.join(INSTANTS)}, got {instant!r}")
        self.sequence = sequence
        self.shoot = shoot
        self.selector = config.selector
        self.instant = instant
        self.fixed_bracket_index = int(fixed_bracket_index)
        self.cameras = tuple(cameras) if cameras is not None else tuple(c for c in CAMERAS if c in sequence.cameras)
        self.white, self.black = int(sequence.white_level), int(sequence.black_level)

    def ticks(self):
        for cycle in self.sequence.cycles:
            yield _CycleTick(self, cycle)


class _FrameTick:
    skipped = None

    def __init__(self, provider: "LiveRateProvider", index: int) -> None:
        p = self.provider = provider
        self.index = index
        self.missing = {c: [] for c in p.cameras}
        self.start_ns = int(p.start_ns) + int(round(index * 1e9 / p.frame_rate_hz))
        self.shots = _Shots(p.shoot, index, p.white, p.black)

    def shot(self, target_ms: float, want_right: bool = False) -> Shot:
        mid_ns = self.start_ns + int(round(float(target_ms) * 1e6 / 2.0))  # mid-exposure
        return _shot(self.shots, self.provider.cameras, mid_ns, target_ms, target_ms, want_right, self.missing)


class LiveRateProvider:
    """A live camera at its own frame rate, with an exposure latency (see the module notes).

    Parameters
    ----------
    shoot : callable(timestamp_ns, camera, exposure_ms, frame_index) -> uint16 (H, W)
        The capture; ``timestamp_ns`` is mid-exposure, the window ``timestamp_ns -+ exposure_ms / 2``.
    n_frames : int
        Frames to run (ticks).
    white_level, black_level : int
        The camera's levels (saturated fractions).
    start_ns : int
        Start of frame 0.
    frame_rate_hz : float
        Frames per second (default :data:`BOREALHDR_FRAME_RATE_HZ`, 22).  An exposure longer
        than the frame period keeps the frame grid (the window overlaps the next frame's start).
    latency_frames : int
        Frames a proposal waits before it is used (default 1): proposed after frame k, used
        from frame ``k + 1 + latency_frames``.
    cameras : tuple of str
        Default ``("left",)``; the first is the one methods read.
    """

    def __init__(self, shoot: Callable, *, n_frames: int, white_level: int, black_level: int, start_ns: int = 0,
                 frame_rate_hz: float = BOREALHDR_FRAME_RATE_HZ, latency_frames: int = 1,
                 cameras=("left",)) -> None:
        if isinstance(n_frames, bool) or int(n_frames) < 0:
            raise PlaybackError(f"n_frames must be a non-negative integer, got {n_frames!r}")
        if not (np.isfinite(frame_rate_hz) and frame_rate_hz > 0):
            raise PlaybackError(f"frame_rate_hz must be finite and positive, got {frame_rate_hz!r}")
        if isinstance(latency_frames, bool) or int(latency_frames) < 0:
            raise PlaybackError(f"latency_frames must be an integer >= 0, got {latency_frames!r}")
        if not 0 <= int(black_level) < int(white_level):
            raise PlaybackError(f"levels must satisfy 0 <= black < white, got {black_level}..{white_level}")
        self.shoot = shoot
        self.n_frames = int(n_frames)
        self.white, self.black = int(white_level), int(black_level)
        self.start_ns = int(start_ns)
        self.frame_rate_hz = float(frame_rate_hz)
        self.latency_ticks = int(latency_frames)
        self.cameras = tuple(cameras)

    def frame_start_ns(self, index: int) -> int:
        """Start of frame ``index``'s exposure, ns."""
        return self.start_ns + int(round(index * 1e9 / self.frame_rate_hz))

    def ticks(self):
        for k in range(self.n_frames):
            yield _FrameTick(self, k)
