"""Fault suite, issue 24 (caches): every cache entry carries its key and a checksum, verified on
read; a swapped, altered, truncated or NaN/negative entry is never used: it is rebuilt, by the
read that found it and by ``exposim cache``."""

from __future__ import annotations

import numpy as np
import pytest

from emulator.commands.cli import main
from emulator.io.borealhdr import load_sequence
from emulator.io.png import read_png16
from emulator.io.framecache import CACHE_DIRNAME, FrameCacheEntryError, cached_frame_path, read_cached_frame
from emulator.orchestration.framecache import build_frame_cache
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


# ------------------------------------------------------------------------------ render cache
def _store_two(tmp_path):
    from scenes.cache import KEY_ATTRIBUTE, canonical_json, store_entry

    rng = np.random.default_rng(0)
    out = {}
    for name in ("a", "b"):
        material = {"v": 2, "scene": name}
        img = rng.random((6, 8, 3), dtype=np.float32)
        path = store_entry(tmp_path / f"{name}.exr", img, {KEY_ATTRIBUTE: canonical_json(material)})
        out[name] = (path, material, img)
    return out


def test_render_cache_entries_carry_key_and_checksum(tmp_path):
    from scenes.cache import CacheEntryError, load_entry, store_entry

    e = _store_two(tmp_path)
    (pa, ma, ia), (pb, mb, ib) = e["a"], e["b"]
    assert np.array_equal(load_entry(pa, ma), ia)
    da, db = pa.read_bytes(), pb.read_bytes()
    pa.write_bytes(db)  # swapped
    pb.write_bytes(da)
    with pytest.raises(CacheEntryError, match="another render"):
        load_entry(pa, ma)
    # altered pixels under the right key: the checksum tells
    from emulator.io.exr import write_exr

    from scenes.cache import KEY_ATTRIBUTE, SHA_ATTRIBUTE, canonical_json, pixels_sha256

    write_exr(pa, ia * 2, overwrite=True, attributes={KEY_ATTRIBUTE: canonical_json(ma), SHA_ATTRIBUTE: pixels_sha256(ia)})
    with pytest.raises(CacheEntryError, match="checksum"):
        load_entry(pa, ma)
    for bad in (np.full_like(ia, np.nan), ia - 5.0):  # NaN, negative: refused as a fresh render is
        store_entry(pa, bad.astype(np.float32), {KEY_ATTRIBUTE: canonical_json(ma)})
        with pytest.raises(CacheEntryError, match="non-finite or negative"):
            load_entry(pa, ma)


@pytest.mark.render
def test_a_bad_render_cache_entry_is_rendered_again_and_replaced(tmp_path):
    import scenes
    from scenes.cache import load_entry

    scene = scenes.get_scene("static_lab", seed=0)
    pose = scene.default_pose()
    kw = dict(width=24, height=16, spp=2, seed=1, cache_dir=tmp_path, denoise="off")
    first = scenes.render(scene, pose, **kw)
    (entry,) = tmp_path.rglob("*.exr")
    good = entry.read_bytes()
    from scenes.cache import KEY_ATTRIBUTE, store_entry

    from emulator.io.exr import read_exr_attributes

    key = read_exr_attributes(entry)[KEY_ATTRIBUTE]
    store_entry(entry, np.full_like(first, -5.0), {KEY_ATTRIBUTE: key})  # a hit holding -5
    again = scenes.render(scene, pose, **kw)
    assert again.tobytes() == first.tobytes() and entry.read_bytes() == good
    assert load_entry(entry).tobytes() == first.tobytes()
