"""``exposim cache``: decode a recording's PNGs once into a decoded-frame cache (zstd ``.npy``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from emulator.commands.progress import add_quiet
from emulator.commands.body import CommandBody

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "cache",
        help="decode a recording once into a frame cache that later runs read instead of the PNGs",
        description=(
            "Decode every 16-bit PNG of a recording once and store it zstd-compressed beside the "
            "recording (default SEQUENCE/.exposim-frames). `exposim run`, `emulate` and `info` then "
            "read the cache instead of decoding the PNGs (the same uint16 arrays, byte for byte; each "
            "entry is checked against its PNG when written). An entry names its PNG's size and "
            "modification time, so a replaced PNG is decoded again. Re-running keeps valid entries."
        ),
    )
    p.add_argument("sequence", type=Path, help="recording folder holding camera_left/ and camera_right/")
    p.add_argument("--frame-cache", type=Path, default=None, metavar="DIR",
                   help="where to write the cache (default: SEQUENCE/.exposim-frames, found automatically); a "
                        "folder elsewhere serves a read-only recording: give run, info and emulate the same "
                        "--frame-cache DIR")
    p.add_argument("--cache-dir", dest="frame_cache", type=Path, help=argparse.SUPPRESS)  # old spelling
    add_quiet(p)
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.add_argument("--level", type=int, default=3,
                   help="zstandard level: 1..22 (default %(default)s; higher packs smaller), or one of zstd's fast "
                        "levels -1..-100 (entries 1.2-1.8x larger, read in about half the time: 2.5-3.7 ms "
                        "instead of 6.7-7.8 ms for a 1920x1200 frame)")
    p.set_defaults(func=CommandBody("emulator.commands.cache_body:cache"))


register.order = 15  # after info
