"""``exposim validate native SEQ -o OUT``: the command line of :func:`validation.native_loo.run_study`."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from emulator.commands import argtypes
from emulator.core.native import BLUR_STOPS_PER_PX, WARP_MODES
from validation.native_loo.study import NativeLooConfig, run_study
from validation.protocol import Study

__all__ = ["HELP", "STUDY", "add_arguments", "run_from_args"]

HELP = ("native emulation on a real recording, leaving each frame out: every recorded frame is emulated from the "
        "frames around it and compared with itself (image error, motion left after the warp, SIFT good matches) "
        "by motion class and warp mode")


def add_arguments(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The study's options on ``p``."""
    p.add_argument("sequence", metavar="SEQ", help="a recording (BorealHDR layout, folder or zip)")
    p.add_argument("-o", "--output", type=Path, required=True, help="output folder (results.json, report.md)")
    p.add_argument("--force", action="store_true", help="overwrite an existing results.json")
    p.add_argument("--size", type=argtypes.size, metavar="WxH",
                   help="centre crop of every frame, WIDTHxHEIGHT (default: the recorded size)")
    p.add_argument("--frames", type=argtypes.positive_int, metavar="N",
                   help="hide at most N frames, spread evenly over the recording (default: every frame)")
    p.add_argument("--warps", type=argtypes.names, default=WARP_MODES,
                   help=f"warp modes compared, of {','.join(WARP_MODES)} (default: all)")
    p.add_argument("--blur-aware", action="store_true",
                   help=f"the blur-aware native selector ({BLUR_STOPS_PER_PX:g} stop per px of excess blur)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    return p


def _config(args):
    return NativeLooConfig(size=args.size, max_frames=args.frames, warps=tuple(args.warps),
                           blur_stops_per_px=BLUR_STOPS_PER_PX if args.blur_aware else None)


def run_from_args(args) -> int:
    """Run the study from parsed :func:`add_arguments` options; print the table's ``all`` rows."""
    words = ["exposim", "validate", "native", str(args.sequence), "-o", str(args.output)]
    if args.size is not None:
        words += ["--size", f"{args.size[0]}x{args.size[1]}"]
    if args.frames is not None:
        words += ["--frames", str(args.frames)]
    words += ["--warps", ",".join(args.warps)] + (["--blur-aware"] if args.blur_aware else [])
    say = None if args.quiet else (lambda line: print(line, file=sys.stderr, flush=True))
    results = run_study(args.sequence, args.output, _config(args), command=shlex.join(words), force=args.force,
                        progress=say)
    for r in results["summary"]["table"]:
        if r["motion_class"] == "all":
            print(f"{r['warp']}: {r['n_frames']} frames, error {r['rmse_percent']:.2f} %, motion left "
                  f"{r['motion_left_px']:.2f} px, {r['sift_good_matches']:.0f} SIFT good matches")
    print(f"wrote {args.output / 'results.json'} and {args.output / 'report.md'}")
    return 0



#: ``exposim validate native``: real data only, no synthetic extra.
STUDY = Study("native", HELP, add_arguments, run_from_args, extras=())
