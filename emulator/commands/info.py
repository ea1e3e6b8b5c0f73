"""``exposim info``: describe a recording (cameras, brackets, cycles, partial cycles and gaps)."""

from __future__ import annotations

import argparse
from pathlib import Path

from emulator.commands.body import CommandBody

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "info",
        help="describe a recording: cameras, brackets, cycles, partial cycles and gaps",
        description="Describe a BorealHDR-layout recording (cycles are grouped by timestamp).",
    )
    p.add_argument("sequence", type=Path, help="recording folder holding camera_left/ and camera_right/, or a trajectory .zip")
    p.add_argument("--frame-cache", type=Path, default=None, metavar="DIR",
                   help="read decoded frames from this frame cache (made by 'exposim cache SEQ --frame-cache DIR'; "
                        "default: SEQUENCE/.exposim-frames when it exists)")
    p.add_argument("--json", action="store_true", help="print one JSON object (cycles as a list)")
    p.add_argument("--calibration", type=Path, default=None, metavar="DIR",
                   help="folder with left.yaml/right.yaml (ROS camera_info) for the blur in pixels (default: "
                        "calibration/ inside or beside the recording, BorealHDR: the one of the recording's month)")
    p.add_argument("--stamp", choices=("start", "middle", "end"), default="end",
                   help="where a frame's timestamp lies in its exposure window (default end, fitted on the BorealHDR sample; docs/blur.md)")
    p.set_defaults(func=CommandBody("emulator.commands.info_body:info"))


register.order = 10  # place in `exposim --help`
