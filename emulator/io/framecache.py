"""Decoded-frame cache: each 16-bit PNG of a recording stored once as a zstd-compressed ``.npy``.

Decoding a 1920 x 1200 16-bit PNG costs ~30-40 ms on the project machine, and the closed
loop decodes the same brackets on every run over a sequence.  :func:`emulator.tools.framecache.build_frame_cache`
decodes every frame once and writes ``<cache>/camera_<side>/<exposure>/<timestamp>.<size>-<mtime_ns>.npy.zst``
(the PNG's byte size and modification time in the name: a PNG replaced after the cache was
built no longer matches its entry, and is decoded from the PNG again).  When
:func:`emulator.io.borealhdr.load_sequence` finds a cache (``frame_cache=`` or the default
folder :data:`CACHE_DIRNAME` inside the recording), ``Frame.load`` reads the entry instead
of the PNG: the same uint16 array, byte for byte (checked when the cache is built).

Format: the ``.npy`` bytes of the decoded array (``numpy.lib.format``), compressed with
zstandard (level 3 by default), read straight into a fresh array (no copy).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from emulator.errors import DatasetError

__all__ = [
    "CACHE_DIRNAME",
    "CACHE_SUFFIX",
    "encode_frame",
    "cached_frame_path",
    "read_cached_frame",
    "resolve_frame_cache",
]

#: Default cache folder inside a recording (load_sequence ignores dot folders).
CACHE_DIRNAME = ".exposim-frames"
#: Suffix of a cache entry.
CACHE_SUFFIX = ".npy.zst"
#: zstandard level of :func:`emulator.tools.framecache.build_frame_cache` (decoding speed barely depends on it).
DEFAULT_LEVEL = 3


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
            raise DatasetError(f"{default}: no frame cache (build it with `exposim cache`)")
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


def encode_frame(img: np.ndarray, level: int = DEFAULT_LEVEL) -> bytes:
    """The cache entry bytes of a decoded frame (zstd-compressed ``.npy``)."""
    import zstandard

    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.ascontiguousarray(img), allow_pickle=False)
    return zstandard.ZstdCompressor(level=level).compress(buf.getvalue())


def read_cached_frame(path, *, png_path=None, white_level: int | None = None) -> np.ndarray | None:
    """The frame stored at ``path`` (uint16, writeable, owning its data), or None if absent.

    Raises :class:`~emulator.errors.DatasetError` naming the file for a corrupt entry, and,
    as :func:`emulator.io.png.read_png16` does, for DN above ``white_level``.
    """
    import zstandard

    path = Path(path)
    try:
        fh = open(path, "rb")
    except FileNotFoundError:
        return None
    source = f" (cache of {png_path})" if png_path is not None else ""
    try:
        with fh, zstandard.ZstdDecompressor().stream_reader(fh) as reader:
            version = np.lib.format.read_magic(reader)
            read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
                np.lib.format.read_array_header_2_0
            shape, fortran, dtype = read_header(reader)
            if dtype != np.uint16 or len(shape) != 2 or fortran:
                raise DatasetError(f"{path}: frame cache entry holds {dtype} {shape}, expected a 2-D uint16 "
                                   f"image{source}; rebuild the cache")
            img = np.empty(shape, dtype=np.uint16)
            view = memoryview(img).cast("B")
            got = 0
            while got < img.nbytes:
                n = reader.readinto(view[got:])
                if not n:
                    break
                got += n
    except (zstandard.ZstdError, ValueError, OSError, EOFError) as exc:
        raise DatasetError(f"{path}: corrupt frame cache entry{source} ({exc}); rebuild the cache") from None
    if got != img.nbytes:
        raise DatasetError(f"{path}: truncated frame cache entry{source} ({got} of {img.nbytes} bytes); "
                           "rebuild the cache")
    if white_level is not None:
        top = int(img.max())
        if top > white_level:
            from emulator.io.png import white_level_message

            raise DatasetError(white_level_message(png_path or path, top, white_level))
    return img


