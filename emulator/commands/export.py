"""``exposim export``: one method's emulated images for downstream SLAM (EuRoC, TUM, ROS 2 bag).

Only parses arguments and calls :func:`emulator.io.export.export_method`.
"""

from __future__ import annotations

import argparse
import sys

from emulator.commands.argtypes import refine_mode
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

__all__ = ["register"]


def _export(args: argparse.Namespace) -> int:
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


def register(subparsers) -> None:
    """Add ``export`` to the ``exposim`` parser."""
    p = subparsers.add_parser(
        "export",
        help="export one method's emulated images for SLAM: EuRoC, TUM lists, ROS 2 bag",
        description="Write one AE method's emulated left/right images of a run folder in a layout SLAM "
        "pipelines read: euroc (mav0/cam0/data/<ns>.png + data.csv, cam1; ORB-SLAM3, VINS-Fusion, Basalt), "
        "tum (left/, right/ + left.txt, right.txt) or rosbag2 (sensor_msgs/Image on /cam0/image_raw and "
        "/cam1/image_raw, CameraInfo on /camN/camera_info when the calibration is known; written with rosbags). "
        "png16 runs are exported as 16-bit grey in DN (mono16) unless --mono8; png8 runs as saved (mono8). "
        "The output folder must not exist; nothing is ever overwritten.",
    )
    p.add_argument("run_dir", metavar="RUN_DIR", help="output folder of `exposim run` (images saved)")
    p.add_argument("--method", required=True, help="the AE method whose images to export")
    p.add_argument("--format", required=True, choices=("euroc", "tum", "rosbag2"), help="output layout")
    p.add_argument("-o", "--output", required=True, help="output folder to create (must not exist)")
    p.add_argument("--mono8", action="store_true",
                   help="png16 runs: 8-bit grey by the benchmarks' fixed scale instead of 16-bit grey in DN")
    p.add_argument("--calibration", help="folder with left.yaml, right.yaml (default: chosen from the recording's "
                   "layout and date, as bench vo; none is written when none is found)")
    p.add_argument("--no-calibration", action="store_true", help="write no calibration files or camera_info")

    p.add_argument("--refine-extrinsics", type=refine_mode, default="auto", metavar="auto|N",
                   help="check the calibration's stereo extrinsics on the method's left-right pairs as bench vo does: "
                        "'auto' (default) refines them when the epipolar residual needs it, N always refines from N "
                        "pairs, 0 writes the calibration as given")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=_export)


register.order = 45  # place in `exposim --help`
