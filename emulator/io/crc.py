"""CRC-32 (zlib's): zlib-ng's vectorised kernel where it is installed, else zlib's own.

Both give the same value for the same bytes (tests/emulator/io/test_crc.py). On a 1920x1200 16-bit frame
(4.6 MB) zlib's ``crc32`` takes 1.07 ms on the development machine and zlib-ng's 0.08 ms. The
frame cache checks one per read, and the PNG check one per chunk.
"""

from __future__ import annotations

try:
    from zlib_ng.zlib_ng import crc32
except ImportError:  # pragma: no cover - zlib-ng is a dependency; a bare environment still works
    from zlib import crc32

__all__ = ["crc32"]
