"""Decoded-frame cache: built once, read instead of the PNGs, the same arrays byte for byte."""

from __future__ import annotations

import os

import numpy as np
import pytest

from emulator.io.borealhdr import load_sequence, write_frame
from emulator.errors import DatasetError
from emulator.io.framecache import CACHE_DIRNAME, cached_frame_path, read_cached_frame
from emulator.orchestration.framecache import build_frame_cache


def _frames(seq):
    return [f for c in seq.cycles for cam in c.frames.values() for f in cam.values()]


@pytest.mark.slow
def test_sample_cache_reads_byte_identical_frames(sample_seq, tmp_path):
    cache = tmp_path / "frames"
    summary = build_frame_cache(sample_seq, cache)
    assert summary["frames"] == 34 and summary["written"] == 34 and summary["kept"] == 0
    assert 0 < summary["cache_bytes"] < 1.2 * summary["png_bytes"]
    plain = load_sequence(sample_seq, frame_cache=False)
    cached = load_sequence(sample_seq, frame_cache=cache)
    assert [f.cache_path for f in _frames(plain)] == [None] * 34
    for a, b in zip(_frames(plain), _frames(cached)):
        assert a == b and b.cache_path.is_file()  # same frame (the cache path is not compared)
        x, y = a.load(), b.load()
        assert x.dtype == y.dtype == np.uint16 and x.shape == y.shape and x.tobytes() == y.tobytes()
        assert y.flags.writeable and y.flags.owndata
    again = build_frame_cache(sample_seq, cache)
    assert again["written"] == 0 and again["kept"] == 34


def _tiny(tmp_path):
    root = tmp_path / "seq"
    rng = np.random.default_rng(0)
    for i, (ms, ts) in enumerate(((1.0, 1000), (2.0, 2000), (1.0, 3000), (2.0, 4000))):
        for cam in ("left", "right"):
            write_frame(root, cam, ms, ts, rng.integers(0, 4095, (8, 12), dtype=np.uint16))
    return root


def test_default_folder_stale_entries_and_errors(tmp_path):
    root = _tiny(tmp_path)
    summary = build_frame_cache(root)  # default: inside the recording
    assert summary["written"] == 8 and (root / CACHE_DIRNAME).is_dir()
    seq = load_sequence(root)  # found without being named, and not scanned as data
    frames = _frames(seq)
    assert len(frames) == 8 and all(f.cache_path is not None for f in frames)
    assert load_sequence(root, frame_cache=False)[0].frames["left"][1.0].cache_path is None
    # a PNG rewritten after the cache was built: its entry no longer matches, the PNG is read
    frame = seq[0].frames["left"][1.0]
    new = np.full((8, 12), 7, np.uint16)
    write_frame(root, "left", 1.0, 1000, new, overwrite=True)
    os.utime(frame.path, ns=(1, 1))
    fresh = load_sequence(root)[0].frames["left"][1.0]
    assert not fresh.cache_path.exists() and np.array_equal(fresh.load(), new)
    assert build_frame_cache(root)["removed"] == 1 and fresh.cache_path.is_file()
    assert np.array_equal(load_sequence(root)[0].frames["left"][1.0].load(), new)
    # a corrupt entry is an error naming the file when read directly; loading a frame never
    # uses it: the PNG is decoded and the entry written again (issue 24)
    entry = cached_frame_path(root / CACHE_DIRNAME, root, frame.path)
    entry.write_bytes(entry.read_bytes()[:40])
    with pytest.raises(DatasetError, match="corrupt|truncated"):
        read_cached_frame(entry)
    assert np.array_equal(load_sequence(root)[0].frames["left"][1.0].load(), new)
    assert np.array_equal(read_cached_frame(entry), new)
    # white level is checked as for the PNG
    good = cached_frame_path(root / CACHE_DIRNAME, root, seq[0].frames["right"][1.0].path)
    with pytest.raises(DatasetError, match="white_level"):
        read_cached_frame(good, white_level=10)
    assert read_cached_frame(tmp_path / "absent.npy.zst") is None
    with pytest.raises(DatasetError, match="not found"):
        load_sequence(root, frame_cache=tmp_path / "nowhere")


def test_cache_command_builds_then_keeps(tmp_path, capsys):
    """`exposim cache SEQ` writes one entry per PNG, and a second run keeps them all."""
    from emulator.commands.cli import main

    seq = _tiny(tmp_path)
    n_png = len(list(seq.rglob("*.png")))
    assert main(["cache", str(seq)]) == 0
    first = capsys.readouterr().out
    assert f"{n_png} frames ({n_png} written, 0 kept" in first
    assert main(["cache", str(seq)]) == 0
    assert f"(0 written, {n_png} kept" in capsys.readouterr().out
    assert len(list((seq / CACHE_DIRNAME).rglob("*.npy.zst"))) == n_png


def test_a_fast_level_reads_the_same_frames_from_larger_entries(tmp_path, capsys):
    """`exposim cache --level -1` (zstd's fast level): the same arrays, entries at least as large
    as level 3's; levels outside 1..22 and -1..-100 are refused in one line."""
    from emulator.commands.cli import main

    seq = _tiny(tmp_path)
    fast, packed = tmp_path / "fast", tmp_path / "packed"
    assert main(["cache", str(seq), "--frame-cache", str(fast), "--level", "-1", "-q"]) == 0
    assert main(["cache", str(seq), "--frame-cache", str(packed), "-q"]) == 0
    capsys.readouterr()
    a, b = load_sequence(seq, frame_cache=fast), load_sequence(seq, frame_cache=packed)
    plain = load_sequence(seq, frame_cache=False)
    for x, y, z in zip(_frames(a), _frames(b), _frames(plain)):
        assert x.load().tobytes() == y.load().tobytes() == z.load().tobytes()
        assert x.cache_path.stat().st_size >= y.cache_path.stat().st_size
    for bad in ("0", "23", "-101"):
        with pytest.raises(SystemExit, match=f"--level must be 1..22, or -1..-100 for zstd's fast levels, got {bad}"):
            main(["cache", str(seq), "--frame-cache", str(tmp_path / "x"), "--level", bad, "-q"])
