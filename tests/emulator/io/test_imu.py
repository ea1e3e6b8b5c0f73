"""The IMU reader: imu/imu.csv in folders and zips, one warning without one, malformed files named by line."""

from __future__ import annotations

import shutil
import warnings

import numpy as np
import pytest

from emulator.errors import DatasetError
from emulator.io.borealhdr import load_sequence
from emulator.io.imu import IMU_COLUMNS, ImuData, ImuMissingWarning, parse_imu, read_imu, write_imu

try:
    from tests.emulator.playback.test_playback import write_static_sequence
    from tests.emulator.io.test_zip import zip_folder
except ImportError:  # tests collected as a package
    from tests.test_playback import write_static_sequence
    from tests.test_zip import zip_folder

HEADER = ",".join(IMU_COLUMNS)


def test_sample_imu_units_and_rates(sample_seq):
    imu = read_imu(sample_seq)
    # 200 s at 100 Hz, timestamps in ns on the camera clock (first frame 1695668703271420672 ns)
    assert len(imu) == 19988 and imu.timestamp_ns.dtype == np.int64
    assert imu.timestamp_ns[0] == 1695668703096986112
    assert abs(imu.rate_hz - 100.0) < 0.1
    assert 199.8 < (imu.timestamp_ns[-1] - imu.timestamp_ns[0]) * 1e-9 < 199.9
    # gravity on +z (m/s^2): the accelerometer at rest reads ~9.8 in norm
    assert abs(np.median(np.linalg.norm(imu.acc_m_s2, axis=1)) - 9.81) < 0.1
    # the figures: median 10.7 deg/s, p90 18.2, p99 27.2
    d = imu.describe()["angular_speed_deg_s"]
    assert round(d["p50"], 1) == 10.7 and round(d["p90"], 1) == 18.2 and round(d["p99"], 1) == 27.2


def test_sequence_exposes_imu_in_folder_and_zip(sample_seq, tmp_path):
    folder = load_sequence(sample_seq)
    zp = zip_folder(sample_seq, tmp_path / "rec.zip", "data/backpack_2023-09-25-15-05-03")
    zipped = load_sequence(zp)
    assert folder.imu is not None and zipped.imu is not None
    np.testing.assert_array_equal(folder.imu.timestamp_ns, zipped.imu.timestamp_ns)
    np.testing.assert_array_equal(folder.imu.gyro_rad_s, zipped.imu.gyro_rad_s)
    assert str(zipped.imu.path).startswith(str(zp))


def test_missing_imu_warns_once_and_changes_nothing(tmp_path):
    seq_dir, _ = write_static_sequence(tmp_path / "seq", n_cycles=2, shape=(8, 8))
    with pytest.warns(ImuMissingWarning, match="no imu/imu.csv"):
        a = load_sequence(seq_dir)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ImuMissingWarning)
        b = load_sequence(seq_dir)  # said once: no second warning
    assert a.imu is None and b.imu is None and a.describe() == b.describe()


def test_write_read_round_trip(tmp_path):
    imu = ImuData(np.array([10, 20, 35], dtype=np.int64), np.arange(9.0).reshape(3, 3) / 7,
                  -np.arange(9.0).reshape(3, 3) / 3, np.array([11, 21, 36], dtype=np.int64))
    write_imu(tmp_path / "imu" / "imu.csv", imu)
    back = read_imu(tmp_path)
    for name in ("timestamp_ns", "ros_time_ns", "gyro_rad_s", "acc_m_s2"):
        np.testing.assert_array_equal(getattr(back, name), getattr(imu, name))


@pytest.mark.parametrize("body, line, match", [
    ("1,2,0.1,0.2,0.3,0,0,9.8\n1,3,0.1,0.2,0.3,0,0,9.8\n", 3, "not after the previous"),
    ("1,2,0.1,0.2,0.3,0,0\n", 2, "expected 8"),
    ("1.5,2,0.1,0.2,0.3,0,0,9.8\n", 2, "integer nanoseconds"),
    ("1,2,0.1,x,0.3,0,0,9.8\n", 2, "must be numbers"),
    ("1,2,0.1,nan,0.3,0,0,9.8\n", 2, "non-finite"),
])
def test_malformed_imu_names_file_and_line(tmp_path, body, line, match):
    seq_dir, _ = write_static_sequence(tmp_path / "seq", n_cycles=1, shape=(8, 8))
    (seq_dir / "imu").mkdir()
    (seq_dir / "imu" / "imu.csv").write_text(HEADER + "\n" + body)
    with pytest.raises(DatasetError, match=rf"imu\.csv: line {line}: .*{match}"):
        load_sequence(seq_dir)


def test_bad_header_and_empty(tmp_path):
    with pytest.raises(DatasetError, match="line 1: header must be"):
        parse_imu(b"t,gx\n1,2\n", "x/imu.csv")
    with pytest.raises(DatasetError, match="no IMU samples"):
        parse_imu(HEADER + "\n", "x/imu.csv")
