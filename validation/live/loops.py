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

from validation.live.config import FIXED_INSTANT_BRACKET_INDEX, VARIANTS, LiveError

__all__ = ["DatasetRadiance", "SharedRadiance", "lockstep", "make_shoot", "iter_live", "iter_emulated",
           "write_run_folder", "drop_run_images", "has_run_images"]

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


class SharedRadiance:
    """An ``exposure_aware`` radiance (:func:`scenes.walkshots.walk_radiance`) whose recent results are
    shared by the loops that ask for them: the radiance of a shot (instant, camera, exposure) is
    integrated once and served again to every loop that captures the same shot while it is among the
    ``keep`` most recent ones (the re-seeded live runs differ from their run only in the capture noise,
    so they ask for the same shots when advanced in :func:`lockstep` with it).  A pure cache: the
    returned arrays are the ones the radiance computed (never to be written to); ``hits`` and ``misses``
    count the calls."""

    exposure_aware = True

    def __init__(self, radiance: Callable[[int, str, float], np.ndarray], keep: int = 64) -> None:
        import collections

        if not getattr(radiance, "exposure_aware", False):
            raise LiveError("SharedRadiance needs an exposure-aware radiance (radiance(t, camera, exposure_ms))")
        self._radiance, self._keep = radiance, int(keep)
        self._memo: collections.OrderedDict = collections.OrderedDict()
        self.hits = self.misses = 0

    def __call__(self, timestamp_ns: int, camera: str, exposure_ms: float) -> np.ndarray:
        key = (int(timestamp_ns), camera, float(exposure_ms))
        hit = self._memo.get(key)
        if hit is not None:
            self.hits += 1
            self._memo.move_to_end(key)
            return hit
        self.misses += 1
        hit = self._memo[key] = self._radiance(timestamp_ns, camera, exposure_ms)
        while len(self._memo) > self._keep:
            self._memo.popitem(last=False)
        return hit


def lockstep(loops, on_step: Callable[[], None] | None = None) -> list[list]:
    """Every item of each iterator of ``loops``, the iterators advanced together (one item of each in
    turn, an exhausted one left out): ``[items of loops[0], items of loops[1], ...]``.  Independent closed
    loops give what each gives alone; advanced together, they ask for the same instants at about the same
    time (:class:`SharedRadiance`).  ``on_step`` is called after each item.  When one of them raises (or
    the walk is interrupted), the others are closed at once, which ends their method workers."""
    out: list[list] = [[] for _ in loops]
    iterators = [iter(it) for it in loops]
    active = list(enumerate(iterators))
    try:
        while active:
            still = []
            for i, it in active:
                try:
                    out[i].append(next(it))
                except StopIteration:
                    continue
                still.append((i, it))
                if on_step is not None:
                    on_step()
            active = still
    finally:
        for it in iterators:  # a closed loop suspended mid-walk stops its workers (its own finally)
            close = getattr(it, "close", None)
            if close is not None:
                close()
    return out


def _words(x: float) -> list[int]:
    return np.array([float(x)], dtype=np.float64).view(np.uint32).tolist()


def live_setup(sequence, camera, config, response, **kwargs):
    """The recording, its :class:`RunConfig` and the response of a live loop (cycle-rate or
    native-rate); the synthetic camera's levels must be the recording's."""
    from emulator.playback import RunConfig, resolve_sequence

    seq = resolve_sequence(sequence)
    cfg = RunConfig.from_kwargs(config, **kwargs)
    response = cfg.response_for(seq, response)
    white, black = int(seq.white_level), int(seq.black_level)
    if (camera.white_level, camera.black_level) != (white, black):
        raise LiveError(f"camera levels {camera.black_level}..{camera.white_level} differ from the recording's "
                        f"{black}..{white}")
    return seq, cfg, response


def make_shoot(radiance: Callable[[int, str], np.ndarray], camera, cameras, *, seed: int = 0, noise: bool = True):
    """The ``shoot(timestamp_ns, camera, exposure_ms, index)`` of the live providers for a synthetic camera.

    Captures ``radiance(timestamp_ns, camera)`` with :func:`synth.capture` (an ``exposure_aware``
    radiance is called with the exposure too, and integrates over the shot's window); the noise of
    camera ``c`` (its position in ``cameras``) at tick ``index`` and exposure ``t`` is seeded
    by ``SeedSequence([seed, 14001, index, c, bits of t])``.
    """
    import synth

    cams = tuple(cameras)

    def shoot(timestamp_ns: int, cam: str, exposure_ms: float, index: int) -> np.ndarray:
        rng = np.random.SeedSequence([int(seed), _LIVE_TAG, int(index), cams.index(cam), *_words(exposure_ms)])
        # an exposure-aware provider integrates over the live shot's own window
        rad = (radiance(timestamp_ns, cam, exposure_ms) if getattr(radiance, "exposure_aware", False)
               else radiance(timestamp_ns, cam))
        return synth.capture(rad, exposure_ms, camera, seed=rng, noise=noise)

    return shoot


def iter_live(
    sequence,
    radiance: Callable[[int, str], np.ndarray],
    camera,
    methods,
    *,
    timing: str = "same-instant",
    response=None,
    initial_ms: float | None = None,
    range_ms=None,
    selector: str | None = None,
    mode: str | None = None,
    noise: bool = True,
    seed: int = 0,
    config=None,
) -> Iterator:
    """The live closed loop at the cycle rate: each cycle, each method's camera captures at its own exposure.

    The one closed loop (:func:`emulator.playback.closed_loop`) over a
    :class:`emulator.playback.LiveCycleProvider`: the same initial-exposure clamp, guard,
    clamp, time limit and method failures as the emulated loop.  For a camera at its own
    frame rate, use :class:`emulator.playback.LiveRateProvider` with :func:`make_shoot`.

    Parameters
    ----------
    sequence : emulator.core.dataset.Sequence or path
        The bracketed recording of the walk: it gives the cycles, their shot timestamps,
        and (same-instant timing) the brackets the selector looks at.
    radiance : callable(timestamp_ns, camera) -> ndarray
        The radiance each camera saw at a shot's instant (e.g. :class:`DatasetRadiance`); one
        with ``exposure_aware = True`` is called ``radiance(timestamp_ns, camera, exposure_ms)``
        and integrates over the live shot's own exposure window (:func:`scenes.walkshots.walk_radiance`).
    camera : synth.Camera
        The recording's camera (``synth.sequence.load_camera``).
    methods : names or AE method instances
        As :func:`emulator.playback.iter_run` takes them and runs them: each in its own worker process (forked
        from the one fork server, NumPy's kernels of :mod:`emulator.numpy_dispatch`) unless ``config.workers``
        is ``"inline"``; names are built fresh.
    timing : {"same-instant", "fixed-instant"}
        Capture at the timestamp of the bracket the emulator would select for the live
        target, or at the cycle's first shot.
    response, initial_ms, range_ms, selector, mode
        As in :func:`emulator.playback.iter_run` (the response goes to methods that take it);
        ``config`` (a :class:`emulator.playback.RunConfig`) gives them all at once.
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
    from emulator.core.dataset import CAMERAS
    from emulator.playback import LiveCycleProvider, closed_loop
    from emulator.playback.workers import start_methods

    if timing not in VARIANTS:
        raise LiveError(f"timing must be one of {', '.join(VARIANTS)}, got {timing!r}")
    seq, cfg, response = live_setup(sequence, camera, config, response, initial_ms=initial_ms, range_ms=range_ms,
                                    selector=selector, mode=mode)
    built = start_methods(methods, cfg, response)  # as the emulated loop runs them (cfg.workers: worker processes)
    cams = tuple(c for c in CAMERAS if c in seq.cameras)
    shoot = make_shoot(radiance, camera, cams, seed=seed, noise=noise)
    provider = LiveCycleProvider(seq, shoot, cfg, instant="selected" if timing == "same-instant" else "fixed",
                                 fixed_bracket_index=FIXED_INSTANT_BRACKET_INDEX, cameras=cams)
    return closed_loop(provider, built, cfg, want_right=True, keep_images=True)


def iter_emulated(sequence, methods, *, noise: str = "none", noise_model=None, seed: int = 0, response=None,
                  initial_ms: float | None = None, range_ms=None, selector: str | None = None, mode: str | None = None,
                  config=None):
    """The normal closed loop (:func:`emulator.playback.iter_run`), both images emulated and kept."""
    from emulator.playback import iter_run

    return iter_run(sequence, methods, config, initial_ms=initial_ms, range_ms=range_ms, selector=selector,
                    response=response, mode=mode, emulate_right=True, keep_images=True, noise=noise,
                    noise_model=noise_model, noise_seed=seed)


def _relative_to(path, folder) -> str:
    """``path`` relative to ``folder`` (a study folder moves as a whole), or absolute where no relative path exists."""
    import os

    try:
        return os.path.relpath(Path(path).resolve(), Path(folder).resolve())
    except ValueError:  # another drive
        return str(Path(path).resolve())


def write_run_folder(folder, sequence_path, cycles, names, *, white_level: int, black_level: int,
                     description: dict | None = None, png_level: int = 1) -> Path:
    """Write cycles (with images) as a run folder that ``exposim bench features|vo`` read.

    The layout of :func:`emulator.orchestration.runner.run_to_folder` with ``save="png16"``, written by
    the same :class:`emulator.io.runfolder.RunWriter`: ``run.json``,
    ``<method>/exposures.csv``, ``<method>/images/{left,right}/<ts>.png``,
    ``<method>/images/times.txt``; the recording is named relative to ``folder``.  Refuses an existing non-empty folder
    (:class:`~emulator.errors.OutputExistsError`).  ``png_level``: zlib level of the images (0: about 14x faster to
    write and 6x faster to read, about 1.5x the size; the same pixels at any level).
    """
    from emulator.io.runcsv import NATIVE_COLUMNS
    from emulator.io.runfolder import RunWriter, format_row

    folder = Path(folder)
    cycles = list(cycles)
    steps = [st for cs in cycles for st in cs.steps.values()]
    cameras = ["left"] + (["right"] if any(st.right is not None for st in steps) else [])
    # steps of native emulation carry their native columns (format_row writes them): so must the header
    native = [getattr(st, "native", None) is not None for st in steps]
    if any(native) and not all(native):
        raise LiveError(f"{folder}: a run folder's steps are either all native-rate or none")
    run_json = {"sequence": _relative_to(sequence_path, folder), "methods": list(names), "save": "png16",
                "white_level": int(white_level), "black_level": int(black_level), "cameras": cameras,
                "n_cycles": len(cycles), **(description or {})}
    with RunWriter(folder, png_level=png_level) as writer:
        writer.start(run_json, list(names), cameras, "png16", columns=NATIVE_COLUMNS if any(native) else ())
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


def drop_run_images(folder) -> int:
    """Delete the images of a run folder (``<method>/images/<camera>/``), keeping ``run.json``, each method's
    ``exposures.csv`` and ``images/times.txt``; returns the number of images deleted."""
    import shutil

    n = 0
    for cam_dir in sorted(Path(folder).glob("*/images/*")):
        if cam_dir.is_dir():
            n += sum(1 for _ in cam_dir.iterdir())
            shutil.rmtree(cam_dir)
    return n


def has_run_images(folder) -> bool:
    """Whether a run folder still holds its images (:func:`drop_run_images` deletes them)."""
    return any(p.is_dir() for p in Path(folder).glob("*/images/*"))
