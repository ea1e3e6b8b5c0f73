"""Build a recording's decoded-frame cache (:mod:`emulator.io.framecache` is the format)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from emulator.errors import DatasetError
from emulator.io.borealhdr import load_sequence
from emulator.io.files import atomic_write_bytes
from emulator.io.framecache import (CACHE_DIRNAME, CACHE_SUFFIX, DEFAULT_LEVEL, FrameCacheEntryError,
                                    cached_frame_path, encode_entry, entry_key, read_cached_frame)
from emulator.io.png import read_png16

__all__ = ["build_frame_cache"]


def build_frame_cache(
    sequence_dir,
    cache_dir=None,
    *,
    level: int = DEFAULT_LEVEL,
    verify: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> dict:
    """Decode every frame of a recording once and store it in ``cache_dir`` (default
    ``<sequence>/.exposim-frames``); entries already present for the current PNG are kept.

    Entries present are checked (key and checksum, :func:`read_cached_frame`) and bad ones
    rebuilt (counted in ``written`` and ``rebuilt``).  ``verify`` reads each new entry back and compares it with the decoded PNG (byte for
    byte); a mismatch raises and removes the entry.  Entries of an older version of a PNG
    are removed.  Returns counts and sizes: ``frames``, ``written``, ``kept``, ``removed``,
    ``png_bytes``, ``cache_bytes``, ``cache_dir``.  ``progress(done, total)`` after each frame.
    """
    root = Path(sequence_dir)
    seq = load_sequence(root, frame_cache=False)
    cache = Path(cache_dir) if cache_dir is not None else root / CACHE_DIRNAME
    frames = [f for cycle in seq.cycles for cam in cycle.frames.values() for f in cam.values()]
    frames.sort(key=lambda f: (f.camera, f.exposure_ms, f.timestamp_ns))
    summary = {"cache_dir": str(cache), "frames": len(frames), "written": 0, "kept": 0, "removed": 0,
               "rebuilt": 0, "png_bytes": 0, "cache_bytes": 0}
    for i, frame in enumerate(frames, 1):
        target = cached_frame_path(cache, root, frame.path)
        summary["png_bytes"] += frame.path.stat().st_size
        for old in target.parent.glob(f"{frame.path.stem}.*{CACHE_SUFFIX}") if target.parent.is_dir() else ():
            if old != target:
                old.unlink()
                summary["removed"] += 1
        bad = False
        if target.is_file():
            try:
                read_cached_frame(target, png_path=frame.path)
            except FrameCacheEntryError:
                bad = True
        if target.is_file() and not bad:
            summary["kept"] += 1
        else:
            img = read_png16(frame.path, white_level=frame.white_level)
            atomic_write_bytes(target, encode_entry(img, level, entry_key(target)), overwrite=True)
            summary["rebuilt"] += bad
            if verify:
                back = read_cached_frame(target, png_path=frame.path)
                if back is None or back.shape != img.shape or back.tobytes() != img.tobytes():
                    target.unlink(missing_ok=True)
                    raise DatasetError(f"{target}: cache entry does not read back as {frame.path}")
            summary["written"] += 1
        summary["cache_bytes"] += target.stat().st_size
        if progress is not None:
            progress(i, len(frames))
    return summary
