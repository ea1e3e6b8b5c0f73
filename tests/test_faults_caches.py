"""Fault suite, issue 24 (caches): every cache entry carries its key and a checksum, verified on
read; a swapped, altered, truncated or NaN/negative entry is never used: it is rebuilt, by the
read that found it and by ``exposim cache``."""

from __future__ import annotations

import numpy as np
import pytest

from emulator.cli import main
from emulator.io.borealhdr import load_sequence
from emulator.io.png import read_png16
from emulator.io.framecache import (CACHE_DIRNAME, FrameCacheEntryError, build_frame_cache, cached_frame_path,
                                    read_cached_frame)
from test_playback import write_static_sequence


@pytest.fixture
def cached(tmp_path):
    root, _ = write_static_sequence(tmp_path / "seq", n_cycles=2, shape=(32, 48))
    build_frame_cache(root)
    seq = load_sequence(root)
    frames = [f for c in seq.cycles for cam in c.frames.values() for f in cam.values()]
    truth = {f.path: read_png16(f.path) for f in frames}
    return root, frames, truth


def _entry(root, frame):
    return cached_frame_path(root / CACHE_DIRNAME, root, frame.path)


def test_swapped_frame_cache_entries_are_detected_and_rebuilt(cached, capsys):
    root, frames, truth = cached
    a, b = frames[0], frames[3]
    ea, eb = _entry(root, a), _entry(root, b)
    da, db = ea.read_bytes(), eb.read_bytes()
    ea.write_bytes(db)
    eb.write_bytes(da)
    with pytest.raises(FrameCacheEntryError, match="swapped"):
        read_cached_frame(ea)
    # a load never uses the swapped entry: the PNG's pixels, and the entry written again
    assert np.array_equal(a.load(), truth[a.path])
    assert np.array_equal(read_cached_frame(ea), truth[a.path])
    # exposim cache rebuilds the other one
    assert main(["cache", str(root)]) == 0
    out = capsys.readouterr().out
    assert "1 bad rebuilt" in out and f"{len(frames) - 1} kept" in out
    assert np.array_equal(read_cached_frame(eb), truth[b.path])
    assert main(["cache", str(root)]) == 0 and "0 bad rebuilt" in capsys.readouterr().out


@pytest.mark.parametrize("damage", ["flip-pixel", "truncate", "old-format"])
def test_altered_frame_cache_entries_are_rebuilt(cached, damage):
    import io

    import zstandard

    root, frames, truth = cached
    frame = frames[1]
    entry = _entry(root, frame)
    raw = zstandard.ZstdDecompressor().decompress(entry.read_bytes())
    if damage == "flip-pixel":  # valid zstd, same key, other pixels: only the checksum can tell
        data = bytearray(raw)
        data[-1] ^= 0x01
        entry.write_bytes(zstandard.ZstdCompressor().compress(bytes(data)))
    elif damage == "truncate":
        entry.write_bytes(entry.read_bytes()[: len(entry.read_bytes()) // 2])
    else:  # the format before keys and checksums
        buf = io.BytesIO()
        np.lib.format.write_array(buf, truth[frame.path])
        entry.write_bytes(zstandard.ZstdCompressor().compress(buf.getvalue()))
    with pytest.raises(FrameCacheEntryError):
        read_cached_frame(entry)
    assert np.array_equal(load_sequence(root).cycles[frame_cycle(frames, frame)].frames[frame.camera][frame.exposure_ms]
                          .load(), truth[frame.path])
    assert np.array_equal(read_cached_frame(entry), truth[frame.path])


def frame_cycle(frames, frame):
    seq = load_sequence(frame.path.parents[2])
    for c in seq.cycles:
        if frame.exposure_ms in c.frames.get(frame.camera, {}) and \
                c.frames[frame.camera][frame.exposure_ms].path == frame.path:
            return seq.cycles.index(c)
    raise AssertionError(frame.path)
