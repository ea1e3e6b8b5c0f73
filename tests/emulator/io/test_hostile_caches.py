"""Swapped and corrupted frame-cache and render-cache entries (issue 24), written
independently of tests/test_faults_*.py.

Outcome asserted: a run through a damaged frame cache gives the bytes of a run without a cache;
``exposim cache`` rebuilds what is bad; a damaged render-cache entry is never returned.
"""

from __future__ import annotations

import os
import re

import numpy as np
import pytest

from emulator.commands.cli import main
from test_playback import write_static_sequence

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
