"""emulator.io.crc: zlib-ng's CRC-32 gives zlib's values, so cache entries and PNG checks are unchanged."""

from __future__ import annotations

import zlib

import numpy as np
import pytest

from emulator.io import crc


@pytest.mark.parametrize("n", [0, 1, 7, 64, 4095, 65536 + 3, 4_608_000])
def test_crc32_equals_zlibs(n):
    data = np.random.default_rng(n).integers(0, 256, n, dtype=np.uint8)
    view = memoryview(data).cast("B")
    assert crc.crc32(view) == zlib.crc32(view)
    assert crc.crc32(view[n // 3:]) == zlib.crc32(view[n // 3:])  # a slice, as the PNG check reads chunks
    assert crc.crc32(bytes(view), 12345) == zlib.crc32(bytes(view), 12345)


def test_zlib_ngs_kernel_is_the_one_used_where_installed():
    zlib_ng = pytest.importorskip("zlib_ng.zlib_ng")
    assert crc.crc32 is zlib_ng.crc32


def test_an_entry_written_with_zlibs_crc_reads_back(tmp_path, monkeypatch):
    """Entries from before (zlib's crc32 in their header) stay valid: the value is the same."""
    from emulator.io import framecache

    img = np.random.default_rng(1).integers(0, 4096, (30, 40), dtype=np.uint16)
    path = tmp_path / "camera_left" / "1.0" / "123.45-67.npy.zst"
    path.parent.mkdir(parents=True)
    monkeypatch.setattr(framecache, "crc32", zlib.crc32)
    framecache.write_cached_frame(path, img)
    monkeypatch.undo()
    assert framecache.read_cached_frame(path).tobytes() == img.tobytes()
