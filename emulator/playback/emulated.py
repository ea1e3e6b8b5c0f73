"""The emulated image provider: a recording's brackets emulated at each method's target (offline).

:class:`EmulatedProvider` yields one tick per cycle (one sweep of the brackets).  A tick's
:meth:`~EmulatedTick.shot` selects a bracket for the target (once per target, among the
brackets present for every camera; the first camera's saturation decides), emulates the
first camera's image (and the second's when asked) and checks that the stereo pair comes
from one capture instant.  A cycle's images are decoded at most once and only when some
method needs them; from each bracket's histogram the saturated and valid fractions of any
emulation follow without touching the pixels again; each ratio's lookup table is built
once (cached on the response) and methods with the same target share one emulated image.
Every image handed out is a read-only view of an array the provider owns
(:func:`~emulator.autoexposure.isolation.readonly_view`), which built-in methods read without
a copy.
"""

from __future__ import annotations

import threading
import time

import cv2
import numpy as np

from emulator.autoexposure.isolation import readonly_view
from emulator.core.dataset import CAMERAS, missing_text
from emulator.core.emulate import apply_lut
from emulator.errors import DatasetError
from emulator.playback.config import RATES, RunConfig, provides_rate
from emulator.playback.loop import Shot
from emulator.playback.records import RunStats
from emulator.core.select import select
from emulator.noise import consistent_noise

__all__ = ["EmulatedProvider", "EmulatedTick", "METHOD_CAMERA", "Memo", "CycleImages", "clip_fractions"]

#: Camera whose emulated image the methods read and whose saturation selects the bracket.
METHOD_CAMERA = "left"


class Memo:
    """``compute()`` once per key, whichever thread asks first (one lock per key)."""

    def _memo_init(self) -> None:
        self._lock = threading.Lock()
        self._locks: dict = {}
        self._data: dict = {}

    def _memo(self, key: tuple, compute):
        with self._lock:
            lock = self._locks.setdefault(key, threading.Lock())
        with lock:
            hit = self._data.get(key)
            if hit is None:
                hit = self._data[key] = compute()
            return hit


class CycleImages(Memo):
    """Decoded brackets of one cycle, each decoded at most once (thread-safe), with histograms."""

    def __init__(self, cycle, white_level: int, black_level: int, stats: RunStats, noise=None,
                 shapes: dict | None = None, blur=None) -> None:
        self.cycle = cycle
        self.shapes = shapes  # the run's image size, shared by every cycle: a frame of another size is refused
        self.white = white_level
        self.black = black_level
        self.stats = stats
        self.noise = noise  # None, or (NoiseModel, seed) for noise-consistent emulation
        self.blur = blur  # None, or a hook .apply(cycle, camera, exposure_ms, ratio, raw, out) -> out (blur-consistent)
        self._memo_init()

    def get(self, camera: str, exposure_ms: float) -> tuple[np.ndarray, np.ndarray]:
        return self._memo((camera, exposure_ms), lambda: self._decode(camera, exposure_ms))

    def _decode(self, camera: str, exposure_ms: float) -> tuple[np.ndarray, np.ndarray]:
        frame = self.cycle.frames[camera][exposure_ms]
        t0 = time.perf_counter()
        raw = frame.load()
        if self.shapes is not None:
            first = self.shapes.setdefault("shape", (raw.shape, frame.path))
            if raw.shape != first[0]:
                raise DatasetError(
                    f"{frame.path}: image is {raw.shape[1]}x{raw.shape[0]} pixels, but {first[1]} of the same "
                    f"recording is {first[0][1]}x{first[0][0]}; every image of a recording must have one size"
                )
        t1 = time.perf_counter()
        hist = cv2.calcHist([raw], [0], None, [self.white + 1], [0, self.white + 1]).ravel().astype(np.int64)
        t2 = time.perf_counter()
        self.stats.add("decode_s", t1 - t0)
        self.stats.add("histogram_s", t2 - t1, 0)
        hist.setflags(write=False)
        return readonly_view(raw), hist

    def emulated(self, camera: str, exposure_ms: float, ratio: float, table: np.ndarray, stats: RunStats) -> np.ndarray:
        """The bracket emulated at ``ratio`` (read-only; shared by methods with the same target)."""
        return self._memo((camera, exposure_ms, ratio),
                          lambda: self._emulate(camera, exposure_ms, ratio, table, stats))

    def _emulate(self, camera: str, exposure_ms: float, ratio: float, table: np.ndarray,
                 stats: RunStats) -> np.ndarray:
        raw, _ = self.get(camera, exposure_ms)
        if ratio == 1.0:
            return raw
        t0 = time.perf_counter()
        out = apply_lut(table, raw)
        if self.blur is not None:
            out = self.blur.apply(self.cycle, camera, exposure_ms, ratio, raw, out)
        if self.noise is not None:
            out = self._add_noise(camera, exposure_ms, ratio, raw, out)
        stats.add("emulate_s", time.perf_counter() - t0)
        return readonly_view(out)

    def _add_noise(self, camera: str, exposure_ms: float, ratio: float, raw: np.ndarray, plain: np.ndarray):
        """Noise-consistent emulation (``emulator.core.emulate``, ``noise="consistent"``), seeded by
        (seed, cycle, camera, bracket, ratio): independent of threads and of which method asks."""
        model, seed = self.noise
        words = np.array([exposure_ms, ratio], dtype=np.float64).view(np.uint32).tolist()
        rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(self.cycle.index),
                                                            CAMERAS.index(camera), *words]))
        return consistent_noise(raw, plain, ratio, model, rng)

    def saturated(self, camera: str, exposure_ms: float) -> float:
        _, hist = self.get(camera, exposure_ms)
        n = int(hist[: self.black + 1].sum() + hist[self.white :].sum())
        return n / float(hist.sum())


def clip_fractions(hist: np.ndarray, table: np.ndarray, valid: np.ndarray, white: int, black: int) -> tuple[float, float]:
    """(saturated fraction of the emulated image, valid fraction) from the source histogram."""
    n = float(hist.sum())
    tab = table[: hist.size]
    clipped = (tab >= white) | (tab <= black)
    return float(hist[clipped].sum()) / n, float(hist[valid[: hist.size]].sum()) / n


class EmulatedTick:
    """One cycle of an :class:`EmulatedProvider` (see :meth:`shot`)."""

    def __init__(self, provider: "EmulatedProvider", cycle, shapes: dict) -> None:
        p = provider
        self.provider = p
        self.cycle = cycle
        self.index = cycle.index
        self.missing = {c: cycle.missing(c) for c in p.cameras}
        avail = cycle.available(p.cameras)
        self.skipped = None if avail else "no bracket present for every camera"
        if self.skipped is None and p.skip_partial and any(self.missing.values()):
            self.skipped = "partial cycle left out (--skip-partial): " + missing_text(self.missing)
        self.images = images = CycleImages(cycle, p.white, p.black, p.stats, p.noise, shapes, p.blur)
        lead = p.cameras[0]
        # the closures hold the images, not the tick: no reference cycle, so a cycle's decoded
        # and emulated images are freed as soon as the loop drops the tick (a cycle through
        # ``self`` kept them until the garbage collector ran: ~30 MB per cycle, fresh pages)
        self.brackets = {e: (lambda e=e: images.saturated(lead, e)) for e in avail}

    def select(self, target_ms: float) -> float:
        """The bracket of ``target_ms`` (the blur hook's choice when it selects, ``--blur-aware``)."""
        p = self.provider
        kw = {"white_level": p.white, "black_level": p.black}
        if p.blur is None:
            return select(p.selector, target_ms, self.brackets, **kw)
        return p.blur.select(p.selector, self.cycle, p.cameras[0], target_ms, self.brackets, kw)

    def shot(self, target_ms: float, want_right: bool = False) -> Shot:
        """The shot of ``target_ms``: the selected bracket emulated (first camera; second when asked)."""
        shot, rest = self.split_shot(target_ms, want_right)
        rest()
        return shot

    def split_shot(self, target_ms: float, want_right: bool = False):
        """(shot, rest): :meth:`shot` in two parts.  ``shot`` holds what the method reads (the first
        camera); ``rest()`` fills in the second camera (its fractions, its image when asked) and
        raises what :meth:`shot` would raise for it.  The closed loop calls ``rest()`` while the
        method's worker computes, so the second camera's decoding costs no time on the method's chain."""
        p = self.provider
        lead, other = p.cameras[0], (p.cameras[1] if len(p.cameras) > 1 else None)
        key = self.select(target_ms)
        frame = self.cycle.frames[lead][key]
        _, hist = self.images.get(lead, key)
        ratio = target_ms / key
        table, valid = p.response.lut(ratio)  # thread-safe, cached per ratio
        left = self.images.emulated(lead, key, ratio, table, p.stats)
        sat, val = clip_fractions(hist, table, valid, p.white, p.black)
        shot = Shot(timestamp_ns=int(frame.timestamp_ns), exposure_ms=float(target_ms), bracket_ms=float(key),
                    ratio=float(ratio), left=left, saturated_fraction=sat, valid_fraction=val,
                    bracket_saturated_fraction=self.images.saturated(lead, key),
                    missing_left_ms=tuple(self.missing.get(lead, ())),
                    missing_right_ms=tuple(self.missing.get(other, ())) if other else ())
        if other is None:
            return shot, _nothing

        def rest() -> None:
            rframe = self.cycle.frames[other][key]
            if rframe.timestamp_ns != frame.timestamp_ns:
                raise DatasetError(
                    f"{rframe.path}: stereo pair mismatch, {other} timestamp {rframe.timestamp_ns} != "
                    f"{lead} timestamp {frame.timestamp_ns} for bracket {key} ms"
                )
            _, rhist = self.images.get(other, key)
            shot.saturated_fraction_right, shot.valid_fraction_right = clip_fractions(rhist, table, valid, p.white,
                                                                                    p.black)
            if want_right:
                shot.right = self.images.emulated(other, key, ratio, table, p.stats)

        return shot, rest


def _nothing() -> None:
    return None


@provides_rate(RATES[0])
class EmulatedProvider:
    """A recording's cycles as ticks whose shots are emulated from the brackets.

    Parameters
    ----------
    sequence : emulator.core.dataset.Sequence
    config : RunConfig
        Its selector is used; its noise settings are resolved by the caller into ``noise``.
    response : CameraResponse
        At the recording's levels (:meth:`RunConfig.response_for`).
    cameras : tuple of str or None
        Cameras to emulate, the first read by methods and deciding the bracket (default:
        the recording's, left first).
    noise : None or (NoiseModel, seed)
        Noise-consistent emulation, each image seeded by (seed, cycle, camera, bracket, ratio).
    blur : None or hook
        Blur-consistent emulation: ``blur.apply(cycle, camera, bracket_ms, ratio, raw, emulated) -> image``,
        once per emulated image, before the noise.
    cycles : iterable of int or None
        The cycle indices to visit (default all).
    """

    latency_ticks = 0
    #: What a tick is (progress, reports), and the columns it adds to ``exposures.csv`` (none).
    unit = "cycles"
    columns = ()
    #: A method may run this many cycles ahead of the slowest (:func:`~emulator.playback.loop.closed_loop`
    #: with ``jobs > 1``): a cycle's images are decoded on demand and memoised per tick, so ticks are
    #: independent.  Each tick in flight keeps its decoded images (up to ~55 MB at 1920x1200).
    ticks_ahead = 2

    def __init__(self, sequence, config: RunConfig, response, *, cameras=None, noise=None, stats: RunStats | None = None,
                 cycles=None, blur=None) -> None:
        self.sequence = sequence
        self.selector = config.selector
        self.response = response
        self.white, self.black = int(sequence.white_level), int(sequence.black_level)
        if cameras is None:
            cams = tuple(c for c in CAMERAS if c in sequence.cameras)
            if METHOD_CAMERA in cams:
                cams = (METHOD_CAMERA,) + tuple(c for c in cams if c != METHOD_CAMERA)
            cameras = cams
        self.cameras = tuple(cameras)
        self.noise = noise
        self.blur = blur
        self.skip_partial = bool(getattr(config, "skip_partial", False))
        self.stats = stats if stats is not None else RunStats()
        self._cycles = None if cycles is None else list(cycles)

    @classmethod
    def for_run(cls, sequence, config: RunConfig, response, *, noise=None, stats=None, blur=None):
        """The provider of a cycle-rate run (:meth:`RunConfig.provider_for`)."""
        return cls(sequence, config, response, noise=noise, stats=stats, blur=blur)

    @property
    def tick_indices(self) -> list[int]:
        """The index of every tick (the cycles visited)."""
        return [c.index for c in self.sequence.cycles] if self._cycles is None else list(self._cycles)

    def run_json(self) -> dict:
        """What ``run.json`` records of this provider (nothing at cycle rate)."""
        return {}

    def finish_run_json(self, run_json: dict) -> None:
        """Add what the run found out to ``run.json`` (nothing at cycle rate)."""

    def ticks(self):
        shapes: dict = {}
        cycles = self.sequence.cycles if self._cycles is None else [self.sequence[i] for i in self._cycles]
        for cycle in cycles:
            yield EmulatedTick(self, cycle, shapes)
