"""Stereo VO, calibration and RPE (emulator.metrics.vo, emulator.metrics.stereo, emulator.metrics.rpe).

The VO is checked on a short synthetic stereo sequence rendered here by ray casting a
textured box room (five planes with band-limited noise textures) from exact poses: a
stereo rig with a 0.18 m baseline walks 0.15 m per frame with a slow yaw and a lateral
sway.  Stated bound: every frame tracked, end-point error below 1 % of the path length,
per-frame rotation error below 0.1 deg, and the RPE through evo below 1 %.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from emulator.metrics import stereo as stereo_mod
from emulator.metrics import vo as vo_mod
from emulator.errors import CalibrationError, MetricsError, TrajectoryError
from emulator.io.camera_info import read_camera_info
from emulator.io.tum import write_tum
from emulator.metrics.rpe import rpe_by_length
from emulator.metrics.trajectory import associate, read_trajectory, trajectory_from_poses

from tests.conftest import SHARED as _SHARED, missing_shared  # noqa: E402

SHARED = _SHARED / "data" / "borealhdr_sample" / "calibration"

# --------------------------------------------------------------------------- synthetic scene

#: Planes n . X = h of the box room (camera axes: x right, y down, z forward), with the
#: two world axes that carry each plane's texture.
PLANES = [
    ((0, 0, 1), 12.0, (0, 1)),  # back wall
    ((1, 0, 0), -3.0, (2, 1)),  # left wall
    ((1, 0, 0), 3.0, (2, 1)),  # right wall
    ((0, 1, 0), 1.5, (0, 2)),  # floor
    ((0, 1, 0), -2.5, (0, 2)),  # ceiling
]
TEXEL_M = 0.02
BASELINE_M = 0.18
SIZE = (256, 192)
FOCAL_PX = 192.0
STEP_NS = 274_000_000
T0_NS = 1_700_000_000_000_000_000


def _texture(seed: int, size: int = 1024) -> np.ndarray:
    rng = np.random.default_rng(seed)
    tex = np.zeros((size, size), np.float32)
    for sigma, weight in ((1.5, 0.6), (4.0, 1.0), (10.0, 1.0)):
        noise = cv2.GaussianBlur(rng.standard_normal((size, size)).astype(np.float32), (0, 0), sigma)
        tex += weight * noise / noise.std()
    return np.clip(128 + 40 * tex, 0, 255).astype(np.float32)


_TEXTURES: list[np.ndarray] = []


def render(K: np.ndarray, T_wc: np.ndarray, size=SIZE) -> np.ndarray:
    """8-bit grey image of the box room seen by a pinhole camera at pose ``T_wc``."""
    if not _TEXTURES:
        _TEXTURES.extend(_texture(100 + i) for i in range(len(PLANES)))
    W, H = size
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    d = (np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(K).T) @ T_wc[:3, :3].T
    c = T_wc[:3, 3]
    best = np.full((H, W), np.inf)
    out = np.zeros((H, W), np.float32)
    for (n, h, (a, b)), tex in zip(PLANES, _TEXTURES):
        n = np.asarray(n, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (h - c @ n) / (d @ n)
        t[~np.isfinite(t) | (t <= 0)] = np.inf
        X = c + np.where(np.isfinite(t), t, 0)[..., None] * d
        half = tex.shape[0] / 2
        mx = (X[..., a] / TEXEL_M + half).astype(np.float32)
        my = (X[..., b] / TEXEL_M + half).astype(np.float32)
        img = cv2.remap(tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        sel = t < best
        out[sel] = img[sel]
        best[sel] = t[sel]
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def ground_truth(n: int) -> np.ndarray:
    """(n, 4, 4) camera-to-world poses: 0.15 m forward per frame, 1 deg yaw, sway."""
    poses = np.tile(np.eye(4), (n, 1, 1))
    for k in range(n):
        poses[k, :3, :3] = Rotation.from_euler("y", 1.0 * k, degrees=True).as_matrix()
        poses[k, :3, 3] = [0.2 * np.sin(0.5 * k), 0.02 * k, 0.15 * k]
    return poses


def intrinsics(size=SIZE) -> np.ndarray:
    return np.array([[FOCAL_PX, 0, size[0] / 2 - 0.5], [0, FOCAL_PX, size[1] / 2 - 0.5], [0, 0, 1.0]])


def write_camera_info(path: Path, K: np.ndarray, P: np.ndarray, size=SIZE) -> None:
    """A ROS camera_info YAML file, as the synthetic writer produces (no distortion)."""

    def block(name, rows, cols, values):
        data = ", ".join(f"{v:.10g}" for v in np.ravel(values))
        return f"{name}:\n  rows: {rows}\n  cols: {cols}\n  data: [{data}]\n"

    path.write_text(
        f"image_width: {size[0]}\nimage_height: {size[1]}\ncamera_name: synthetic\n"
        + block("camera_matrix", 3, 3, K)
        + "distortion_model: plumb_bob\n"
        + block("distortion_coefficients", 1, 5, np.zeros(5))
        + block("rectification_matrix", 3, 3, np.eye(3))
        + block("projection_matrix", 3, 4, P)
    )


def gray8_to_bayer12(gray8: np.ndarray) -> np.ndarray:
    """A grey scene as a 12-bit RGGB mosaic (every site holds the grey level)."""
    return np.rint(gray8.astype(np.float64) * 4095 / 255).astype(np.uint16)


def make_synthetic_run(root: Path, n_frames: int = 6, methods=("fixed",), right_pitch_deg: float = 0.0) -> dict:
    """Write a synthetic sequence (calibration, ground truth) and a run folder of it.

    Every method gets the same images.  ``right_pitch_deg`` tilts the right camera about
    its x axis while the calibration files keep claiming a parallel rig (the BorealHDR
    September 2023 situation).  Returns paths, timestamps and the ground truth.
    """
    seq = root / "sequence"
    (seq / "calibration").mkdir(parents=True)
    (seq / "ground_truth").mkdir()
    K = intrinsics()
    write_camera_info(seq / "calibration" / "left.yaml", K, np.c_[K, np.zeros(3)])
    write_camera_info(seq / "calibration" / "right.yaml", K, np.c_[K, [-FOCAL_PX * BASELINE_M, 0, 0]])
    poses = ground_truth(n_frames)
    stamps = [T0_NS + k * STEP_NS for k in range(n_frames)]
    write_tum(seq / "ground_truth" / "poses_left.txt", stamps, poses)
    run = root / "run"
    run.mkdir()
    (run / "run.json").write_text(json.dumps({
        "sequence": str(seq), "methods": list(methods), "selector": "higher_no_sat",
        "initial_ms": 4.0, "range_ms": [1.0, 32.0], "save": "png16", "white_level": 4095, "black_level": 0,
    }))
    images = []
    pitch = Rotation.from_euler("x", right_pitch_deg, degrees=True).as_matrix()
    for T in poses:
        T_right = T.copy()
        T_right[:3, 3] = T[:3, 3] + T[:3, :3] @ [BASELINE_M, 0, 0]
        T_right[:3, :3] = T[:3, :3] @ pitch
        images.append((render(K, T), render(K, T_right)))
    for m in methods:
        for side in ("left", "right"):
            (run / m / "images" / side).mkdir(parents=True)
        lines = []
        for ts, (left, right) in zip(stamps, images):
            cv2.imwrite(str(run / m / "images" / "left" / f"{ts}.png"), gray8_to_bayer12(left))
            cv2.imwrite(str(run / m / "images" / "right" / f"{ts}.png"), gray8_to_bayer12(right))
            lines.append(f"{ts} {ts / 1e9:.9f} 4.0")
        (run / m / "images" / "times.txt").write_text("\n".join(lines) + "\n")
        (run / m / "exposures.csv").write_text(
            "cycle,timestamp_ns,target_ms,bracket_ms,ratio,saturated_fraction,valid_fraction\n"
        )
    return {"run": run, "sequence": seq, "poses": poses, "stamps": stamps}


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    return make_synthetic_run(tmp_path_factory.mktemp("vo"), n_frames=6)


def _frames(run: Path, method: str = "fixed"):
    from emulator.metrics.features import load_gray8

    lefts = sorted((run / method / "images" / "left").glob("*.png"))
    for p in lefts:
        levels = dict(white_level=4095, black_level=0)  # make_synthetic_run scales grey to 0..4095
        yield (int(p.stem), load_gray8(p, **levels),
               load_gray8(run / method / "images" / "right" / p.name, **levels))


# --------------------------------------------------------------------------- calibration


def test_read_real_borealhdr_calibration():
    if not SHARED.is_dir():
        missing_shared("shared BorealHDR sample not available")
    left = read_camera_info(SHARED / "september_2023" / "left.yaml")
    assert (left.width, left.height) == (1920, 1200)
    assert left.K[0, 0] == pytest.approx(1180.80514)
    assert left.D[0] == pytest.approx(-0.219776)
    assert left.P[1, 2] == pytest.approx(580.01843)  # multi-line flow list with a trailing comma
    calib = stereo_mod.load_stereo_calibration(SHARED / "september_2023")
    assert calib.baseline_m == pytest.approx(180.0 / 1009.76978)
    np.testing.assert_allclose(calib.T, [-calib.baseline_m, 0, 0])
    april = stereo_mod.load_stereo_calibration(SHARED / "april_2023")  # comments, non-identity R
    assert abs(np.linalg.det(april.R) - 1) < 1e-6
    rect = stereo_mod.stereo_rectification(calib)
    assert rect.baseline_m == pytest.approx(calib.baseline_m)
    assert rect.K[0, 0] == rect.K[1, 1]
    with pytest.raises(CalibrationError, match="1920x1200"):
        calib.check_image_shape((240, 320), "img.png")


def test_calibration_errors(tmp_path):
    K = intrinsics()
    write_camera_info(tmp_path / "left.yaml", K, np.c_[K, np.zeros(3)])
    write_camera_info(tmp_path / "right.yaml", K, np.c_[K, np.zeros(3)])  # Tx = 0: no baseline
    with pytest.raises(CalibrationError, match="right.yaml.*Tx"):
        stereo_mod.load_stereo_calibration(tmp_path)
    text = (tmp_path / "left.yaml").read_text().replace("camera_matrix", "camera_matrx")
    (tmp_path / "left.yaml").write_text(text)
    with pytest.raises(CalibrationError, match="left.yaml: missing or malformed 'camera_matrix'"):
        read_camera_info(tmp_path / "left.yaml")
    with pytest.raises(CalibrationError, match="does not exist"):
        read_camera_info(tmp_path / "nope.yaml")
    with pytest.raises(CalibrationError, match="pass --calibration"):
        stereo_mod.find_calibration(tmp_path / "no_sequence")


# --------------------------------------------------------------------------- VO


def test_vo_recovers_synthetic_motion(synthetic):
    calib = stereo_mod.load_stereo_calibration(synthetic["sequence"] / "calibration")
    rect = stereo_mod.stereo_rectification(calib)
    result = vo_mod.run_stereo_vo(_frames(synthetic["run"]), rect)
    assert result.succeeded, result.failures
    assert result.tracked.all()
    gt = synthetic["poses"]
    gt_rel = np.linalg.inv(gt[0]) @ gt  # ground truth with the first frame at the origin
    path = np.sum(np.linalg.norm(np.diff(gt_rel[:, :3, 3], axis=0), axis=1))
    end_error = np.linalg.norm(result.poses[-1, :3, 3] - gt_rel[-1, :3, 3])
    assert end_error < 0.01 * path, (end_error, path)
    for k in range(1, len(gt)):
        d_est = np.linalg.inv(result.poses[k - 1]) @ result.poses[k]
        d_gt = np.linalg.inv(gt_rel[k - 1]) @ gt_rel[k]
        E = np.linalg.inv(d_gt) @ d_est
        angle = np.degrees(np.arccos(np.clip((np.trace(E[:3, :3]) - 1) / 2, -1, 1)))
        assert angle < 0.1, (k, angle)
        assert np.linalg.norm(E[:3, 3]) < 0.01, (k, E[:3, 3])  # 1 cm of a 0.15 m step
    assert (result.n_inliers[1:] >= 100).all()


def blank_frames(data: dict, root: Path, frames: tuple[int, ...]) -> dict:
    """A copy of a synthetic run whose ``frames`` are uniform grey (nothing to track)."""
    import shutil

    run = root / "run_blank"
    shutil.copytree(data["run"], run)
    for k in frames:
        for side in ("left", "right"):
            path = run / "fixed" / "images" / side / f"{data['stamps'][k]}.png"
            cv2.imwrite(str(path), np.full((SIZE[1], SIZE[0]), 2048, np.uint16))
    return {**data, "run": run}


def test_vo_failures_are_reported_with_constant_velocity(synthetic, tmp_path):
    import itertools

    data = blank_frames(synthetic, tmp_path, (2,))
    rect = stereo_mod.stereo_rectification(stereo_mod.load_stereo_calibration(data["sequence"] / "calibration"))
    result = vo_mod.run_stereo_vo(itertools.islice(_frames(data["run"]), 5), rect)
    assert not result.succeeded
    reasons = [(f.index, f.reason) for f in result.failures]
    assert reasons == [(2, "too_few_matches"), (3, "too_few_stereo_points")]
    assert result.failures[0].timestamp_ns == data["stamps"][2]
    assert result.tracked.tolist() == [True, True, False, False, True]
    # constant velocity: the failed frame 2 repeats the measured motion 0 -> 1
    step01 = np.linalg.inv(result.poses[0]) @ result.poses[1]
    step12 = np.linalg.inv(result.poses[1]) @ result.poses[2]
    np.testing.assert_allclose(step12, step01, atol=1e-12)
    # implausible jumps: every measured motion (0.15 m) exceeds a 1 cm limit
    strict = vo_mod.VOParameters(max_step_m=0.01)
    jumpy = vo_mod.run_stereo_vo(itertools.islice(_frames(synthetic["run"]), 3), rect, strict)
    assert [f.reason for f in jumpy.failures] == ["implausible_jump"] * 2
    assert (jumpy.poses == np.eye(4)).all()  # no accepted motion: constant velocity = identity


def test_uncalibrated_rig_rotation_is_detected_and_refined(tmp_path):
    import itertools

    data = make_synthetic_run(tmp_path, n_frames=2, right_pitch_deg=0.8)
    calib = stereo_mod.load_stereo_calibration(data["sequence"] / "calibration")
    plain = vo_mod.run_stereo_vo(_frames(data["run"]), stereo_mod.stereo_rectification(calib))
    assert [f.reason for f in plain.failures] == ["too_few_stereo_points"]
    assert "row offset" in plain.failures[0].detail  # about f * tan(0.8 deg) = 2.7 px
    assert abs(plain.row_offset_px[0]) > 2.0
    pairs = [(left, right) for _, left, right in itertools.islice(_frames(data["run"]), 2)]
    est = stereo_mod.estimate_stereo_extrinsics(calib, pairs)
    # X_r = R X_l + T with the right camera pitched by +0.8 deg about x: R = Rx(-0.8 deg)
    assert est.rotation_deg[0] == pytest.approx(-0.8, abs=0.05)
    assert abs(est.rotation_deg[1]) < 0.1 and abs(est.rotation_deg[2]) < 0.1  # 0.1 deg = 0.3 px here
    np.testing.assert_allclose(est.T / BASELINE_M, [-1, 0, 0], atol=0.03)
    refined = vo_mod.run_stereo_vo(_frames(data["run"]), stereo_mod.stereo_rectification(calib.with_extrinsics(est.R, est.T)))
    assert refined.succeeded and abs(refined.row_offset_px).max() < 0.5


def test_vo_parameters_are_validated():
    with pytest.raises(MetricsError, match="min_inliers"):
        vo_mod.VOParameters(min_inliers=3)
    with pytest.raises(MetricsError, match="disparity"):
        vo_mod.VOParameters(min_disparity_px=0)


# --------------------------------------------------------------------------- RPE


def test_tum_round_trip_keeps_nanoseconds(tmp_path):
    poses = ground_truth(4)
    stamps = [T0_NS + 1, T0_NS + 274_000_003, T0_NS + 548_000_000, T0_NS + 999_999_999]
    write_tum(tmp_path / "t.txt", stamps, poses)
    first = (tmp_path / "t.txt").read_text().split()[0]
    assert first == "1700000000.000000001"
    traj = read_trajectory(tmp_path / "t.txt")
    np.testing.assert_allclose(np.array(traj.poses_se3), poses, atol=1e-8)
    (tmp_path / "bad.txt").write_text("1 2 3\n")
    with pytest.raises(TrajectoryError, match="bad.txt"):
        read_trajectory(tmp_path / "bad.txt")


def test_rpe_by_length_scale_and_errors():
    n = 41
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 2, 3] = np.linspace(0, 4, n)  # straight line, 0.1 m steps
    stamps = [T0_NS + k * STEP_NS for k in range(n)]
    ref = trajectory_from_poses(stamps, poses)
    doubled = poses.copy()
    doubled[:, :3, 3] *= 2
    est = trajectory_from_poses(stamps, doubled)
    raw = rpe_by_length(ref, est, [1.0], align_scale=False)
    assert raw["scale"] == 1.0 and raw["path_length_m"] == pytest.approx(4.0)
    assert raw["deltas"][0]["trans_percent"]["median"] == pytest.approx(100.0)  # twice as far: error = length
    assert raw["deltas"][0]["trans_pct"] == raw["deltas"][0]["trans_percent"]  # the deprecated alias
    assert raw["deltas"][0]["rot_deg_per_m"]["max"] == 0.0
    pairs = raw["deltas"][0]["pairs"]  # every pair's errors, for intervals: the statistics are theirs
    assert len(pairs["trans_percent"]) == raw["deltas"][0]["n_pairs"] == len(pairs["first_index"])
    assert np.median(pairs["trans_percent"]) == raw["deltas"][0]["trans_percent"]["median"]
    assert all(b - a == 10 for a, b in zip(pairs["first_index"], pairs["second_index"]))  # 1 m of 0.1 m steps
    none = rpe_by_length(ref, est, [100.0], align_scale=False)
    assert none["deltas"][0]["n_pairs"] == 0 and none["deltas"][0]["trans_percent"] is None
    with pytest.raises(TrajectoryError, match="straight"):  # Umeyama needs a non-degenerate path
        rpe_by_length(ref, est, [1.0], align_scale=True)
    curved = ground_truth(n)
    ref = trajectory_from_poses(stamps, curved)
    doubled = curved.copy()
    doubled[:, :3, 3] *= 2
    aligned = rpe_by_length(ref, trajectory_from_poses(stamps, doubled), [0.5, 1.0], align_scale=True)
    assert aligned["scale"] == pytest.approx(0.5)
    for entry in aligned["deltas"]:
        assert entry["n_pairs"] > 0
        assert entry["trans_pct"]["max"] < 1e-9
        assert entry["rot_deg_per_m"]["max"] < 1e-6


def test_associate_without_overlap_is_a_clear_error():
    poses = np.tile(np.eye(4), (3, 1, 1))
    ref = trajectory_from_poses([T0_NS, T0_NS + STEP_NS, T0_NS + 2 * STEP_NS], poses)
    est = trajectory_from_poses([1_000, 2_000, 3_000], poses)
    with pytest.raises(TrajectoryError, match="no timestamps overlap"):
        associate(ref, est, max_diff_s=0.06, interpolate=True)


def test_bench_vo_on_synthetic_run(synthetic, tmp_path):
    from emulator.metrics.bench import bench_vo

    results = bench_vo(synthetic["run"], tmp_path / "out", deltas_m=[0.17, 0.35], max_frames=3)
    assert results["reference_source"].startswith("synthetic")
    m = results["methods"]["fixed"]
    assert m["status"] == "success" and m["n_tracked"] == 3
    assert m["rpe"]["n_associated"] == 3
    assert m["rpe"]["scale"] == pytest.approx(1.0, abs=0.01)
    for entry in m["rpe"]["deltas"]:
        assert entry["n_pairs"] > 0
        assert entry["trans_pct"]["median"] < 1.0
        assert entry["rot_deg_per_m"]["median"] < 0.5
    # each method's median RPE at each length with a block-bootstrap interval over segments of the run
    for k, iv in enumerate(results["rpe_intervals"]):
        assert iv["delta_m"] == m["rpe"]["deltas"][k]["delta_m"]
        for name, r in iv["methods"].items():
            assert r["estimate"] == results["methods"][name]["rpe"]["deltas"][k]["trans_percent"]["median"]
            assert r["ci95"] is None or r["ci95"][0] <= r["estimate"] <= r["ci95"][1]
    assert "Methods compared with 95 % intervals" in (tmp_path / "out" / "report.md").read_text()
    est = read_trajectory(tmp_path / "out" / "fixed.txt")
    assert est.num_poses == 3
    for name in ("results.json", "report.md", "fig6_rpe.png", "trajectories.png"):
        assert (tmp_path / "out" / name).is_file()
