"""``exposim export``: one method's emulated images for downstream SLAM (EuRoC, TUM, ROS 2 bag).

Only parses arguments and calls :func:`emulator.io.export.export_method`.
"""

from __future__ import annotations

from emulator.commands.argtypes import refine_mode
from emulator.commands.body import CommandBody

__all__ = ["register"]


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
    p.set_defaults(func=CommandBody("emulator.commands.export_body:export"))


register.order = 45  # place in `exposim --help`
