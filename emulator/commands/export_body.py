"""What ``exposim export`` runs, imported when it runs (its arguments: :mod:`emulator.commands.export`)."""

from __future__ import annotations

import argparse
import sys

from emulator.errors import CalibrationError
from emulator.io.export import export_method
from emulator.io.files import strict_json
from emulator.io.runfolder import read_run_folder
from emulator.metrics.stereo import (
    choose_calibration,
    load_stereo_calibration,
    StereoCalibration,
    rectified_camera_infos,
)
from emulator.metrics.vo_bench import check_extrinsics

__all__ = ["export"]


def export(args: argparse.Namespace) -> int:
    run = read_run_folder(args.run_dir, [args.method])
    calib, note, written = None, "", {"written": "none (--no-calibration)"}
    if not args.no_calibration:
        first = run.methods[args.method].frames[0].timestamp_ns if run.methods[args.method].frames else None
        try:
            choice = choose_calibration(run.sequence, args.calibration, first)
            calib = load_stereo_calibration(choice.folder)
        except CalibrationError as exc:
            if args.calibration is not None:
                raise
            note = f"none: {exc}"
            written = {"written": "none", "reason": str(exc)}
        else:
            calib, written = _checked_extrinsics(calib, run, args)
            written = {"folder": str(choice.folder), "reason": choice.reason, **written}
            note = f"{choice.folder} ({choice.reason}), {written['line']}"
    summary = export_method(run, args.method, args.output, args.format, calibration=calib, mono8=args.mono8,
                            metadata={"calibration_written": written})
    if args.json:
        print(strict_json(summary))
    else:
        print(f"exported {summary['n_images']} images of {args.method} ({', '.join(summary['cameras'])}; "
              f"{', '.join(summary['encodings'])}) as {args.format} to {summary['output']}", file=sys.stderr)
        print(f"calibration: {note or 'not written (--no-calibration)'}", file=sys.stderr)
    return 0


def _checked_extrinsics(calib, run, args):
    """``bench vo``'s extrinsics check on the exported method's stereo pairs (the same code): the
    calibration to write (the refined pose as the rectification R, P of both cameras) and its record."""
    frames = run.methods[args.method].frames
    if args.refine_extrinsics == 0:
        return calib, {"written": "given", "line": "written as given (--refine-extrinsics 0: not checked)"}
    if not frames or any(f.right is None for f in frames):
        return calib, {"written": "given", "line": "written as given (no right images to check it with)"}
    refined, record = check_extrinsics(calib, frames, run, args.refine_extrinsics)
    residual = record.get("epipolar_residual_px")
    if not record.get("refined"):
        shown = "" if residual is None else f"epipolar residual {residual:.2f} px, "
        return calib, {"written": "given", "extrinsics": record, "line": f"written as given ({shown}{record['reason']})"}
    after = record["estimate"]["epipolar_residual_after_px"]
    left, right = rectified_camera_infos(refined)
    out = StereoCalibration(left, right, refined.baseline_m, refined.R, refined.T)
    return out, {"written": "refined", "extrinsics": record,
                 "line": f"extrinsics refined as bench vo does: epipolar residual {residual:.2f} px -> {after:.2f} px; "
                         "left.yaml/right.yaml hold the refined rectification (R, P)"}
