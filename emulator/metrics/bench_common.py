"""What the feature and VO benchmarks share: the stated 8-bit conversion, the frames used,
the version, the progress bar and the contact sheet of the compared images.

Split out of :mod:`emulator.metrics.bench`; :mod:`emulator.metrics.vo_bench` and ``bench``
both import from here (no circle).
"""

from __future__ import annotations

from emulator.errors import MetricsError
from emulator.io.runfolder import MethodRun
from emulator.metrics.features import load_gray8
from emulator.core.native import is_native_run
from emulator.io.runcsv import read_tables
from emulator.report.html import Thumb, spread_indices, contact_sheet, thumbnail

__all__ = ["CONVERSION", "benchmark_frames", "progress_iter", "method_frames", "features_sheet"]

#: The 12-bit to 8-bit conversion, as stated in the results.
CONVERSION = (
    "gray8 = clip(round((cv2.cvtColor(raw, COLOR_BayerRG2GRAY) - black_level) * 255 / "
    "(white_level - black_level)), 0, 255) for png16 Bayer images; png8 images, "
    "converted by exposim run with the same formula, are used as saved"
)


def progress_iter(iterable, progress, desc: str, total: int):
    """``iterable`` with progress: a tqdm bar when ``progress`` is True; when it is a callable, it is called
    as ``progress(desc, done, total)`` before each item and after the last (the command line turns that
    into log lines); nothing when False."""
    if callable(progress):
        return _reported(iterable, progress, desc, total)
    from tqdm import tqdm

    return tqdm(iterable, desc=desc, total=total, unit="img", disable=not progress, leave=False)


def _reported(iterable, progress, desc: str, total: int):
    done = 0
    for item in iterable:
        progress(desc, done, total)
        yield item
        done += 1
    progress(desc, done, total)


def benchmark_frames(run, every_frame: bool = False):
    """The frames a benchmark uses of ``run`` (a :class:`~emulator.io.runfolder.RunFolder`).

    A cycle-rate run: all of them.  A native-rate run (``exposim run --rate native``): one per
    recorder cycle, the frame at the cycle's first shot (column ``benchmarked`` of each method's
    table), the instant the native-rate live condition is benchmarked at, so that both rates are
    compared on the same number of equally spaced images; ``every_frame``: all of them.
    """
    from dataclasses import replace

    if every_frame or not is_native_run(run.meta):
        return run
    tables = read_tables(run.path, list(run.methods))
    methods = {}
    for name, method in run.methods.items():
        t = tables[name]
        if "benchmarked" not in t:
            raise MetricsError(f"{run.path / name / 'exposures.csv'}: a native-rate table without its column "
                               "'benchmarked'; pass --every-frame to use every frame")
        keep = {int(ts) for ts, b in zip(t["timestamp_ns"], t["benchmarked"]) if b}
        methods[name] = replace(method, frames=tuple(f for f in method.frames if f.timestamp_ns in keep))
    return replace(run, methods=methods)


def method_frames(method: MethodRun, max_frames: int | None):
    """The frames of ``method`` a benchmark reads: the first ``max_frames`` (at least 2) or all of them."""
    frames = method.frames
    if max_frames is not None:
        if max_frames < 2:
            raise MetricsError(f"max_frames must be at least 2, got {max_frames}")
        frames = frames[:max_frames]
    return frames


def features_sheet(run, result: dict, max_frames, n_cycles: int = 6) -> str:
    """Contact sheet of the images a benchmark compared (first run): sampled left frames per method."""
    rows = []
    for name, method in run.methods.items():
        frames = method_frames(method, max_frames)
        per = {} if result is None else result["methods"].get(name, {})
        cells = []
        for i in spread_indices(len(frames), n_cycles):
            f = frames[i]
            gray = load_gray8(f.left, white_level=run.white_level, black_level=run.black_level)
            exposure = "?" if f.exposure_ms is None else f"{f.exposure_ms:.2f} ms"
            caption = f"frame {i}: {exposure}"
            if per.get("n_keypoints"):
                caption += f", {per['n_keypoints'][i]} keypoints"
            cells.append(Thumb(thumbnail(gray), caption))
        rows.append((name, cells))
    return contact_sheet(rows, title=f"Images compared ({run.path.name}, left camera, sampled frames)")
