"""A BorealHDR trajectory zip read in place: same cycles and same run CSVs as the unpacked folder."""

from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path

import pytest

from emulator.commands.cli import main
from emulator.errors import DatasetError
from emulator.io.borealhdr import ZipSource, load_sequence, read_frame

try:
    from tests.emulator.playback.test_playback import write_static_sequence
except ImportError:  # tests collected as a package
    from tests.test_playback import write_static_sequence

METHODS = "classical-50,kim,zhang,shim,fixed"


def zip_folder(folder: Path, zip_path: Path, prefix: str, *, extra: dict[str, bytes] | None = None,
               compression=zipfile.ZIP_DEFLATED) -> Path:
    """Zip ``folder`` under ``prefix/`` (directory entries included), plus ``extra`` members."""
    with zipfile.ZipFile(zip_path, "w", compression=compression) as zf:
        for p in sorted(folder.rglob("*")):
            name = f"{prefix}/{p.relative_to(folder).as_posix()}" if prefix else p.relative_to(folder).as_posix()
            if p.is_dir():
                zf.writestr(name + "/", b"")
            else:
                zf.write(p, name)
        for name, data in (extra or {}).items():
            zf.writestr(name, data)
    return zip_path


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    """A static recording, its zip (prefix ``data/backpack_x/``, lidar and IMU beside the cameras) and the
    calibration beside the zip, as in the BorealHDR layout (``<root>/calibration/``)."""
    base = tmp_path_factory.mktemp("zip")
    seq, _ = write_static_sequence(base / "seq", n_cycles=5, shape=(32, 48))
    root = base / "dataset"
    root.mkdir()
    shutil.copytree(seq / "calibration", root / "calibration")
    zp = zip_folder(seq, root / "backpack_x.zip", "data/backpack_x",
                    extra={"data/backpack_x/lidar/x.bin": b"\x00" * 64, "data/backpack_x/imu.csv": b"t,ax\n0,1\n",
                           "__MACOSX/data/backpack_x/camera_left/._x": b"junk", "README.txt": b"hello"})
    return seq, zp


def test_zip_scan_equals_folder_scan(synthetic):
    seq, zp = synthetic
    a, b = load_sequence(seq), load_sequence(zp)
    assert b.path == zp
    da, db = a.describe(), b.describe()
    da.pop("path"), db.pop("path")
    assert da == db and len(b) == 5 and b.white_level == 4095  # exposim.json read from inside the zip
    left_a = sorted((f.path.relative_to(seq), f) for f in _frames(a))
    left_b = sorted((f.path.relative_to(zp), f) for f in _frames(b))
    assert [p for p, _ in left_a] == [p for p, _ in left_b] and len(left_a) == 5 * 6 * 2
    for (_, fa), (_, fb) in zip(left_a, left_b):
        assert (read_frame(fa) == read_frame(fb)).all()


def _frames(seq):
    out = []
    for c in seq.cycles:
        for cam_frames in c.frames.values():
            out.extend(cam_frames.values())
    return out


def test_zip_run_csvs_equal_folder_run(synthetic, tmp_path):
    seq, zp = synthetic
    assert main(["run", str(seq), "--methods", METHODS, "-o", str(tmp_path / "a"), "--no-progress"]) == 0
    assert main(["run", str(zp), "--methods", METHODS, "-o", str(tmp_path / "b"), "--no-progress"]) == 0
    for m in METHODS.split(","):
        a = (tmp_path / "a" / m / "exposures.csv").read_bytes()
        assert a.count(b"\n") == 6 and a == (tmp_path / "b" / m / "exposures.csv").read_bytes()
    assert json.loads((tmp_path / "b" / "run.json").read_text())["sequence"] == str(zp.resolve())


def test_zip_of_the_shared_sample(sample_seq, pcalib_path, tmp_path):
    zp = zip_folder(sample_seq, tmp_path / f"{sample_seq.name}.zip", sample_seq.name,
                    compression=zipfile.ZIP_STORED)  # the sample's own imu/imu.csv goes in and is read
    a, b = load_sequence(sample_seq).describe(), load_sequence(zp).describe()
    a.pop("path"), b.pop("path")
    assert a == b and len(a["cycles"]) == 4
    args = ["--methods", "classical-50,zhang", "--response", str(pcalib_path), "--no-progress"]
    assert main(["run", str(sample_seq), "-o", str(tmp_path / "a"), *args]) == 0
    assert main(["run", str(zp), "-o", str(tmp_path / "b"), *args]) == 0
    for m in ("classical-50", "zhang"):
        a = (tmp_path / "a" / m / "exposures.csv").read_bytes()
        assert a.count(b"\n") == 5 and a == (tmp_path / "b" / m / "exposures.csv").read_bytes()


def test_zip_errors_name_the_zip(synthetic, tmp_path, capsys):
    seq, _ = synthetic
    two = tmp_path / "two.zip"
    with zipfile.ZipFile(two, "w") as zf:
        zf.writestr("a/camera_left/8.0/1.png", b"x")
        zf.writestr("b/camera_right/8.0/1.png", b"x")
    with pytest.raises(DatasetError, match=r"two\.zip: the zip holds 2 recordings \(a/, b/\)"):
        load_sequence(two)
    none = tmp_path / "none.zip"
    with zipfile.ZipFile(none, "w") as zf:
        zf.writestr("lidar/x.bin", b"x")
    with pytest.raises(DatasetError, match=r"none\.zip: the zip holds no camera_left/ or camera_right/"):
        ZipSource(none)
    corrupt = tmp_path / "corrupt.zip"
    corrupt.write_bytes(b"PK\x03\x04 not really a zip" * 10)
    for path, what in ((corrupt, "not a readable zip archive"), (two, "2 recordings")):
        assert main(["info", str(path)]) == 1
        err = capsys.readouterr().err.strip()
        assert str(path) in err and what in err and "\n" not in err
    # a damaged member (CRC mismatch) is a one-line error naming the member
    good = zip_folder(seq, tmp_path / "damaged.zip", "", compression=zipfile.ZIP_STORED)
    data = bytearray(good.read_bytes())
    with zipfile.ZipFile(good) as zf:
        info = next(i for i in zf.infolist() if i.filename.endswith(".png"))
    start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
    data[start + 100] ^= 0xFF
    good.write_bytes(bytes(data))
    s = load_sequence(good)
    bad = next(f for f in _frames(s) if f.path.as_posix().endswith(info.filename))
    with pytest.raises(DatasetError, match=r"damaged\.zip.*corrupt member"):
        read_frame(bad)
