import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from emulator import DatasetError
from emulator.io.borealhdr import exposure_folder_name, find_response, load_sequence, sequence_response, write_frame
from emulator.io.png import read_png16, write_png16
from emulator.errors import OutputExistsError


def test_real_sample_cycles_grouped_by_timestamp(sample_seq):
    seq = load_sequence(sample_seq)
    assert seq.cameras == ("left", "right")
    assert seq.brackets == (1.0, 2.0, 4.0, 8.0, 16.0, 32.0)
    assert seq.white_level == 4094 and seq.black_level == 0
    assert len(seq) == 4
    assert seq.partial_cycles == [0, 3]
    # cycle 0: recording starts mid-sweep; the right camera starts one shot... later (at 8 ms)
    assert sorted(seq[0].frames["left"]) == [2.0, 4.0, 8.0, 16.0, 32.0]
    assert sorted(seq[0].frames["right"]) == [8.0, 16.0, 32.0]
    assert seq[0].missing("right") == [1.0, 2.0, 4.0]
    assert seq[3].missing("left") == [2.0, 4.0, 8.0, 16.0, 32.0]
    for c in (1, 2):
        assert not seq[c].partial and seq[c].stereo_exposures() == list(seq.brackets)
    for cycle in seq:
        # every stereo pair shares one timestamp
        for b in cycle.stereo_exposures():
            assert cycle.frames["left"][b].timestamp_ns == cycle.frames["right"][b].timestamp_ns
        # a sweep increases in exposure and lasts less than one sweep period (~274 ms)
        ts = [f.timestamp_ns for _, f in sorted(cycle.frames["left"].items())]
        assert ts == sorted(ts)
        assert ts[-1] - ts[0] < 274e6
    # pairing by file index would pair the 2 ms images 274 ms apart; by timestamp they are equal
    left2 = sorted((sample_seq / "camera_left" / "2.0").iterdir())
    right2 = sorted((sample_seq / "camera_right" / "2.0").iterdir())
    by_index = int(right2[0].stem) - int(left2[0].stem)
    assert by_index == pytest.approx(274e6, rel=0.01)
    assert seq[1].frames["left"][2.0].timestamp_ns == seq[1].frames["right"][2.0].timestamp_ns == int(right2[0].stem)


def test_real_sample_decodes_lazily_and_checks_levels(sample_seq):
    seq = load_sequence(sample_seq)
    raw = seq[1].frames["left"][32.0].load()
    assert raw.dtype == np.uint16 and raw.shape == (1200, 1920)
    assert raw.max() == 4094
    r = sequence_response(seq)
    assert r.white_level == 4094 and r.black_level == 0
    assert find_response(sample_seq).name == "pcalib_inside1.txt"


def _make_seq(tmp_path, shots, cameras=("left", "right"), shape=(8, 8)):
    seq = tmp_path / "seq"
    for cam in cameras:
        for t, e in shots:
            write_frame(seq, cam, e, t, np.full(shape, int(e * 10), np.uint16))
    return seq


SWEEP = [1.0, 2.0, 4.0, 8.0, 16.0, 32.0]


def _shots(n_cycles, start=0, period_ns=45_500_000):
    shots = []
    i = 0
    for _ in range(n_cycles):
        for e in SWEEP:
            shots.append((1_000_000_000 + i * period_ns, e))
            i += 1
    return shots[start:]


def test_mid_sweep_start_and_dropped_bracket(tmp_path):
    shots = _shots(3, start=2)
    del shots[7]  # drop the 4 ms shot of the second full cycle
    seq = load_sequence(_make_seq(tmp_path, shots))
    assert len(seq) == 3
    assert sorted(seq[0].frames["left"]) == [4.0, 8.0, 16.0, 32.0]
    assert seq[1].missing("left") == [8.0] or seq[1].missing("left") == [4.0]
    assert not seq[2].partial
    assert any("cycle 1" in g for g in seq.gaps)


def test_dropped_whole_tail_and_head_split_by_time(tmp_path):
    # cycle A has only 1, 2 ms; the next recorded shots are 4..32 ms of the *following* sweep
    shots = _shots(3)
    kept = shots[:2] + shots[14:]
    seq = load_sequence(_make_seq(tmp_path, kept, cameras=("left",)))
    assert [sorted(c.frames["left"]) for c in seq] == [[1.0, 2.0], [4.0, 8.0, 16.0, 32.0]]
    assert any("no right camera" in g for g in seq.gaps)


def test_metadata_levels(tmp_path):
    seq_dir = _make_seq(tmp_path, _shots(1))
    (seq_dir / "exposim.json").write_text(json.dumps({"white_level": 4095, "black_level": 64}))
    seq = load_sequence(seq_dir)
    assert (seq.white_level, seq.black_level) == (4095, 64)
    (seq_dir / "exposim.json").write_text("{broken")
    with pytest.raises(DatasetError, match=r"exposim\.json: malformed JSON"):
        load_sequence(seq_dir)


def test_bad_layouts(tmp_path):
    seq_dir = _make_seq(tmp_path, _shots(1))
    (seq_dir / "camera_left" / "fast").mkdir()
    with pytest.raises(DatasetError, match=r"unknown folder name 'fast'"):
        load_sequence(seq_dir)
    shutil.rmtree(seq_dir / "camera_left" / "fast")
    (seq_dir / "camera_left" / "-2.0").mkdir()
    with pytest.raises(DatasetError, match="not a positive finite"):
        load_sequence(seq_dir)
    shutil.rmtree(seq_dir / "camera_left" / "-2.0")
    (seq_dir / "camera_left" / "8.0" / "notes.txt").write_text("x")
    with pytest.raises(DatasetError, match=r"notes\.txt: unexpected file name"):
        load_sequence(seq_dir)

    empty = tmp_path / "empty"
    (empty / "camera_left").mkdir(parents=True)
    with pytest.raises(DatasetError, match="camera_left: camera folder holds no images"):
        load_sequence(empty)
    nothing = tmp_path / "nothing"
    nothing.mkdir()
    with pytest.raises(DatasetError, match="no camera_left/ or camera_right/"):
        load_sequence(nothing)
    with pytest.raises(FileNotFoundError, match="not found"):
        load_sequence(tmp_path / "absent")


def test_conflicting_exposure_for_one_timestamp(tmp_path):
    seq_dir = _make_seq(tmp_path, _shots(1))
    src = next((seq_dir / "camera_right" / "8.0").iterdir())
    dst = seq_dir / "camera_right" / "16.0" / src.name
    src.rename(dst)
    with pytest.raises(DatasetError, match="filed under 16.0 ms here but 8.0 ms"):
        load_sequence(seq_dir)


def test_corrupt_and_8bit_png(tmp_path):
    seq_dir = _make_seq(tmp_path, _shots(1))
    seq = load_sequence(seq_dir)
    frame = seq[0].frames["left"][4.0]
    frame.path.write_bytes(frame.path.read_bytes()[:40])
    with pytest.raises(DatasetError, match=r"4\.0/\d+\.png: cannot decode image \(corrupt or truncated PNG"):
        frame.load()
    import cv2

    eight = seq[0].frames["left"][8.0]
    cv2.imwrite(str(eight.path), np.zeros((8, 8), np.uint8))
    with pytest.raises(DatasetError, match=r"expected a 16-bit PNG .*\(8-bit image\)"):
        eight.load()
    hot = seq[0].frames["left"][16.0]
    write_png16(hot.path, np.full((8, 8), 4095, np.uint16), overwrite=True)
    with pytest.raises(DatasetError, match="maximum DN 4095 exceeds the white level 4094.*--white-level 4095"):
        hot.load()
    with pytest.raises(FileNotFoundError):
        read_png16(tmp_path / "none.png")


def test_writer_is_atomic_and_refuses_overwrite(tmp_path, monkeypatch):
    p = write_frame(tmp_path / "s", "left", 8.0, 123, np.ones((4, 4), np.uint16))
    assert p == tmp_path / "s" / "camera_left" / "8.0" / "123.png"
    np.testing.assert_array_equal(read_png16(p), np.ones((4, 4)))
    with pytest.raises(OutputExistsError, match="123.png: exists"):
        write_frame(tmp_path / "s", "left", 8.0, 123, np.ones((4, 4), np.uint16))

    import emulator.io.files as files_io

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(files_io.os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        write_frame(tmp_path / "s", "left", 8.0, 456, np.ones((4, 4), np.uint16))
    assert sorted(x.name for x in (tmp_path / "s" / "camera_left" / "8.0").iterdir()) == ["123.png"]


def test_exposure_folder_names():
    assert exposure_folder_name(8) == "8.0"
    assert exposure_folder_name(0.5) == "0.5"
    assert exposure_folder_name(0.125) == "0.125"
    assert float(exposure_folder_name(1 / 3)) == 1 / 3
