"""``exposim cache``: decode a recording's PNGs once into a decoded-frame cache (zstd ``.npy``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from emulator.commands.progress import add_quiet, bars_enabled
from emulator.io.files import strict_json
from emulator.io.framecache import MIN_FAST_LEVEL
from emulator.orchestration.framecache import build_frame_cache

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
    p.set_defaults(func=_cache)


register.order = 15  # after info


def _cache(args) -> int:
    from tqdm import tqdm

    if not (1 <= args.level <= 22 or MIN_FAST_LEVEL <= args.level <= -1):
        raise SystemExit(f"exposim cache: error: --level must be 1..22, or -1..{MIN_FAST_LEVEL} for zstd's fast "
                         f"levels, got {args.level}")
    with tqdm(total=None, unit="frame", desc="cache", disable=not bars_enabled(args.quiet)) as bar:
        def progress(done, total):
            bar.total = total
            bar.update(done - bar.n)

        s = build_frame_cache(args.sequence, args.frame_cache, level=args.level, progress=progress)
    if args.json:
        print(strict_json({k: str(v) if isinstance(v, Path) else v for k, v in s.items()}, indent=1))
        return 0
    ratio = s["cache_bytes"] / s["png_bytes"] if s["png_bytes"] else float("nan")
    print(f"{s['cache_dir']}: {s['frames']} frames ({s['written']} written, {s['kept']} kept, "
          f"{s['removed']} stale removed, {s['rebuilt']} bad rebuilt), {s['cache_bytes'] / 1e6:.1f} MB ({ratio:.2f} x the PNGs)")
    return 0
