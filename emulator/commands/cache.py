"""``exposim cache``: decode a recording's PNGs once into a decoded-frame cache (zstd ``.npy``)."""

from __future__ import annotations

import argparse
from pathlib import Path

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
    p.add_argument("--cache-dir", type=Path, default=None,
                   help="where to write the cache (default: SEQUENCE/.exposim-frames, found automatically)")
    p.add_argument("--level", type=int, default=3, help="zstandard compression level (default: %(default)s)")
    p.set_defaults(func=_cache)


register.order = 15  # after info


def _cache(args) -> int:
    from tqdm import tqdm

    from emulator.io.framecache import build_frame_cache

    if not 1 <= args.level <= 22:
        raise SystemExit(f"exposim cache: error: --level must be 1..22, got {args.level}")
    with tqdm(total=None, unit="frame", desc="cache", disable=None) as bar:
        def progress(done, total):
            bar.total = total
            bar.update(done - bar.n)

        s = build_frame_cache(args.sequence, args.cache_dir, level=args.level, progress=progress)
    ratio = s["cache_bytes"] / s["png_bytes"] if s["png_bytes"] else float("nan")
    print(f"{s['cache_dir']}: {s['frames']} frames ({s['written']} written, {s['kept']} kept, "
          f"{s['removed']} stale removed, {s['rebuilt']} bad rebuilt), {s['cache_bytes'] / 1e6:.1f} MB ({ratio:.2f} x the PNGs)")
    return 0
