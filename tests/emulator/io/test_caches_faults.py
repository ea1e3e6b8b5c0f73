"""Faults of the caches: a frame-cache or render-cache entry swapped, altered, truncated or corrupted is never used (two suites written independently, one after the other).

Fault suite, issue 24 (caches): every cache entry carries its key and a checksum, verified on
read; a swapped, altered, truncated or NaN/negative entry is never used: it is rebuilt, by the
read that found it and by ``exposim cache``.
"""

from __future__ import annotations

import numpy as np
import pytest

from emulator.commands.cli import main
from emulator.io.borealhdr import load_sequence
from emulator.io.png import read_png16
from emulator.io.framecache import CACHE_DIRNAME, FrameCacheEntryError, cached_frame_path, read_cached_frame
from emulator.orchestration.framecache import build_frame_cache
from tests.emulator.playback.test_playback import write_static_sequence
import os
import re


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


# ------------------------------------------------------------------------------------------------
# Swapped and corrupted frame-cache and render-cache entries (issue 24), written
# independently of the suite above.
#
# Outcome asserted: a run through a damaged frame cache gives the bytes of a run without a cache;
# ``exposim cache`` rebuilds what is bad; a damaged render-cache entry is never returned.
# ------------------------------------------------------------------------------------------------
METHODS = "classical-50,shim"


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("cseq") / "seq", n_cycles=4, shape=(32, 48))
    return root


def _outputs(run_dir):
    return {p.relative_to(run_dir).as_posix(): p.read_bytes() for p in sorted(run_dir.rglob("*"))
            if p.is_file() and p.suffix in (".csv", ".png") and p.name != "exposure.png"}


@pytest.fixture(scope="module")
def uncached(seq, tmp_path_factory):
    out = tmp_path_factory.mktemp("cbase") / "run"
    assert main(["run", str(seq), "--methods", METHODS, "-o", str(out), "--save", "png16", "-q"]) == 0
    return _outputs(out)


def _entries(cache, camera, bracket):
    return sorted((cache / f"camera_{camera}" / bracket).glob("*.zst"))


def _build(seq, cache, capsys):
    capsys.readouterr()
    assert main(["cache", str(seq), "--frame-cache", str(cache), "-q"]) == 0
    return capsys.readouterr()


def _swap(a, b):
    tmp = a.with_name("swap.tmp")
    os.replace(a, tmp)
    os.replace(b, a)
    os.replace(tmp, b)


def _damage_swap_brackets(cache):
    # every 4 ms entry of the left camera swapped with a 16 ms one (different pixels)
    for a, b in zip(_entries(cache, "left", "4.0"), _entries(cache, "left", "16.0")):
        _swap(a, b)


def _damage_swap_cameras(cache):
    for a, b in zip(_entries(cache, "left", "8.0"), _entries(cache, "right", "8.0")):
        _swap(a, b)


def _damage_truncate(cache):
    for p in _entries(cache, "left", "8.0"):
        p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])


def _damage_garbage(cache):
    for p in _entries(cache, "left", "8.0"):
        p.write_bytes(np.random.default_rng(0).integers(0, 256, p.stat().st_size, dtype=np.uint8).tobytes())


def _damage_empty(cache):
    for p in _entries(cache, "left", "8.0"):
        p.write_bytes(b"")


def _damage_symlink(cache):
    src = _entries(cache, "left", "16.0")[0]
    for p in _entries(cache, "left", "8.0"):
        p.unlink()
        p.symlink_to(src)


def _damage_flip_byte(cache):
    for p in _entries(cache, "left", "8.0"):
        data = bytearray(p.read_bytes())
        data[len(data) // 2] ^= 0x40
        p.write_bytes(bytes(data))


DAMAGES = [_damage_swap_brackets, _damage_swap_cameras, _damage_truncate, _damage_garbage, _damage_empty,
           _damage_symlink, _damage_flip_byte]


@pytest.mark.parametrize("damage", DAMAGES, ids=lambda f: f.__name__.replace("_damage_", ""))
def test_a_damaged_frame_cache_never_changes_a_run(seq, uncached, tmp_path, damage, capsys):
    cache = tmp_path / "fc"
    _build(seq, cache, capsys)
    damage(cache)
    out = tmp_path / "run"
    rc = main(["run", str(seq), "--methods", METHODS, "-o", str(out), "--save", "png16", "-q",
               "--frame-cache", str(cache)])
    err = capsys.readouterr().err
    if rc == 0:
        assert _outputs(out) == uncached
    else:  # refused: one line naming the bad entry
        lines = [x for x in err.strip().splitlines() if "warning" not in x]
        assert rc == 1 and len(lines) == 1 and str(cache) in lines[0], err


@pytest.mark.parametrize("damage", DAMAGES, ids=lambda f: f.__name__.replace("_damage_", ""))
def test_exposim_cache_rebuilds_bad_entries(seq, uncached, tmp_path, damage, capsys):
    cache = tmp_path / "fc"
    _build(seq, cache, capsys)
    damage(cache)
    report = _build(seq, cache, capsys).out
    m = re.search(r"(\d+) bad rebuilt", report)
    assert m and int(m.group(1)) > 0, report
    # after the rebuild the cache is whole: nothing bad left, and a run through it is exact
    again = _build(seq, cache, capsys).out
    assert re.search(r"\b0 bad rebuilt", again) and re.search(r"\b0 written", again), again
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", METHODS, "-o", str(out), "--save", "png16", "-q",
                 "--frame-cache", str(cache)]) == 0
    assert _outputs(out) == uncached
    # no symlink left pointing at another frame's entry
    assert not any(p.is_symlink() for p in cache.rglob("*.zst"))


def test_a_cache_of_another_recording_is_not_used(seq, uncached, tmp_path, capsys):
    other, _ = write_static_sequence(tmp_path / "other", n_cycles=4, shape=(32, 48), k=100.0)
    cache = tmp_path / "fc"
    _build(other, cache, capsys)
    out = tmp_path / "run"
    rc = main(["run", str(seq), "--methods", METHODS, "-o", str(out), "--save", "png16", "-q",
               "--frame-cache", str(cache)])
    if rc == 0:
        assert _outputs(out) == uncached


# ------------------------------------------------------------------ render cache
@pytest.fixture
def exr():
    pytest.importorskip("OpenEXR", reason="the render cache needs the synthetic extra (OpenEXR)")


def _material(i):
    return {"v": 1, "scene": {"name": f"s{i}"}, "width": 4, "height": 3}


def _radiance(i):
    return (np.arange(36, dtype=np.float32).reshape(3, 4, 3) + 10 * i).astype(np.float32)


@pytest.fixture
def two_entries(tmp_path, exr):
    from scenes.cache import KEY_ATTRIBUTE, canonical_json, store_entry

    paths = []
    for i in (1, 2):
        p = tmp_path / f"e{i}.exr"
        store_entry(p, _radiance(i), {KEY_ATTRIBUTE: canonical_json(_material(i))})
        paths.append(p)
    return paths


def test_render_cache_hit_is_exact(two_entries):
    from scenes.render import _read_cached

    got = _read_cached(two_entries[0], 4, 3, _material(1))
    assert got is not None and np.array_equal(got, _radiance(1))


def test_swapped_render_cache_entries_are_not_used(two_entries):
    from scenes.cache import CacheEntryError, load_entry
    from scenes.render import _read_cached

    a, b = two_entries
    _swap(a, b)
    assert _read_cached(a, 4, 3, _material(1)) is None and _read_cached(b, 4, 3, _material(2)) is None
    with pytest.raises(CacheEntryError, match=re.escape(str(a))):
        load_entry(a, _material(1))


@pytest.mark.parametrize("bad", [np.nan, -5.0, np.inf])
def test_a_render_cache_entry_holding_bad_values_is_not_used(tmp_path, bad, exr):
    from scenes.cache import KEY_ATTRIBUTE, canonical_json, store_entry
    from scenes.render import _read_cached

    p = tmp_path / "bad.exr"
    img = _radiance(1)
    img[1, 2, 0] = bad
    try:
        store_entry(p, img, {KEY_ATTRIBUTE: canonical_json(_material(1))})
    except Exception as exc:  # refused at write: equally safe
        assert type(exc).__module__.startswith(("emulator", "scenes")), exc
        return
    assert _read_cached(p, 4, 3, _material(1)) is None


def test_render_cache_entry_with_a_byte_flipped_or_truncated(two_entries):
    from scenes.render import _read_cached

    a, b = two_entries
    data = bytearray(a.read_bytes())
    data[-20] ^= 0x01
    a.write_bytes(bytes(data))
    b.write_bytes(b.read_bytes()[:-40])
    assert _read_cached(a, 4, 3, _material(1)) is None
    assert _read_cached(b, 4, 3, _material(2)) is None


def test_render_cache_entry_with_the_right_key_but_altered_pixels(tmp_path, exr):
    """Key attribute copied onto other pixels (written without the checksum attribute)."""
    from emulator.io.exr import write_exr
    from scenes.cache import KEY_ATTRIBUTE, SHA_ATTRIBUTE, canonical_json, pixels_sha256
    from scenes.render import _read_cached

    p = tmp_path / "forged.exr"
    write_exr(p, _radiance(2), overwrite=True,
              attributes={KEY_ATTRIBUTE: canonical_json(_material(1)), SHA_ATTRIBUTE: pixels_sha256(_radiance(1))})
    assert _read_cached(p, 4, 3, _material(1)) is None
