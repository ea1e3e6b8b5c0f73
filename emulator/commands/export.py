"""``exposim export``: one method's emulated images for downstream SLAM (EuRoC, TUM, ROS 2 bag).

Only parses arguments and calls :func:`emulator.io.export.export_method`.
"""

from __future__ import annotations

import argparse
import json
import sys

__all__ = ["register"]


def _export(args: argparse.Namespace) -> int:
    from emulator.errors import CalibrationError
    from emulator.io.export import export_method
    from emulator.io.runfolder import read_run_folder
    from emulator.metrics.stereo import choose_calibration, load_stereo_calibration

    run = read_run_folder(args.run_dir, [args.method])
    calib, note = None, ""
    if not args.no_calibration:
        first = run.methods[args.method].frames[0].timestamp_ns if run.methods[args.method].frames else None
        try:
            choice = choose_calibration(run.sequence, args.calibration, first)
            calib = load_stereo_calibration(choice.folder)
            note = f"{choice.folder} ({choice.reason})"
        except CalibrationError as exc:
            if args.calibration is not None:
                raise
            note = f"none: {exc}"
    summary = export_method(run, args.method, args.output, args.format, calibration=calib, mono8=args.mono8)
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"exported {summary['n_images']} images of {args.method} ({', '.join(summary['cameras'])}; "
              f"{', '.join(summary['encodings'])}) as {args.format} to {summary['output']}", file=sys.stderr)
        print(f"calibration: {note or 'not written (--no-calibration)'}", file=sys.stderr)
    return 0


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
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=_export)


register.order = 45  # place in `exposim --help`
