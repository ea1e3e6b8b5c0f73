"""Closed-loop playback of AE methods on a bracketed recording (paper sections III-B, V-D).

For each cycle (one sweep of the brackets) and each method: the method's current target
exposure selects a bracket (once per cycle, among the brackets present for both cameras;
the **left** camera's saturation decides), the emulator renders the left and right images
at the target from that bracket, the method reads the emulated left image and proposes the
next exposure, which is clamped to the configured range.  Every method starts from the
same initial exposure.  The timestamp of an emulated image is the timestamp of the bracket
it came from, so a stereo pair always comes from one capture instant.

Many methods on one sequence share the decoded brackets: a cycle's images are decoded at
most once (lazily: only the brackets some method selects or whose saturation the selector
asks for), their histogram is computed once, and from it each method's saturated and valid
fractions follow without touching the pixels again; each ratio's lookup table is built once
(cached on the :class:`~emulator.response.CameraResponse`), and methods with the same target
in a cycle share one emulated image.  The images handed to methods are read-only.  ``jobs > 1`` runs the methods of
a cycle on threads (NumPy and OpenCV release the GIL); results do not depend on ``jobs``, nor on
the machine's cores (each cycle's methods run under one BLAS thread, :mod:`emulator.pools`).

Library API: :func:`iter_run` (a generator of :class:`CycleStep`) and :func:`run` (tables in
memory).  Nothing here prints.  Methods are chosen by name in
:mod:`emulator.autoexposure.methodset`; a run written to a run folder (with ``resume``) and
its report are :mod:`emulator.runner`; the folder's layout, writer and reader are
:mod:`emulator.io.runfolder`.  The clamp default
is :data:`emulator.autoexposure.DEFAULT_RANGE_MS`, shared with the paper-mode methods.

``saturated_fraction`` and ``valid_fraction`` describe the emulated left image the method
saw: pixels at or below black or at or above white, and pixels whose source carried the
information the target needs (see :func:`emulator.emulate.emulate`).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import cv2
import numpy as np

from emulator.autoexposure import DEFAULT_RANGE_MS, AutoExposureMethod
from emulator.autoexposure.isolation import call_method
from emulator.autoexposure.methodset import build_methods
from emulator.autoexposure.registry import MethodFailed
from emulator.dataset import CAMERAS, Sequence
from emulator.emulate import apply_lut, check_exposure
from emulator.errors import DatasetError, PlaybackError
from emulator.io.borealhdr import load_sequence, sequence_response
from emulator.pools import single_thread_pools
from emulator.select import SELECTORS, select

__all__ = [
    "run",
    "iter_run",
    "MethodStep",
    "CycleStep",
    "RunResult",
    "RunStats",
    "PlaybackError",
    "DEFAULT_INITIAL_MS",
    "DEFAULT_SELECTOR",
    "guard_exposure",
]

#: First exposure of every method, ms.
DEFAULT_INITIAL_MS = 4.0
DEFAULT_SELECTOR = "higher-no-sat"
#: Camera whose emulated image the methods read and whose saturation selects the bracket.
METHOD_CAMERA = "left"


# ============================================================================ records
@dataclass
class MethodStep:
    """What one method did in one cycle (its CSV row: :func:`emulator.io.runfolder.format_row`)."""

    method: str
    cycle: int
    timestamp_ns: int
    target_ms: float
    bracket_ms: float
    ratio: float
    saturated_fraction: float
    valid_fraction: float
    next_ms: float
    proposed_ms: float
    guarded: bool
    clamped: bool
    bracket_saturated_fraction: float
    saturated_fraction_right: float | None = None
    valid_fraction_right: float | None = None
    missing_left_ms: tuple[float, ...] = ()
    missing_right_ms: tuple[float, ...] = ()
    left: np.ndarray | None = field(default=None, repr=False)
    right: np.ndarray | None = field(default=None, repr=False)


@dataclass
class CycleStep:
    """One cycle of a run: each method's step, or why the cycle was skipped."""

    cycle: int
    steps: dict[str, MethodStep]
    missing: dict[str, list[float]]
    skipped: str | None = None
    #: Methods that failed in this cycle (no step; dropped from later cycles): name -> reason.
    failed: dict[str, str] = field(default_factory=dict)


@dataclass
class RunStats:
    """Counters and timers of a run (wall-clock seconds; thread-safe)."""

    decodes: int = 0
    decode_s: float = 0.0
    histogram_s: float = 0.0
    emulate_s: float = 0.0
    emulations: int = 0
    method_s: dict[str, float] = field(default_factory=dict)
    method_calls: dict[str, int] = field(default_factory=dict)
    cycles: int = 0
    wall_s: float = 0.0
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def add(self, name: str, seconds: float, count: int = 1) -> None:
        with self._lock:
            setattr(self, name, getattr(self, name) + seconds)
            if name == "decode_s":
                self.decodes += count
            elif name == "emulate_s":
                self.emulations += count

    def add_method(self, method: str, seconds: float) -> None:
        with self._lock:
            self.method_s[method] = self.method_s.get(method, 0.0) + seconds
            self.method_calls[method] = self.method_calls.get(method, 0) + 1

    def as_dict(self) -> dict:
        def per(total, n):
            return 1000.0 * total / n if n else None

        return {
            "cycles": self.cycles,
            "wall_s": self.wall_s,
            "cycles_per_s": self.cycles / self.wall_s if self.wall_s > 0 else None,
            "decodes": self.decodes,
            "decode_ms_per_image": per(self.decode_s, self.decodes),
            "emulations": self.emulations,
            "emulate_ms_per_image": per(self.emulate_s, self.emulations),
            "method_ms_per_frame": {m: per(s, self.method_calls.get(m, 0)) for m, s in self.method_s.items()},
        }


@dataclass
class RunResult:
    """In-memory result of :func:`run`: per-method steps (images dropped) and skipped cycles."""

    steps: dict[str, list[MethodStep]]
    skipped: list[tuple[int, str]]
    methods: dict[str, AutoExposureMethod]
    stats: RunStats
    #: Methods that failed: name -> "failed: <reason> at cycle N" (their steps stop before N).
    failed: dict[str, str] = field(default_factory=dict)

    def column(self, method: str, name: str) -> np.ndarray:
        """One field of every step of ``method`` as an array (e.g. ``"target_ms"``)."""
        return np.array([getattr(s, name) for s in self.steps[method]])


# ============================================================================ the loop
class _CycleImages:
    """Decoded brackets of one cycle, each decoded at most once (thread-safe), with histograms."""

    def __init__(self, cycle, white_level: int, black_level: int, stats: RunStats, noise=None,
                 shapes: dict | None = None, blur=None) -> None:
        self.cycle = cycle
        self.shapes = shapes  # the run's image size, shared by every cycle: a frame of another size is refused
        self.white = white_level
        self.black = black_level
        self.stats = stats
        self.noise = noise  # None, or (NoiseModel, seed) for noise-consistent emulation
        self.blur = blur  # None, or an emulator.motion.BlurHook for blur-consistent emulation
        self._lock = threading.Lock()
        self._locks: dict = {}
        self._data: dict = {}

    def get(self, camera: str, exposure_ms: float) -> tuple[np.ndarray, np.ndarray]:
        key = (camera, exposure_ms)
        with self._lock:
            lock = self._locks.setdefault(key, threading.Lock())
        with lock:
            hit = self._data.get(key)
            if hit is not None:
                return hit
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
            raw.setflags(write=False)
            hist.setflags(write=False)
            self._data[key] = (raw, hist)
            return raw, hist

    def emulated(self, camera: str, exposure_ms: float, ratio: float, table: np.ndarray, stats: RunStats) -> np.ndarray:
        """The bracket emulated at ``ratio`` (read-only; shared by methods with the same target)."""
        key = (camera, exposure_ms, ratio)
        with self._lock:
            lock = self._locks.setdefault(key, threading.Lock())
        with lock:
            hit = self._data.get(key)
            if hit is not None:
                return hit
            raw, _ = self.get(camera, exposure_ms)
            if ratio == 1.0:
                out = raw
            else:
                t0 = time.perf_counter()
                out = apply_lut(table, raw)
                if self.blur is not None:
                    out = self.blur.apply(self.cycle, camera, exposure_ms, ratio, raw, out)
                if self.noise is not None:
                    out = self._add_noise(camera, exposure_ms, ratio, raw, out)
                stats.add("emulate_s", time.perf_counter() - t0)
                out.setflags(write=False)
            self._data[key] = out
            return out

    def _add_noise(self, camera: str, exposure_ms: float, ratio: float, raw: np.ndarray, plain: np.ndarray):
        """Noise-consistent emulation (``emulator.emulate``, ``noise="consistent"``), seeded by
        (seed, cycle, camera, bracket, ratio): independent of threads and of which method asks."""
        from emulator.noise import consistent_noise

        model, seed = self.noise
        words = np.array([exposure_ms, ratio], dtype=np.float64).view(np.uint32).tolist()
        rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(self.cycle.index),
                                                            CAMERAS.index(camera), *words]))
        return consistent_noise(raw, plain, ratio, model, rng)

    def saturated(self, camera: str, exposure_ms: float) -> float:
        _, hist = self.get(camera, exposure_ms)
        n = int(hist[: self.black + 1].sum() + hist[self.white :].sum())
        return n / float(hist.sum())


def _fractions(hist: np.ndarray, table: np.ndarray, valid: np.ndarray, white: int, black: int) -> tuple[float, float]:
    """(saturated fraction of the emulated image, valid fraction) from the source histogram."""
    n = float(hist.sum())
    tab = table[: hist.size]
    clipped = (tab >= white) | (tab <= black)
    return float(hist[clipped].sum()) / n, float(hist[valid[: hist.size]].sum()) / n


def guard_exposure(proposed, fallback_ms: float, range_ms) -> tuple[float, float, bool]:
    """What the loop makes of a method's answer: ``(proposed, next_ms, guarded)``.

    ``proposed`` as a float (NaN if it is not a number); a non-finite or non-positive answer
    is replaced by ``fallback_ms`` (the exposure just used) and ``guarded`` is True; the
    result is clamped to ``range_ms`` (compare ``next_ms`` with ``proposed`` to see a clamp).
    """
    try:
        proposed = float(proposed)
    except (TypeError, ValueError):
        proposed = math.nan
    bad = not (math.isfinite(proposed) and proposed > 0)
    return proposed, _clamp(fallback_ms if bad else proposed, range_ms), bad


def _clamp(value: float, range_ms) -> float:
    lo, hi = range_ms
    return min(max(value, lo), hi)


def _check_range(range_ms) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in range_ms)
    except (TypeError, ValueError):
        raise PlaybackError(f"range_ms must be (low_ms, high_ms), got {range_ms!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
        raise PlaybackError(f"range_ms must satisfy 0 < low <= high (ms), got {range_ms!r}")
    return lo, hi


def _check_timeout(method_timeout) -> float | None:
    if method_timeout is None:
        return None
    try:
        value = float(method_timeout)
    except (TypeError, ValueError):
        raise PlaybackError(f"method_timeout must be a number of seconds or None, got {method_timeout!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise PlaybackError(f"method_timeout must be finite and positive (seconds), got {method_timeout!r}")
    return value


def _resolve_sequence(sequence) -> Sequence:
    return sequence if isinstance(sequence, Sequence) else load_sequence(sequence)


def iter_run(
    sequence,
    methods,
    *,
    initial_ms: float = DEFAULT_INITIAL_MS,
    range_ms=DEFAULT_RANGE_MS,
    selector: str = DEFAULT_SELECTOR,
    response=None,
    mode: str = "paper",
    options: Mapping | None = None,
    jobs: int = 1,
    emulate_right: bool = False,
    keep_images: bool = False,
    on_step: Callable[[MethodStep], None] | None = None,
    stats: RunStats | None = None,
    noise: str = "none",
    noise_model=None,
    noise_seed: int = 0,
    method_timeout: float | None = None,
    blur=None,
) -> Iterator[CycleStep]:
    """Run the closed loop cycle by cycle, yielding a :class:`CycleStep` per cycle.

    Parameters
    ----------
    sequence : Sequence or path
        The recording (BorealHDR layout).
    methods : "all", "m1,m2", names, or AE method instances
        Methods built by name get ``mode``, ``options[name]`` and the response (zhang).
    initial_ms, range_ms : float, (float, float)
        Shared first exposure, and the clamp applied to every proposal (ms).
    selector : str
        Bracket selector (``emulator.select.SELECTORS``), run once per method and cycle on
        the brackets present for both cameras; the left camera's saturation decides.
    response : CameraResponse or None
        Default: the sequence's own (:func:`emulator.dataset.sequence_response`).
    jobs : int
        Threads across methods within a cycle (output does not depend on it).
    emulate_right, keep_images : bool
        Also emulate the right image (its fractions are computed anyway); keep the emulated
        images on the yielded steps (else they are dropped after ``on_step``).
    on_step : callable(MethodStep) or None
        Called in the worker right after each method's step, with the images attached
        (used to write them in parallel).
    stats : RunStats or None
        Filled with counters and timings.
    noise, noise_model, noise_seed : str, NoiseModel, int
        ``noise="consistent"`` emulates with the noise a capture at the target would have
        (:func:`emulator.emulate.emulate`; needs ``noise_model``), each emulated image seeded
        by (``noise_seed``, cycle, camera, bracket, ratio).  The saturated and valid
        fractions still describe the plain emulation.  Default ``"none"``: exact eq. 2.
    method_timeout : float or None
        Per-call wall-time limit of ``next_exposure``, s (default none).  A call over it
        completes (no thread is killed) but fails its method, as does a plugin method that
        raises or returns a non-finite or non-positive exposure
        (:class:`~emulator.autoexposure.registry.MethodFailed`): the method gets no step from
        that cycle on, the cycle's :attr:`CycleStep.failed` names it with the reason, and the
        other methods go on unchanged.
    blur : emulator.motion.BlurHook or None
        Blur-consistent emulation (``--blur consistent``, :func:`emulator.motion.blur_hook`):
        each emulated image goes through it once; it records each image's blur mismatch.
    """
    seq = _resolve_sequence(sequence)
    initial_ms = check_exposure(initial_ms, "initial_ms")
    lo_hi = _check_range(range_ms)
    initial_ms = _clamp(initial_ms, lo_hi)  # the first exposure obeys the clamp as every proposal does
    if selector not in SELECTORS:
        raise PlaybackError(f"unknown selector {selector!r}; choose one of {', '.join(SELECTORS)}")
    if int(jobs) < 1:
        raise PlaybackError(f"jobs must be >= 1, got {jobs!r}")
    if response is None:
        response = sequence_response(seq)
    white, black = int(seq.white_level), int(seq.black_level)
    if response.white_level != white or response.black_level != black:
        response = response.with_levels(white_level=white, black_level=black)
    timeout_s = _check_timeout(method_timeout)
    built = build_methods(methods, mode=mode, response=response, options=options)
    stats = stats if stats is not None else RunStats()
    noise_spec = _noise_spec(noise, noise_model, noise_seed, response)
    cams = tuple(c for c in CAMERAS if c in seq.cameras)
    method_cam = METHOD_CAMERA if METHOD_CAMERA in cams else cams[0]
    other_cam = next((c for c in cams if c != method_cam), None)
    targets = {name: float(initial_ms) for name in built}
    shapes: dict = {}
    select_kw = {"white_level": white, "black_level": black}

    def step_one(name: str, method, images: _CycleImages, brackets: dict, missing: dict, cycle) -> MethodStep:
        target = targets[name]
        key = (select(selector, target, brackets, **select_kw) if images.blur is None
               else images.blur.select(selector, cycle, method_cam, target, brackets, select_kw))
        frame = cycle.frames[method_cam][key]
        raw, hist = images.get(method_cam, key)
        ratio = target / key
        table, valid = response.lut(ratio)  # thread-safe, cached per ratio
        left = images.emulated(method_cam, key, ratio, table, stats)
        sat, val = _fractions(hist, table, valid, white, black)
        bracket_sat = images.saturated(method_cam, key)
        before = getattr(method, "guard_count", 0)
        t0 = time.perf_counter()
        proposed = call_method(method, left, target)  # isolated; MethodFailed: caught by the cycle loop
        elapsed = time.perf_counter() - t0
        stats.add_method(name, elapsed)
        if timeout_s is not None and elapsed > timeout_s:
            raise MethodFailed(f"took {elapsed:.3g} s in next_exposure, over the limit of {timeout_s:g} s")
        proposed, clamped_value, bad = guard_exposure(proposed, target, lo_hi)
        guarded = bad or getattr(method, "guard_count", 0) > before
        nxt = target if bad else proposed
        right_img = None
        sat_r = val_r = None
        if other_cam is not None:
            rframe = cycle.frames[other_cam][key]
            if rframe.timestamp_ns != frame.timestamp_ns:
                raise DatasetError(
                    f"{rframe.path}: stereo pair mismatch, {other_cam} timestamp {rframe.timestamp_ns} != "
                    f"{method_cam} timestamp {frame.timestamp_ns} for bracket {key} ms"
                )
            _, rhist = images.get(other_cam, key)
            sat_r, val_r = _fractions(rhist, table, valid, white, black)
            if emulate_right:
                right_img = images.emulated(other_cam, key, ratio, table, stats)
        st = MethodStep(
            method=name,
            cycle=cycle.index,
            timestamp_ns=int(frame.timestamp_ns),
            target_ms=target,
            bracket_ms=float(key),
            ratio=float(ratio),
            saturated_fraction=sat,
            valid_fraction=val,
            next_ms=clamped_value,
            proposed_ms=proposed,
            guarded=bool(guarded),
            clamped=clamped_value != nxt,
            bracket_saturated_fraction=bracket_sat,
            saturated_fraction_right=sat_r,
            valid_fraction_right=val_r,
            missing_left_ms=tuple(missing.get(method_cam, ())),
            missing_right_ms=tuple(missing.get(other_cam, ())) if other_cam else (),
            left=left,
            right=right_img,
        )
        if on_step is not None:
            on_step(st)
        if not keep_images:
            st.left = st.right = None
        return st

    failed: dict[str, str] = {}

    def checked_step(a):
        try:
            return step_one(*a)
        except MethodFailed as exc:
            return exc

    pool = ThreadPoolExecutor(max_workers=int(jobs), thread_name_prefix="exposim-run") if int(jobs) > 1 else None
    start = time.perf_counter()
    try:
        for cycle in seq.cycles:
            missing = {c: cycle.missing(c) for c in cams}
            avail = cycle.available(cams)
            if not avail:
                stats.cycles += 1
                yield CycleStep(cycle.index, {}, missing, skipped="no bracket present for every camera")
                continue
            images = _CycleImages(cycle, white, black, stats, noise_spec, shapes, blur)
            brackets = {e: (lambda e=e: images.saturated(method_cam, e)) for e in avail}
            args = [(name, m, images, brackets, missing, cycle) for name, m in built.items() if name not in failed]
            with single_thread_pools(user_api="blas"):  # results independent of the machine's cores
                if pool is None:
                    results = [checked_step(a) for a in args]
                else:
                    results = list(pool.map(checked_step, args))
            now_failed = {}
            for a, st in zip(args, results):
                if isinstance(st, MethodFailed):
                    now_failed[a[0]] = f"failed: {st} at cycle {cycle.index}"
                else:
                    targets[st.method] = st.next_ms
            failed.update(now_failed)
            results = [st for st in results if not isinstance(st, MethodFailed)]
            stats.cycles += 1
            stats.wall_s = time.perf_counter() - start
            yield CycleStep(cycle.index, {st.method: st for st in results}, missing, failed=now_failed)
    finally:
        stats.wall_s = time.perf_counter() - start
        if pool is not None:
            pool.shutdown(wait=True)


def _noise_spec(noise: str, noise_model, noise_seed, response):
    """None for ``noise="none"``, else (model, seed), checked as :func:`emulator.emulate.emulate` does."""
    from emulator.emulate import NOISE_MODES, _check_noise_model

    if noise not in NOISE_MODES:
        raise PlaybackError(f"noise must be one of {', '.join(NOISE_MODES)}, got {noise!r}")
    if noise == "none":
        return None
    if isinstance(noise_seed, bool) or not isinstance(noise_seed, (int, np.integer)) or noise_seed < 0:
        raise PlaybackError(f"noise_seed must be a non-negative integer, got {noise_seed!r}")
    return _check_noise_model(noise_model, response, noise, False), int(noise_seed)


def run(
    sequence,
    methods="all",
    *,
    initial_ms: float = DEFAULT_INITIAL_MS,
    range_ms=DEFAULT_RANGE_MS,
    selector: str = DEFAULT_SELECTOR,
    response=None,
    mode: str = "paper",
    options: Mapping | None = None,
    jobs: int = 1,
    progress: Callable[[int, int], None] | None = None,
    method_timeout: float | None = None,
) -> RunResult:
    """Run the closed loop over a whole sequence in memory (no images kept); see :func:`iter_run`."""
    seq = _resolve_sequence(sequence)
    if response is None:
        response = sequence_response(seq)
    built = build_methods(methods, mode=mode, response=response, options=options)
    stats = RunStats()
    steps: dict[str, list[MethodStep]] = {name: [] for name in built}
    skipped: list[tuple[int, str]] = []
    failed: dict[str, str] = {}
    gen = iter_run(seq, list(built.values()), initial_ms=initial_ms, range_ms=range_ms, selector=selector,
                   response=response, jobs=jobs, stats=stats, method_timeout=method_timeout)
    for i, cs in enumerate(gen, 1):
        failed.update(cs.failed)
        if cs.skipped:
            skipped.append((cs.cycle, cs.skipped))
        for name, st in cs.steps.items():
            steps[name].append(st)
        if progress is not None:
            progress(i, len(seq.cycles))
    return RunResult(steps, skipped, built, stats, failed)
