"""Recording faults found by trying bad input (issue 11): a PNG of another size, one shot
filed twice (folders ``8`` and ``8.0``); refused by the scan, by ``info``, ``run`` and
``emulate``, naming the file(s)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from emulator.commands.cli import main
from emulator.errors import DatasetError
from emulator.io.borealhdr import load_sequence, png_size
from emulator.io.png import encode_png, write_png16
from emulator.playback import iter_run
from tests.emulator.playback.test_playback import write_static_sequence

SHAPE = (16, 24)  # rows, columns


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("ds") / "seq", n_cycles=3, shape=SHAPE)
    return root


@pytest.fixture
def seq(pristine, tmp_path):
    root = tmp_path / "seq"
    shutil.copytree(pristine, root)
    return root


def _one_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_png_size_reads_the_ihdr_chunk():
    for h, w in ((16, 24), (1200, 1920), (1000, 1600), (1, 70000)):
        data = encode_png(np.zeros((h, w), np.uint16))
        assert png_size(data[:24]) == (w, h)
    assert png_size(b"GIF89a" + bytes(18)) is None
    assert png_size(encode_png(np.zeros((4, 4), np.uint16))[:23]) is None  # too short


@pytest.mark.parametrize("camera", ["left", "right"])
def test_png_of_another_size_is_refused_naming_it(seq, tmp_path, capsys, camera):
    odd = sorted((seq / f"camera_{camera}" / "8.0").iterdir())[1]
    write_png16(odd, np.full((SHAPE[0] + 4, SHAPE[1] - 4), 100, np.uint16), overwrite=True)
    with pytest.raises(DatasetError) as err:
        load_sequence(seq)
    msg = str(err.value)
    assert msg.startswith(f"{odd}: image is {SHAPE[1] - 4}x{SHAPE[0] + 4} pixels")
    assert f"are {SHAPE[1]}x{SHAPE[0]}" in msg and "one size" in msg
    for argv in (["info", str(seq)],
                 ["run", str(seq), "--methods", "classical-50", "-o", str(tmp_path / "run"), "--no-progress"],
                 ["emulate", str(seq), "--exposure-ms", "5", "--cycle", "0", "-o", str(tmp_path / "em")]):
        assert main(argv) == 1
        assert str(odd) in _one_line(capsys.readouterr().err)
    assert not (tmp_path / "run").exists() and not (tmp_path / "em").exists()


def test_stereo_pair_of_two_sizes_names_the_odd_camera(seq):
    """A whole right camera at another size (1600x1000 vs 1920x1200 in the fault report, scaled down)."""
    rights = sorted((seq / "camera_right").rglob("*.png"))
    for p in rights[:-1]:  # the majority is still the left size (18 left + 1 right)
        write_png16(p, np.zeros((10, 16), np.uint16), overwrite=True)
    with pytest.raises(DatasetError, match=r"camera_right/.*: image is 16x10 pixels, but 19 other image\(s\) "
                                           r".* are 24x16 .*; 16 more image\(s\) differ"):
        load_sequence(seq)


def test_a_file_replaced_after_the_scan_is_refused_when_decoded(seq):
    loaded = load_sequence(seq)
    frame = loaded[0].frames["right"][4.0]  # selected in cycle 0 (closest to 4 ms)
    write_png16(frame.path, np.zeros((SHAPE[0], SHAPE[1] + 2), np.uint16), overwrite=True)
    with pytest.raises(DatasetError, match=rf"{frame.path}: image is {SHAPE[1] + 2}x{SHAPE[0]} pixels, but .* "
                                           rf"is {SHAPE[1]}x{SHAPE[0]}"):
        for _ in iter_run(loaded, "classical-50,fixed", initial_ms=4.0, selector="closest", emulate_right=True):
            pass


def test_same_shot_in_folders_8_and_8_0_is_refused_naming_both(seq, capsys):
    src = sorted((seq / "camera_left" / "8.0").iterdir())[0]
    (seq / "camera_left" / "8").mkdir()
    copy = seq / "camera_left" / "8" / src.name
    shutil.copy(src, copy)
    with pytest.raises(DatasetError) as err:
        load_sequence(seq)
    msg = str(err.value)
    assert str(src) in msg and str(copy) in msg and "remove one copy" in msg
    assert main(["info", str(seq)]) == 1
    line = _one_line(capsys.readouterr().err)
    assert str(src) in line and str(copy) in line
    # the same in the right camera, with a different folder spelling
    copy.unlink()
    (seq / "camera_left" / "8").rmdir()
    rsrc = sorted((seq / "camera_right" / "16.0").iterdir())[-1]
    (seq / "camera_right" / "16.000").mkdir()
    shutil.copy(rsrc, seq / "camera_right" / "16.000" / rsrc.name)
    with pytest.raises(DatasetError, match=r"same right shot"):
        load_sequence(seq)
