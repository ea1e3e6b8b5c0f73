"""Run the leave-one-frame-out check of native emulation and write ``results.json`` and ``report.md``."""

from __future__ import annotations

import platform
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from validation.common import ValidationError, provenance
from validation.native_loo.measure import GOOD_MATCH_PX, MOTION_CLASSES, crop_sequence, leave_one_out
from emulator.cells import format_number, median_finite

__all__ = ["NativeLooConfig", "run_study", "summarise", "report_markdown"]


@dataclass(frozen=True)
class NativeLooConfig:
    """What the check measures.

    Attributes
    ----------
    size : (int, int) or None
        Centre crop (width, height) of every frame; None: the recorded size.
    max_frames : int or None
        Hide at most this many frames, spread evenly over the recording; None: every frame.
    warps : tuple of str
        Warp modes compared (:data:`emulator.core.native.WARP_MODES`).
    blur_stops_per_px : float or None
        None: the native selector as runs use it; a number: the blur-aware selector with this weight.
    """

    size: tuple[int, int] | None = None
    max_frames: int | None = None
    warps: tuple[str, ...] = ("none", "rotation", "flow")
    blur_stops_per_px: float | None = None

    def as_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}


def summarise(rows: list[dict], warps) -> dict:
    """Medians by motion class (and over every frame) and warp mode; CPU per frame of each mode."""
    classes = [name for name, _ in MOTION_CLASSES] + ["unknown", "all"]
    table = []
    for cls in classes:
        for mode in warps:
            sel = [r for r in rows if r["warp"] == mode and (cls == "all" or r["motion_class"] == cls)]
            if not sel:
                continue
            table.append({"motion_class": cls, "warp": mode, "n_frames": len(sel),
                          "rate_deg_s": median_finite([r.get("rate_deg_s") for r in sel]),
                          "rmse_percent": median_finite([r.get("rmse_percent") for r in sel]),
                          "motion_left_px": median_finite([r.get("motion_left_px") for r in sel]),
                          "sift_good_matches": median_finite([r.get("sift_good_matches") for r in sel]),
                          "neighbour_offset_abs": median_finite(abs(r["source_offset"]) for r in sel)})
    cpu = {m: sum(r["cpu_s"] for r in rows if r["warp"] == m) for m in warps}
    n = {m: sum(1 for r in rows if r["warp"] == m) for m in warps}
    rot = cpu.get("rotation")
    speed = {m: {"cpu_s": cpu[m], "frames": n[m], "frames_per_cpu_s": (n[m] / cpu[m]) if cpu[m] > 0 else None,
                 "cpu_over_rotation": (cpu[m] / rot) if rot else None} for m in warps}
    return {"table": table, "speed": speed}


def report_markdown(results: dict) -> str:
    """``report.md``: the table by motion class and warp mode, and the speed of each mode."""
    c = results["config"]
    lines = ["# Native emulation, leave one frame out", "",
             f"Recording `{results['sequence']}`, {results['n_frames_hidden']} of {results['n_frames']} frames of the "
             f"first camera hidden in turn, size {results['size'][0]}x{results['size'][1]}, selector "
             f"{'blur-aware' if c['blur_stops_per_px'] is not None else 'as runs use it'}.", "",
             "Each hidden frame is emulated at its own exposure from the frames around it (none of its own shots, "
             "on any camera) and compared with the real frame: image error (RMSE, % of the DN range, over the "
             "pixels the source can give), motion left (median optical-flow length from the emulated to the real "
             f"frame, px) and SIFT good matches (ratio test, keypoints within {GOOD_MATCH_PX:g} px). Motion class: "
             "the gyro's mean rate over a frame interval each side (rest < 3, slow 3-8, turning >= 8 deg/s).", "",
             "| motion | warp | frames | rate deg/s | error % | motion left px | SIFT good matches | |offset| |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in results["summary"]["table"]:
        lines.append(f"| {r['motion_class']} | {r['warp']} | {r['n_frames']} | {format_number(r['rate_deg_s'], '.1f')} | "
                     f"{format_number(r['rmse_percent'], '.2f')} | {format_number(r['motion_left_px'], '.2f')} | "
                     f"{format_number(r['sift_good_matches'], '.0f')} | "
                     f"{format_number(r['neighbour_offset_abs'], '.0f')} |")
    lines += ["", "| warp | frames | CPU s (selection, emulation, warp) | frames per CPU s | CPU / rotation's |",
              "| --- | ---: | ---: | ---: | ---: |"]
    for m, s in results["summary"]["speed"].items():
        lines.append(f"| {m} | {s['frames']} | {format_number(s['cpu_s'], '.3f')} | {format_number(s['frames_per_cpu_s'], '.1f')} | "
                     f"{format_number(s['cpu_over_rotation'], '.2f')} |")
    lines += ["", f"Command: `{results['provenance']['experiment']}`", ""]
    return "\n".join(lines)


def _frames_to_hide(n: int, max_frames: int | None) -> list[int]:
    if max_frames is None or max_frames >= n:
        return list(range(n))
    return sorted({int(round(x)) for x in np.linspace(0, n - 1, max(1, int(max_frames)))})


def run_study(sequence, out_dir, config: NativeLooConfig = NativeLooConfig(), *, command: str = "",
              force: bool = False, progress=None) -> dict:
    """Hide each frame of ``sequence`` (a path or :class:`~emulator.core.dataset.Sequence`) in turn, measure, write
    ``results.json`` and ``report.md`` into ``out_dir`` (refused where a results.json is, unless ``force``).
    ``progress(line)`` hears a line per frame."""
    from emulator.errors import CalibrationError
    from emulator.io.files import prepare_output, write_results, write_text
    from emulator.playback.motion import recording_motion
    from emulator.core.native import WARP_MODES
    from emulator.playback import RunConfig
    from emulator.playback.native import NativeProvider, recording_stamp
    from emulator.playback.offline import resolve_sequence

    bad = [w for w in config.warps if w not in WARP_MODES]
    if bad or not config.warps:
        raise ValidationError(f"warps must be some of {', '.join(WARP_MODES)}, got {','.join(config.warps)!r}")
    out = prepare_output(Path(out_dir), force=force)
    seq = resolve_sequence(sequence, imu_warning=False)
    run_config = RunConfig(rate="native")
    response = run_config.response_for(seq)
    try:
        motion = recording_motion(seq, stamp=recording_stamp(seq))
    except CalibrationError:
        motion = None
    seq, motion = crop_sequence(seq, motion, config.size)
    warps = tuple(config.warps) if motion is not None else ("none",)
    providers = {w: NativeProvider(seq, run_config, response, motion=motion, warp=w,
                                   blur_stops_per_px=config.blur_stops_per_px) for w in warps}
    first = providers[warps[0]]
    hide = _frames_to_hide(len(first.frames), config.max_frames)
    rows = leave_one_out(providers, hide, response, progress=progress)
    shape = first.images(0).get(first.cameras[0], first.frames.exposures[0])[0].shape
    results = {
        "sequence": str(seq.path), "n_frames": len(first.frames), "n_frames_hidden": len(hide),
        "size": [int(shape[1]), int(shape[0])], "gyro": motion is not None, "config": config.as_dict(),
        "summary": summarise(rows, warps), "rows": rows,
        "machine": {"platform": platform.platform(), "processor": platform.processor() or platform.machine()},
        "provenance": provenance(command, config.as_dict()),
    }
    write_results(out / "results.json", results, float_digits=12)
    write_text(out / "report.md", report_markdown(results))
    return results
