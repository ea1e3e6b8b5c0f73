"""The two closed loops of the experiment, and the run folders they leave for the benchmarks.

* :func:`iter_live`: each cycle, each method's camera captures at the method's own exposure
  from the radiance at that instant (:func:`synth.capture`) and the method reads that capture;
* :func:`iter_emulated`: the normal closed loop of :func:`emulator.playback.iter_run` on the
  bracketed recording, images kept;
* :func:`write_run_folder`: either loop's cycles as a run folder (through
  :class:`emulator.io.runfolder.RunWriter`, the one writer of that layout) that
  ``exposim bench features|vo`` read.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from emulator.autoexposure.isolation import call_method
from validation.live.config import FIXED_INSTANT_BRACKET_INDEX, VARIANTS, LiveError

__all__ = ["DatasetRadiance", "iter_live", "iter_emulated", "write_run_folder"]

#: Seed-sequence tag of the live captures.
_LIVE_TAG = 14_001


class DatasetRadiance:
    """The radiance each camera saw at each shot of a synthetic recording (its ground truth).

    ``radiance(timestamp_ns, camera)`` reads ``ground_truth/radiance/camera_<camera>/<ts>.exr``
    (written by ``synth.capture_sequence(save_radiance=True)``), keeping the last few.
    """

    def __init__(self, dataset, keep: int = 24) -> None:
        from emulator.io.borealhdr import CAMERA_FOLDERS

        self.root = Path(dataset) / "ground_truth" / "radiance"
        if not self.root.is_dir():
            raise LiveError(f"{self.root}: no radiance ground truth; synthesise the recording with save_radiance=True")
        self._folders = CAMERA_FOLDERS
        self._keep = int(keep)
        self._memo: dict = {}

    def __call__(self, timestamp_ns: int, camera: str) -> np.ndarray:
        from emulator.io.exr import read_exr

        key = (int(timestamp_ns), camera)
        hit = self._memo.get(key)
        if hit is None:
            path = self.root / self._folders[camera] / f"{int(timestamp_ns)}.exr"
            if not path.is_file():
                raise LiveError(f"{path}: no radiance for the {camera} camera at {timestamp_ns} ns")
            hit = read_exr(path)
            self._memo[key] = hit
            while len(self._memo) > self._keep:
                self._memo.pop(next(iter(self._memo)))
        return hit


def _words(x: float) -> list[int]:
    return np.array([float(x)], dtype=np.float64).view(np.uint32).tolist()


def iter_live(
    sequence,
    radiance: Callable[[int, str], np.ndarray],
    camera,
    methods,
    *,
    timing: str = "same-instant",
    response=None,
    initial_ms: float = 4.0,
    range_ms=None,
    selector: str = "higher-no-sat",
    mode: str = "paper",
    noise: bool = True,
    seed: int = 0,
) -> Iterator:
    """The live closed loop: each cycle, each method's camera captures at its own exposure.

    Parameters
    ----------
    sequence : emulator.dataset.Sequence or path
        The bracketed recording of the walk: it gives the cycles, their shot timestamps,
        and (same-instant timing) the brackets the selector looks at.
    radiance : callable(timestamp_ns, camera) -> ndarray
        The radiance each camera saw at a shot's instant (e.g. :class:`DatasetRadiance`); one
        with ``exposure_aware = True`` is called ``radiance(timestamp_ns, camera, exposure_ms)``
        and integrates over the live shot's own exposure window (:func:`scenes.walkshots.walk_radiance`).
    camera : synth.Camera
        The recording's camera (``synth.sequence.load_camera``).
    methods : names or AE method instances
        As :func:`emulator.playback.iter_run` takes them (names are built fresh).
    timing : {"same-instant", "fixed-instant"}
        Capture at the timestamp of the bracket the emulator would select for the live
        target, or at the cycle's first shot.
    response, initial_ms, range_ms, selector, mode
        As in :func:`emulator.playback.iter_run` (the response goes to methods that take it).
    noise : bool
        Sensor noise in the live captures.
    seed : int
        Capture noise of camera c at cycle i and exposure t: ``SeedSequence([seed, 14001,
        i, c, bits of t])``; two methods capturing the same exposure at the same instant
        therefore see the same image (as two methods with the same target share one
        emulated image).

    Yields
    ------
    emulator.playback.CycleStep
        With :class:`emulator.playback.MethodStep` per method, images kept
        (``left``/``right``); ``bracket_ms`` is the bracket whose instant was used,
        ``ratio`` 1, ``valid_fraction`` 1.
    """
    import synth
    from emulator.dataset import CAMERAS
    from emulator.io.borealhdr import load_sequence, sequence_response
    from emulator.autoexposure.methodset import build_methods
    from emulator.playback import DEFAULT_RANGE_MS, CycleStep, MethodStep, guard_exposure
    from emulator.pools import single_thread_pools
    from emulator.select import saturated_fraction, select

    if timing not in VARIANTS:
        raise LiveError(f"timing must be one of {', '.join(VARIANTS)}, got {timing!r}")
    seq = sequence if hasattr(sequence, "cycles") else load_sequence(sequence)
    if response is None:
        response = sequence_response(seq)
    lo, hi = (float(v) for v in (DEFAULT_RANGE_MS if range_ms is None else range_ms))
    if not 0 < lo <= hi:
        raise LiveError(f"range_ms must satisfy 0 < low <= high, got {range_ms!r}")
    white, black = int(seq.white_level), int(seq.black_level)
    if (camera.white_level, camera.black_level) != (white, black):
        raise LiveError(f"camera levels {camera.black_level}..{camera.white_level} differ from the recording's "
                        f"{black}..{white}")
    built = build_methods(methods, mode=mode, response=response)
    cams = tuple(c for c in CAMERAS if c in seq.cameras)
    targets = {name: float(initial_ms) for name in built}
    for cycle in seq.cycles:
        avail = cycle.available(cams)
        if not avail:
            yield CycleStep(cycle.index, {}, {c: cycle.missing(c) for c in cams}, skipped="no bracket present")
            continue
        raws: dict = {}

        def bracket_raw(e, cycle=cycle, raws=raws):
            if e not in raws:
                raws[e] = cycle.frames[cams[0]][e].load()
            return raws[e]

        first = cycle.frames[cams[0]][avail[FIXED_INSTANT_BRACKET_INDEX]].timestamp_ns
        captures: dict = {}
        steps = {}
        for name, method in built.items():
            target = targets[name]
            if timing == "same-instant":
                sats = {e: (lambda e=e: saturated_fraction(bracket_raw(e), white_level=white, black_level=black))
                        for e in avail}
                key = select(selector, target, sats, white_level=white, black_level=black)
                ts = int(cycle.frames[cams[0]][key].timestamp_ns)
            else:
                key = avail[FIXED_INSTANT_BRACKET_INDEX]
                ts = int(first)
            images = []
            for c, cam in enumerate(cams):
                ck = (ts, cam, target)
                if ck not in captures:
                    rng = np.random.SeedSequence([int(seed), _LIVE_TAG, int(cycle.index), c, *_words(target)])
                    # an exposure-aware provider integrates over the live shot's own window [t, t + target]
                    rad = radiance(ts, cam, target) if getattr(radiance, "exposure_aware", False) else radiance(ts, cam)
                    img = synth.capture(rad, target, camera, seed=rng, noise=noise)
                    img.setflags(write=False)
                    captures[ck] = img
                images.append(captures[ck])
            left = images[0]
            right = images[1] if len(images) > 1 else None
            before = getattr(method, "guard_count", 0)
            with single_thread_pools(user_api="blas"):  # as emulator.playback.iter_run
                proposed = call_method(method, left, target)  # emulator.autoexposure.isolation
            proposed, clamped, bad = guard_exposure(proposed, target, (lo, hi))  # as emulator.playback.iter_run
            guarded = bad or getattr(method, "guard_count", 0) > before
            nxt = target if bad else proposed
            sat = saturated_fraction(left, white_level=white, black_level=black)
            sat_r = None if right is None else saturated_fraction(right, white_level=white, black_level=black)
            steps[name] = MethodStep(
                method=name, cycle=cycle.index, timestamp_ns=ts, target_ms=target, bracket_ms=float(key), ratio=1.0,
                saturated_fraction=sat, valid_fraction=1.0, next_ms=clamped, proposed_ms=proposed,
                guarded=bool(guarded), clamped=clamped != nxt, bracket_saturated_fraction=sat,
                saturated_fraction_right=sat_r, valid_fraction_right=None if right is None else 1.0,
                left=left, right=right)
        for name, st in steps.items():
            targets[name] = st.next_ms
        yield CycleStep(cycle.index, steps, {c: cycle.missing(c) for c in cams})


def iter_emulated(sequence, methods, *, noise: str = "none", noise_model=None, seed: int = 0, response=None,
                  initial_ms: float = 4.0, range_ms=None, selector: str = "higher-no-sat", mode: str = "paper"):
    """The normal closed loop (:func:`emulator.playback.iter_run`), both images emulated and kept."""
    from emulator.playback import DEFAULT_RANGE_MS, iter_run

    return iter_run(sequence, methods, initial_ms=initial_ms, range_ms=DEFAULT_RANGE_MS if range_ms is None else
                    range_ms, selector=selector, response=response, mode=mode, emulate_right=True, keep_images=True,
                    noise=noise, noise_model=noise_model, noise_seed=seed)


def write_run_folder(folder, sequence_path, cycles, names, *, white_level: int, black_level: int,
                     description: dict | None = None) -> Path:
    """Write cycles (with images) as a run folder that ``exposim bench features|vo`` read.

    The layout of :func:`emulator.runner.run_to_folder` with ``save="png16"``, written by
    the same :class:`emulator.io.runfolder.RunWriter`: ``run.json``,
    ``<method>/exposures.csv``, ``<method>/images/{left,right}/<ts>.png``,
    ``<method>/images/times.txt``.  Refuses an existing non-empty folder
    (:class:`~emulator.errors.OutputExistsError`).
    """
    from emulator.io.runfolder import RunWriter, format_row

    folder = Path(folder)
    cycles = list(cycles)
    cameras = ["left"] + (["right"] if any(st.right is not None for cs in cycles for st in cs.steps.values()) else [])
    run_json = {"sequence": str(Path(sequence_path).resolve()), "methods": list(names), "save": "png16",
                "white_level": int(white_level), "black_level": int(black_level), "cameras": cameras,
                "n_cycles": len(cycles), **(description or {})}
    with RunWriter(folder) as writer:
        writer.start(run_json, list(names), cameras, "png16")
        for name in names:
            for cs in cycles:
                st = cs.steps.get(name)
                if st is None:
                    continue
                writer.append_row(name, format_row(st))
                for cam, img in (("left", st.left), ("right", st.right)):
                    if img is not None:
                        writer.write_image(name, cam, st.timestamp_ns, img)
        writer.update(status="complete", cycles_done=len(cycles))
        writer.write_times(names)
    return folder
