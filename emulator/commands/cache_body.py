"""What ``exposim cache`` runs, imported when it runs (its arguments: :mod:`emulator.commands.cache`)."""

from __future__ import annotations

from pathlib import Path

from emulator.commands.progress import bars_enabled
from emulator.io.files import strict_json
from emulator.io.framecache import MIN_FAST_LEVEL
from emulator.orchestration.framecache import build_frame_cache

__all__ = ["cache"]


def cache(args) -> int:
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
