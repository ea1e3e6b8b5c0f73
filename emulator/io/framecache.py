"""Decoded-frame cache: each 16-bit PNG of a recording stored once as a zstd-compressed ``.npy``.

Decoding a 1920 x 1200 16-bit PNG costs ~30-40 ms on the project machine, and the closed
loop decodes the same brackets on every run over a sequence.  :func:`emulator.orchestration.framecache.build_frame_cache`
decodes every frame once and writes ``<cache>/camera_<side>/<exposure>/<timestamp>.<size>-<mtime_ns>.npy.zst``
(the PNG's byte size and modification time in the name: a PNG replaced after the cache was
built no longer matches its entry, and is decoded from the PNG again).  When
:func:`emulator.io.borealhdr.load_sequence` finds a cache (``frame_cache=`` or the default
folder :data:`CACHE_DIRNAME` inside the recording), ``Frame.load`` reads the entry instead
of the PNG: the same uint16 array, byte for byte (checked when the cache is built).

Format (version 2): one zstandard frame (level 3 by default, or any level from zstd's fast -100
to 22; with zstd's content checksum)
holding :data:`MAGIC`, one JSON line ``{"key": ..., "crc32": ...}`` and the ``.npy`` bytes of
the decoded array (``numpy.lib.format``), read straight into a fresh array (no copy).  The
key is the entry's place in the cache (``camera_<side>/<exposure>/<timestamp>.<size>-<mtime_ns>``)
and ``crc32`` that of the pixel bytes: both are checked on every read, so an entry moved or
swapped to another frame's name, altered, truncated, or of an older format is a bad entry
(:class:`FrameCacheEntryError`).  :func:`emulator.io.borealhdr.read_frame` then decodes the
PNG and writes the entry again, and :func:`emulator.orchestration.framecache.build_frame_cache` (``exposim cache``) rebuilds
every bad entry it finds.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

from emulator.errors import DatasetError
from emulator.io.crc import crc32
from emulator.io.files import atomic_write_bytes
from emulator.io.png import white_level_message

__all__ = [
    "encode_entry",
    "CACHE_DIRNAME",
    "CACHE_SUFFIX",
    "cached_frame_path",
    "read_cached_frame",
    "resolve_frame_cache",
    "write_cached_frame",
    "FrameCacheEntryError",
    "MAGIC",
]

#: First bytes of a (version 2) cache entry, inside its zstd frame.
MAGIC = b"EXPOSIM-FRAME-2\n"


class FrameCacheEntryError(DatasetError):
    """A frame cache entry is bad (corrupt, truncated, altered, another frame's, old format):
    rebuilt from its PNG, never used."""

#: Default cache folder inside a recording (load_sequence ignores dot folders).
CACHE_DIRNAME = ".exposim-frames"
#: Suffix of a cache entry.
CACHE_SUFFIX = ".npy.zst"
#: zstandard level of :func:`emulator.orchestration.framecache.build_frame_cache`.  A read of a 1920x1200
#: frame takes 6.7-7.8 ms at this level, 5.4-6.1 ms at 1, and 2.5-3.7 ms at zstd's fast level -1,
#: whose entries are 1.2-1.8x larger (0.90-1.0 of the pixel bytes against 0.55-0.78).
DEFAULT_LEVEL = 3
#: The fastest level ``exposim cache --level`` accepts (zstd's fast levels are -1 and below).
MIN_FAST_LEVEL = -100


def resolve_frame_cache(sequence_dir, frame_cache) -> Path | None:
    """The cache folder to use: ``frame_cache`` (a path; ``False`` for none), or by default
    ``<sequence>/.exposim-frames`` when it exists."""
    if frame_cache is False:
        return None
    if frame_cache is None or frame_cache is True:
        default = Path(sequence_dir) / CACHE_DIRNAME
        if default.is_dir():
            return default
        if frame_cache is True:
            raise DatasetError(f"{default}: no frame cache (build it with build_frame_cache)")
        return None
    path = Path(frame_cache)
    if not path.is_dir():
        raise DatasetError(f"{path}: frame cache folder not found")
    return path


def cached_frame_path(cache_dir, sequence_dir, png_path) -> Path:
    """Where the cache entry of ``png_path`` (inside ``sequence_dir``) lives, for its current size and mtime."""
    png_path = Path(png_path)
    st = png_path.stat()
    rel = png_path.relative_to(sequence_dir)
    return Path(cache_dir) / rel.parent / f"{png_path.stem}.{st.st_size}-{st.st_mtime_ns}{CACHE_SUFFIX}"


def entry_key(path) -> str:
    """The key an entry at ``path`` must hold: its last three path parts, suffix removed."""
    parts = Path(path).parts[-3:]
    return "/".join(parts)[: -len(CACHE_SUFFIX)] if parts[-1].endswith(CACHE_SUFFIX) else "/".join(parts)


def encode_entry(img: np.ndarray, level: int, key: str) -> bytes:
    import zstandard

    img = np.ascontiguousarray(img)
    buf = io.BytesIO()
    buf.write(MAGIC)
    buf.write(json.dumps({"key": key, "crc32": crc32(memoryview(img).cast("B"))}).encode() + b"\n")
    np.lib.format.write_array(buf, img, allow_pickle=False)
    return zstandard.ZstdCompressor(level=level, write_checksum=True).compress(buf.getvalue())


def write_cached_frame(path, img: np.ndarray, *, level: int = DEFAULT_LEVEL) -> Path:
    """Write the cache entry of a decoded frame at ``path`` (atomically; its key from ``path``)."""
    return atomic_write_bytes(path, encode_entry(img, level, entry_key(path)), overwrite=True)


def read_cached_frame(path, *, png_path=None, white_level: int | None = None) -> np.ndarray | None:
    """The frame stored at ``path`` (uint16, writeable, owning its data), or None if absent.

    Raises :class:`~emulator.errors.DatasetError` naming the file for a corrupt entry, and,
    as :func:`emulator.io.png.read_png16` does, for DN above ``white_level``.
    """
    import zstandard

    path = Path(path)
    source = f" (cache of {png_path})" if png_path is not None else ""
    try:
        fh = open(path, "rb")
    except FileNotFoundError:
        return None
    except IsADirectoryError:
        raise FrameCacheEntryError(f"{path}: is a folder, not a frame cache entry{source}; rebuild the cache") from None
    try:
        with fh, zstandard.ZstdDecompressor().stream_reader(fh) as reader:
            head = reader.read(len(MAGIC))
            if len(head) < len(MAGIC):
                raise FrameCacheEntryError(f"{path}: truncated frame cache entry{source}; rebuild the cache")
            if head != MAGIC:
                raise FrameCacheEntryError(f"{path}: not a version-2 frame cache entry{source}; rebuild the cache")
            line = b""
            while not line.endswith(b"\n") and len(line) < 4096:
                chunk = reader.read(1)
                if not chunk:
                    break
                line += chunk
            try:
                meta = json.loads(line)
            except ValueError:
                meta = None
            if not isinstance(meta, dict) or meta.get("key") != entry_key(path):
                raise FrameCacheEntryError(
                    f"{path}: frame cache entry holds {meta.get('key') if isinstance(meta, dict) else 'no key'!r}, "
                    f"not {entry_key(path)!r} (moved or swapped){source}; rebuild the cache")
            version = np.lib.format.read_magic(reader)
            read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
                np.lib.format.read_array_header_2_0
            shape, fortran, dtype = read_header(reader)
            if dtype != np.uint16 or len(shape) != 2 or fortran:
                raise FrameCacheEntryError(f"{path}: frame cache entry holds {dtype} {shape}, expected a 2-D uint16 "
                                   f"image{source}; rebuild the cache")
            img = np.empty(shape, dtype=np.uint16)
            view = memoryview(img).cast("B")
            got = 0
            while got < img.nbytes:
                n = reader.readinto(view[got:])
                if not n:
                    break
                got += n
            extra = reader.read(1)  # reach the end of the frame: zstd checks its content checksum
    except FrameCacheEntryError:
        raise
    except (zstandard.ZstdError, ValueError, OSError, EOFError) as exc:
        raise FrameCacheEntryError(f"{path}: corrupt frame cache entry{source} ({exc}); rebuild the cache") from None
    if got != img.nbytes or extra:
        raise FrameCacheEntryError(f"{path}: truncated frame cache entry{source} ({got} of {img.nbytes} bytes); "
                                   "rebuild the cache")
    if crc32(memoryview(img).cast("B")) != meta.get("crc32"):
        raise FrameCacheEntryError(f"{path}: frame cache entry fails its checksum{source}; rebuild the cache")
    if white_level is not None:
        top = int(img.max())
        if top > white_level:
            raise DatasetError(white_level_message(png_path or path, top, white_level))
    return img


