"""``exposim export``: EuRoC, TUM lists and ROS 2 bags of one method's images, read back."""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
import pytest
import yaml

from emulator.commands.cli import main
from emulator.core.gray import bayer_to_gray8
from emulator.io.camera_info import read_camera_info

try:
    from tests.emulator.metrics.test_metrics_vo import make_synthetic_run
except ImportError:  # tests collected as a package
    from tests.test_metrics_vo import make_synthetic_run


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return make_synthetic_run(tmp_path_factory.mktemp("export"), n_frames=3, methods=("fixed", "shim"))


def _cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _raw(run, side, ts):
    return cv2.imread(str(run["run"] / "fixed" / "images" / side / f"{ts}.png"), cv2.IMREAD_UNCHANGED)


def test_euroc_layout(run, tmp_path, capsys):
    out = tmp_path / "euroc"
    code, stdout, err = _cli(capsys, "export", str(run["run"]), "--method", "fixed", "--format", "euroc",
                             "-o", str(out), "--json")
    assert code == 0, err
    summary = json.loads(stdout)
    assert summary["n_images"] == 6 and summary["encodings"] == ["mono16"]
    K = read_camera_info(run["sequence"] / "calibration" / "left.yaml").K
    for cam, side in (("cam0", "left"), ("cam1", "right")):
        rows = (out / "mav0" / cam / "data.csv").read_text().splitlines()
        assert rows[0] == "#timestamp [ns],filename"
        assert [r.split(",") for r in rows[1:]] == [[str(t), f"{t}.png"] for t in run["stamps"]]
        for ts in run["stamps"]:
            got = cv2.imread(str(out / "mav0" / cam / "data" / f"{ts}.png"), cv2.IMREAD_UNCHANGED)
            assert got.dtype == np.uint16
            np.testing.assert_array_equal(got, cv2.cvtColor(_raw(run, side, ts), cv2.COLOR_BayerRG2GRAY))
        sensor = yaml.safe_load((out / "mav0" / cam / "sensor.yaml").read_text())
        assert sensor["intrinsics"] == [K[0, 0], K[1, 1], K[0, 2], K[1, 2]]
        assert sensor["resolution"] == [256, 192] and sensor["rate_hz"] == pytest.approx(1e9 / 274_000_000, rel=1e-5)  # 6 digits
    np.testing.assert_array_equal(read_camera_info(out / "calibration" / "left.yaml").K, K)


def test_tum_layout_mono8(run, tmp_path, capsys):
    out = tmp_path / "tum"
    code, _, err = _cli(capsys, "export", str(run["run"]), "--method", "fixed", "--format", "tum", "-o", str(out),
                        "--mono8")
    assert code == 0, err
    for side in ("left", "right"):
        lines = [ln for ln in (out / f"{side}.txt").read_text().splitlines() if not ln.startswith("#")]
        assert len(lines) == 3
        for line, ts in zip(lines, run["stamps"]):
            stamp, name = line.split()
            assert int(stamp.replace(".", "")) == ts and name == f"{side}/{stamp}.png"
            got = cv2.imread(str(out / name), cv2.IMREAD_UNCHANGED)
            assert got.dtype == np.uint8
            np.testing.assert_array_equal(got, bayer_to_gray8(_raw(run, side, ts), white_level=4095, black_level=0))


def test_rosbag2_read_back(run, tmp_path, capsys):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    out = tmp_path / "bag"
    code, _, err = _cli(capsys, "export", str(run["run"]), "--method", "fixed", "--format", "rosbag2", "-o", str(out))
    assert code == 0, err
    assert not list(tmp_path.glob(".*partial*"))
    store = get_typestore(Stores.ROS2_HUMBLE)
    K = read_camera_info(run["sequence"] / "calibration" / "left.yaml").K
    seen = {}
    with Reader(out) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == {
            "/cam0/image_raw": "sensor_msgs/msg/Image", "/cam1/image_raw": "sensor_msgs/msg/Image",
            "/cam0/camera_info": "sensor_msgs/msg/CameraInfo", "/cam1/camera_info": "sensor_msgs/msg/CameraInfo"}
        for conn, t_ns, raw in reader.messages():
            msg = store.deserialize_cdr(raw, conn.msgtype)
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            assert stamp == t_ns
            seen.setdefault(conn.topic, []).append(stamp)
            if conn.msgtype.endswith("CameraInfo"):
                np.testing.assert_array_equal(msg.k.reshape(3, 3), K)
                assert (msg.width, msg.height) == (256, 192)
                continue
            assert msg.encoding == "mono16" and msg.step == 2 * msg.width and msg.is_bigendian == 0
            img = np.frombuffer(msg.data.tobytes(), dtype="<u2").reshape(msg.height, msg.width)
            side = "left" if conn.topic.startswith("/cam0") else "right"
            np.testing.assert_array_equal(img, cv2.cvtColor(_raw(run, side, stamp), cv2.COLOR_BayerRG2GRAY))
    assert all(v == run["stamps"] for v in seen.values()) and len(seen) == 4


def test_never_overwrites_and_leaves_nothing_on_failure(run, tmp_path, capsys):
    out = tmp_path / "taken"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    code, _, err = _cli(capsys, "export", str(run["run"]), "--method", "fixed", "--format", "tum", "-o", str(out))
    assert code == 1 and "taken: exists" in err and err.count("\n") == 1
    assert [p.name for p in out.iterdir()] == ["keep.txt"]
    code, _, err = _cli(capsys, "export", str(run["run"]), "--method", "nope", "--format", "tum", "-o",
                        str(tmp_path / "x"))
    assert code == 1 and "nope" in err and not (tmp_path / "x").exists()
    broken = tmp_path / "broken_run"
    shutil.copytree(run["run"], broken)
    victim = broken / "fixed" / "images" / "right" / f"{run['stamps'][-1]}.png"
    victim.write_bytes(b"not a png")
    code, _, err = _cli(capsys, "export", str(broken), "--method", "fixed", "--format", "euroc", "-o",
                        str(tmp_path / "y"), "--no-calibration")
    assert code == 1 and victim.name in err
    assert not (tmp_path / "y").exists() and not list(tmp_path.glob(".y.partial*"))


@pytest.fixture(scope="module")
def sample_run(sample_seq, tmp_path_factory):
    out = tmp_path_factory.mktemp("export_sample") / "run"
    assert main(["run", str(sample_seq), "--methods", "shim", "--save", "png16", "-o", str(out), "-q"]) == 0
    return out


def test_export_writes_the_extrinsics_bench_vo_would_refine(sample_run, tmp_path, capsys):
    """On the shared sample the september_2023 files leave ~17 px of epipolar residual: export refines the
    pose with bench vo's code, writes it as the rectification (R, P) of both cameras and says so."""
    from emulator.io.export import EXPORT_FILE
    from emulator.io.runfolder import read_run_folder
    from emulator.metrics.stereo import load_stereo_calibration
    from emulator.metrics.vo_bench import check_extrinsics

    out = tmp_path / "tum"
    code, _, err = _cli(capsys, "export", str(sample_run), "--method", "shim", "--format", "tum", "-o", str(out))
    assert code == 0, err
    meta = json.loads((out / EXPORT_FILE).read_text())["calibration_written"]
    ext = meta["extrinsics"]
    assert meta["written"] == "refined" and meta["folder"].endswith("september_2023") and ext["refined"] is True
    before, after = ext["epipolar_residual_px"], ext["estimate"]["epipolar_residual_after_px"]
    assert before > ext["threshold_px"] == 1.0 and after < 1.0
    line = [ln for ln in err.splitlines() if ln.startswith("calibration: ")]
    assert len(line) == 1 and f"epipolar residual {before:.2f} px -> {after:.2f} px" in line[0]
    # the files read back as the refined pose, and the images fit them
    written = load_stereo_calibration(out / "calibration")
    np.testing.assert_allclose(written.R, np.array(ext["estimate"]["R"]), atol=1e-9)
    np.testing.assert_allclose(written.T, np.array(ext["estimate"]["T_m"]), atol=1e-9)
    given = load_stereo_calibration(meta["folder"])
    np.testing.assert_array_equal(written.left.K, given.left.K)
    np.testing.assert_array_equal(written.right.D, given.right.D)
    run = read_run_folder(sample_run, ["shim"])
    _, again = check_extrinsics(written, run.methods["shim"].frames, run)
    assert again["refined"] is False and again["epipolar_residual_px"] < 1.0


def test_export_as_given_when_asked(sample_run, tmp_path, capsys):
    from emulator.io.camera_info import format_camera_info
    from emulator.metrics.stereo import load_stereo_calibration

    out = tmp_path / "given"
    code, _, err = _cli(capsys, "export", str(sample_run), "--method", "shim", "--format", "tum", "-o", str(out),
                        "--refine-extrinsics", "0")
    assert code == 0, err
    meta = json.loads((out / "export.json").read_text())["calibration_written"]
    assert meta["written"] == "given" and "written as given (--refine-extrinsics 0: not checked)" in err
    given = load_stereo_calibration(meta["folder"])
    assert (out / "calibration" / "right.yaml").read_text() == format_camera_info(given.right)


def test_euroc_sensor_yaml_carries_the_written_stereo_pose(sample_run, tmp_path, capsys):
    """EuRoC's T_BS: identity for cam0 (the body frame is the left camera) and, for cam1, the right
    camera's pose in the left's frame from the extrinsics export wrote (refined on the sample): a
    front end reading only sensor.yaml gets the baseline, not two cameras at one point."""
    from emulator.metrics.stereo import load_stereo_calibration

    out = tmp_path / "euroc"
    code, _, err = _cli(capsys, "export", str(sample_run), "--method", "shim", "--format", "euroc", "-o", str(out))
    assert code == 0, err
    written = load_stereo_calibration(out / "calibration")
    t0 = np.array(yaml.safe_load((out / "mav0" / "cam0" / "sensor.yaml").read_text())["T_BS"]["data"]).reshape(4, 4)
    t1 = np.array(yaml.safe_load((out / "mav0" / "cam1" / "sensor.yaml").read_text())["T_BS"]["data"]).reshape(4, 4)
    np.testing.assert_array_equal(t0, np.eye(4))
    # X_left = T_BS(cam1) X_right inverts X_right = R X_left + T
    x_left = np.array([0.3, -0.2, 4.0])
    x_right = written.R @ x_left + written.T
    np.testing.assert_allclose(t1[:3, :3] @ x_right + t1[:3, 3], x_left, atol=1e-12)
    assert np.linalg.norm(t1[:3, 3]) == pytest.approx(written.baseline_m, rel=1e-12)
    assert 0.17 < written.baseline_m < 0.19 and t1[0, 3] > 0.17  # the right camera lies along +x of the left
    np.testing.assert_array_equal(t1[3], [0.0, 0.0, 0.0, 1.0])
