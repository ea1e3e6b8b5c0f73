"""``exposim emulate``: one cycle emulated at any exposure time, written as PNGs (16-bit Bayer or 8-bit grey)."""

from __future__ import annotations

import argparse
from pathlib import Path

from emulator.commands.body import CommandBody

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "emulate",
        help="emulate one cycle at any exposure time and write PNGs (16-bit Bayer or viewable 8-bit grey)",
        description=(
            "Emulate the image(s) a camera would have captured at --exposure-ms from the bracket "
            "the selector picks in cycle --cycle (one choice for both cameras of a stereo pair). "
            "Writes OUTPUT/<camera>_cycle<NNNN>_<T>ms.png: --save png16 (default) keeps the 12-bit "
            "Bayer mosaic in a 16-bit PNG, which looks black in an image viewer; --save png8 writes "
            "it demosaiced to 8-bit grey with the black level subtracted, as `exposim run --save png8`."
        ),
    )
    p.add_argument("sequence", type=Path, help="recording folder (BorealHDR layout, see `exposim info`)")
    p.add_argument("--exposure-ms", type=float, required=True, help="target exposure time, ms (finite, > 0)")
    p.add_argument("--cycle", type=int, required=True, help="cycle index, from 0 (see `exposim info`)")
    p.add_argument("--camera", choices=("left", "right", "both"), default="both",
                   help="camera(s) to emulate (default both: the ones the recording has)")
    p.add_argument("--selector", choices=("higher-no-sat", "closest", "reference"), default="higher-no-sat",
                   help="bracket selector, decided on the first camera's saturation (default higher-no-sat)")
    p.add_argument("--blur-aware", action="store_true",
                   help="with higher-no-sat: of the two brackets around the target, take the shorter one when "
                        "the longer one's extra motion blur (predicted from the gyro) costs more than the shorter "
                        "one's extra noise; one pixel of blur weighs as much as twice the relative noise of a "
                        "capture at the target (docs/blur.md)")
    p.add_argument("--response", type=Path, help="pcalib file (default: found beside the recording)")
    p.add_argument("--from-ms", type=float, default=None, metavar="E",
                   help="emulate from the bracket of E ms (must be in the cycle) instead of the selector's choice")
    p.add_argument("--blur", choices=("none", "consistent"), default="none",
                   help="none (default): exact eq. 2; consistent: add the gyro's blur of the extra exposure time "
                        "where the target is longer than the bracket (needs imu/imu.csv; docs/blur.md)")
    p.add_argument("--calibration", type=Path, default=None, metavar="DIR",
                   help="folder with left.yaml/right.yaml for --blur (default: found as `exposim info` does)")
    p.add_argument("--stamp", choices=("start", "middle", "end"), default="end",
                   help="where a frame's timestamp lies in its exposure window, for --blur (default end; docs/blur.md)")
    p.add_argument("--frame-cache", type=Path, default=None, metavar="DIR",
                   help="read decoded frames from this frame cache (made by 'exposim cache SEQ --frame-cache DIR'; "
                        "default: SEQUENCE/.exposim-frames when it exists)")
    p.add_argument("--save", choices=("png16", "png8"), default="png16",
                   help="png16 (default): 12-bit Bayer DN in a 16-bit PNG; png8: demosaiced 8-bit grey, viewable")
    p.add_argument("-o", "--output", type=Path, required=True, help="output folder for the PNG(s) (created)")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.set_defaults(func=CommandBody("emulator.commands.emulate_body:emulate_command"))


register.order = 20  # place in `exposim --help`
