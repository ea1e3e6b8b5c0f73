"""synth.capture_sequence: bracket-cycle capture and the ground-truth writer (issue 3)."""

from __future__ import annotations

import hashlib
import json
import math
import os
import stat
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

import synth
from synth.errors import SynthError
import synth.sequence
from emulator.core.emulate import emulate
from emulator.io.borealhdr import exposure_folder_name, load_sequence, sequence_response
from emulator.io.png import read_png16
from emulator.errors import OutputExistsError
from emulator.io.exr import read_exr
from emulator.io.files import atomic_write_bytes, make_staging_dir
from synth import Camera, capture_sequence, shot_schedule
from synth.dataset import MANIFEST_FILE, foreign_files
from synth.errors import PoseError, RadianceError, SourceError, SynthError
from synth.procedural import TranslatingChart

H, W = 48, 64
GT_MS = (3.0, 20.0)


@pytest.fixture(scope="module")
def camera() -> Camera:
    return Camera.preset("borealhdr", width=W, height=H)


@pytest.fixture(scope="module")
def chart(camera) -> TranslatingChart:
    return TranslatingChart(W, H, seed=2, duration_s=1.0, fov_x_deg=camera.fov_x_deg, dynamic_range_db=80.0)


@pytest.fixture(scope="module")
def noiseless_dataset(tmp_path_factory, camera, chart) -> Path:
    out = tmp_path_factory.mktemp("synth") / "seq"
    return capture_sequence(chart, out, camera, n_cycles=2, start_bracket_index=2, noise=False,
                            gt_exposures_ms=GT_MS, gt_captures="both", save_radiance=True, seed=4)


def _hashes(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def _read_tum(path: Path) -> tuple[list[str], np.ndarray]:
    rows = [line.split() for line in path.read_text().splitlines()]
    return [r[0] for r in rows], np.array([[float(v) for v in r[1:]] for r in rows])


# ---------------------------------------------------------------------------- schedule
def test_shot_schedule():
    shots = shot_schedule(9, start_bracket_index=4, start_time_ns=1_000)
    assert [s.exposure_ms for s in shots] == [16.0, 32.0, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 1.0]
    assert [s.cycle for s in shots] == [0, 0, 1, 1, 1, 1, 1, 1, 2]
    assert [s.timestamp_ns for s in shots[:3]] == [1_000, 1_000 + 45_454_545, 1_000 + 90_909_091]
    assert shots[2].time_s == pytest.approx(2 / 22.0)
    assert len({s.timestamp_ns for s in shots}) == 9  # every shot has its own timestamp
    with pytest.raises(SynthError, match="exceeds the frame period"):
        shot_schedule(3, fps=40.0)
    with pytest.raises(SynthError, match="strictly increasing"):
        shot_schedule(3, brackets_ms=(1.0, 4.0, 2.0))
    with pytest.raises(SynthError, match="start_bracket_index"):
        shot_schedule(3, start_bracket_index=6)


# ---------------------------------------------------------------------------- round trip
def test_dataset_loads_with_the_right_cycles_timestamps_and_exposures(noiseless_dataset, camera):
    seq = load_sequence(noiseless_dataset)
    shots = shot_schedule(10, start_bracket_index=2)
    assert seq.cameras == ("left", "right")
    assert seq.brackets == synth.BRACKETS_MS
    assert (seq.white_level, seq.black_level) == (camera.white_level, camera.black_level)
    assert len(seq) == 2
    assert seq[0].missing("left") == [1.0, 2.0] and not seq[1].partial  # started mid-sweep
    for cam in ("left", "right"):
        got = sorted((f.timestamp_ns, f.exposure_ms) for c in seq for f in c.frames[cam].values())
        assert got == [(s.timestamp_ns, s.exposure_ms) for s in shots]
    for c in seq:
        for e in c.stereo_exposures():
            assert c.frames["left"][e].timestamp_ns == c.frames["right"][e].timestamp_ns
    assert all("ground_truth" not in str(f.path) for c in seq for cam in c.frames.values() for f in cam.values())


def test_emulating_with_the_true_response_reproduces_the_noiseless_ground_truth(noiseless_dataset, camera):
    """Per pixel: GT lies in the exact quantisation interval of the source DN, and the
    emulated DN is within max(hi - mid, mid - lo) + 1 of it (the core emulator's bound)."""
    seq = load_sequence(noiseless_dataset)
    response = sequence_response(seq)
    np.testing.assert_array_equal(response.g, camera.response.g)  # the exact response travels
    f, g = response.forward, response.inverse
    top = float(response.white_level)
    checked = 0
    for c in seq:
        for bracket, frame in c.frames["left"].items():
            raw = frame.load()
            for t in GT_MS + (bracket,):
                folder = "captures_noiseless"
                if t == bracket:
                    np.testing.assert_array_equal(emulate(raw, bracket, t, response), raw)
                    continue
                gt = read_png16(noiseless_dataset / "ground_truth" / folder / "camera_left"
                                / exposure_folder_name(t) / f"{frame.timestamp_ns}.png").astype(np.float64)
                k = t / bracket
                emu, valid = emulate(raw, bracket, t, response, return_mask=True)
                d = raw.astype(np.float64)
                lo_c = f(k * g(np.clip(d - 0.5, 0, top)))  # the source DN's exposure interval, scaled
                hi_c = f(k * g(np.clip(d + 0.5, 0, top)))
                levels = (response.black_level, response.white_level)
                lo, hi = np.clip(np.floor(lo_c + 0.5), *levels), np.clip(np.floor(hi_c + 0.5), *levels)
                assert ((gt >= lo) & (gt <= hi))[valid].all(), (bracket, t)
                mid = f(k * response.g[raw])
                bound = np.maximum(hi_c - mid, mid - lo_c) + 1
                err = np.abs(emu.astype(np.float64) - gt)
                assert (err[valid] <= bound[valid]).all(), (bracket, t)
                checked += int(valid.sum())
    assert checked > 10 * H * W


def test_ground_truth_layout(noiseless_dataset, camera, chart):
    root = noiseless_dataset
    meta = json.loads((root / "exposim.json").read_text())
    assert meta["white_level"] == 4094 and meta["brackets_ms"] == list(synth.BRACKETS_MS)
    assert meta["fps"] == 22.0 and meta["baseline_m"] == 0.18 and meta["seed"] == 4
    assert meta["camera"] == json.loads(json.dumps(camera.to_dict()))
    assert meta["source"]["type"] == "synth.procedural.TranslatingChart"
    assert meta["generator"]["version"]
    shots = shot_schedule(10, start_bracket_index=2)
    names = [f"{s.timestamp_ns // 10**9}.{s.timestamp_ns % 10**9:09d}" for s in shots]
    poses = {}
    for side in ("left", "right"):
        stamps, values = _read_tum(root / "ground_truth" / f"poses_{side}.txt")
        assert stamps == names
        poses[side] = values
        for s, (tx, ty, tz, qx, qy, qz, qw) in zip(shots, values):
            expected = chart.pose(s.time_s, side)
            assert (tx, ty, tz) == pytest.approx(tuple(expected[:3, 3]), abs=1e-9)
            assert (qx, qy, qz, qw) == pytest.approx((0, 0, 0, 1), abs=1e-9)
        for kind in ("captures_noiseless", "captures_noisy"):
            for t in GT_MS:
                files = sorted((root / "ground_truth" / kind / f"camera_{side}" / exposure_folder_name(t)).iterdir())
                assert sorted(int(p.stem) for p in files) == sorted(s.timestamp_ns for s in shots)
        exr = sorted((root / "ground_truth" / "radiance" / f"camera_{side}").glob("*.exr"))
        assert len(exr) == len(shots)
        s = shots[3]
        radiance = read_exr(root / "ground_truth" / "radiance" / f"camera_{side}" / f"{s.timestamp_ns}.exr")
        np.testing.assert_array_equal(radiance, chart(s.time_s, side)[0])
    np.testing.assert_allclose(poses["right"][:, 0] - poses["left"][:, 0], 0.18, atol=1e-9)

    left = yaml.safe_load((root / "calibration" / "left.yaml").read_text())
    right = yaml.safe_load((root / "calibration" / "right.yaml").read_text())
    k = camera.intrinsics()
    np.testing.assert_allclose(np.reshape(left["camera_matrix"]["data"], (3, 3)), k)
    p = np.reshape(right["projection_matrix"]["data"], (3, 4))
    assert p[0, 3] == pytest.approx(-k[0, 0] * 0.18) and left["projection_matrix"]["data"][3] == 0.0
    assert right["distortion_coefficients"]["data"] == [0.0] * 5
    assert (right["image_width"], right["image_height"]) == (W, H)


def test_load_camera_rebuilds_the_camera(noiseless_dataset, camera):
    again = synth.load_camera(noiseless_dataset)
    assert again.to_dict() == camera.to_dict()
    np.testing.assert_array_equal(again.response.g, camera.response.g)


def test_noisy_ground_truth_is_independent_of_the_brackets(noiseless_dataset):
    root = noiseless_dataset / "ground_truth"
    clean = sorted((root / "captures_noiseless" / "camera_left" / "20.0").iterdir())
    noisy = sorted((root / "captures_noisy" / "camera_left" / "20.0").iterdir())
    assert [p.name for p in clean] == [p.name for p in noisy]
    assert any(a.read_bytes() != b.read_bytes() for a, b in zip(clean, noisy))


# ---------------------------------------------------------------------------- determinism, overwrite, atomicity
def test_same_seed_gives_identical_files(tmp_path, camera, chart):
    kw = dict(n_shots=7, gt_exposures_ms=(5.0,), gt_captures="noisy", save_radiance=True, seed=9)
    a = _hashes(capture_sequence(chart, tmp_path / "a", camera, **kw))
    b = _hashes(capture_sequence(chart, tmp_path / "b", camera, **kw))
    # 7 shots x 2 cameras x (bracket, ground truth, radiance), 6 description files, the manifest
    assert a == b and len(a) == 7 * 2 * 3 + 6 + 1
    c = _hashes(capture_sequence(chart, tmp_path / "c", camera, **{**kw, "seed": 10}))
    differs = [k for k in a if k.startswith("camera_") and a[k] != c[k]]
    assert len(differs) == 14


def test_ground_truth_of_the_left_camera_only_leaves_the_rest_identical(tmp_path, camera, chart):
    kw = dict(n_shots=4, gt_exposures_ms=(5.0, 20.0), gt_captures="noisy", seed=3)
    both = _hashes(capture_sequence(chart, tmp_path / "both", camera, **kw))
    left = _hashes(capture_sequence(chart, tmp_path / "left", camera, gt_cameras=("left",), **kw))
    dropped = sorted(k for k in both if k not in left)
    assert len(dropped) == 4 * 2 and all(k.startswith("ground_truth/captures_noisy/camera_right/") for k in dropped)
    assert {k: left[k] for k in left if k.startswith(("camera_", "ground_truth/captures"))} == {
        k: both[k] for k in left if k.startswith(("camera_", "ground_truth/captures"))}  # same bytes, same seeds
    assert json.loads((tmp_path / "left" / "exposim.json").read_text())["gt_cameras"] == ["left"]
    assert json.loads((tmp_path / "both" / "exposim.json").read_text())["gt_cameras"] == ["left", "right"]
    for bad in ((), ("centre",), ("right",)):
        target = tmp_path / f"bad-{len(list(tmp_path.iterdir()))}"
        if bad == ("right",):  # a mono recording has no right camera
            with pytest.raises(SynthError, match=r"gt_cameras must name some of the recorded cameras \(left\)"):
                capture_sequence(chart, target, camera, stereo=False, gt_cameras=bad, **kw)
        else:
            with pytest.raises(SynthError, match="gt_cameras must name some of the recorded cameras"):
                capture_sequence(chart, target, camera, gt_cameras=bad, **kw)
        assert not target.exists()


def test_existing_dataset_is_not_overwritten_unless_asked(tmp_path, camera, chart):
    out = capture_sequence(chart, tmp_path / "seq", camera, n_shots=2, stereo=False)
    before = _hashes(out)
    with pytest.raises(OutputExistsError, match="refusing to overwrite"):
        capture_sequence(chart, out, camera, n_shots=3, stereo=False)
    assert _hashes(out) == before
    capture_sequence(chart, out, camera, n_shots=3, stereo=False, overwrite=True)
    assert len(list((out / "camera_left").rglob("*.png"))) == 3  # replaced, no stale shot
    other = tmp_path / "notes"
    other.mkdir()
    (other / "thesis.txt").write_text("keep me")
    with pytest.raises(OutputExistsError, match="not an exposim dataset"):
        capture_sequence(chart, other, camera, n_shots=2, stereo=False, overwrite=True)
    assert (other / "thesis.txt").read_text() == "keep me"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes", "seq"]
    empty = tmp_path / "empty"
    empty.mkdir()
    capture_sequence(chart, empty, camera, n_shots=1, stereo=False)  # an empty folder is used as is
    assert (empty / "exposim.json").is_file()


def test_force_never_deletes_files_synth_did_not_write(tmp_path, camera, chart):
    """issue 11: ``synth --force`` deleted files a user had added inside the old dataset."""
    out = capture_sequence(chart, tmp_path / "seq", camera, n_shots=2, stereo=False)
    manifest = json.loads((out / MANIFEST_FILE).read_text())["files"]
    assert set(manifest) == set(_hashes(out)) - {MANIFEST_FILE}  # every file synth wrote, no other
    (out / "notes.txt").write_text("my notes")
    (out / "camera_left" / "labels").mkdir()
    (out / "camera_left" / "labels" / "0.json").write_text("{}")
    before = _hashes(out)
    with pytest.raises(OutputExistsError) as err:
        capture_sequence(chart, out, camera, n_shots=3, stereo=False, overwrite=True)
    message = str(err.value)
    assert "2 file(s) that exposim synth did not write" in message
    assert "camera_left/labels/0.json" in message and "notes.txt" in message and "nothing was changed" in message
    assert _hashes(out) == before  # old dataset and the user's files untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seq"]  # no staging folder left behind
    # a file synth wrote but the user changed since counts as the user's
    (out / "notes.txt").unlink()
    (out / "camera_left" / "labels" / "0.json").unlink()
    png = next((out / "camera_left").rglob("*.png"))
    png.write_bytes(png.read_bytes() + b"edited")
    with pytest.raises(OutputExistsError, match="changed since synth wrote it"):
        capture_sequence(chart, out, camera, n_shots=3, stereo=False, overwrite=True)
    assert png.read_bytes().endswith(b"edited")
    png.unlink()
    # only synth's own files left (one missing): replaced, and the empty user folder goes with it
    capture_sequence(chart, out, camera, n_shots=3, stereo=False, overwrite=True)
    assert len(list((out / "camera_left").rglob("*.png"))) == 3 and not (out / "camera_left" / "labels").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seq"]


def test_force_on_a_dataset_without_manifest_judges_by_the_layout(tmp_path, camera, chart):
    out = capture_sequence(chart, tmp_path / "seq", camera, n_shots=2, gt_exposures_ms=(5.0,),
                           gt_captures="both", save_radiance=True)
    (out / MANIFEST_FILE).unlink()  # as written before the manifest existed
    (out / "ground_truth" / "my_poses.txt").write_text("0 0 0 0 0 0 0 1\n")
    with pytest.raises(OutputExistsError, match=r"1 file\(s\).*ground_truth/my_poses.txt"):
        capture_sequence(chart, out, camera, n_shots=2, overwrite=True)
    assert (out / "ground_truth" / "my_poses.txt").is_file()
    assert foreign_files(out) == ["ground_truth/my_poses.txt"]  # every file synth wrote matches its layout
    (out / "ground_truth" / "my_poses.txt").unlink()
    capture_sequence(chart, out, camera, n_shots=1, overwrite=True)
    assert len(list((out / "camera_left").rglob("*.png"))) == 1 and (out / MANIFEST_FILE).is_file()


@pytest.mark.parametrize("umask, folder_mode, file_mode", [(0o022, 0o755, 0o644), (0o077, 0o700, 0o600)])
def test_dataset_permissions_follow_the_umask(tmp_path, camera, chart, umask, folder_mode, file_mode):
    """issue 11: datasets came out 0700 and PNGs 0600 under umask 0022 (tempfile's modes)."""
    old = os.umask(umask)
    try:
        out = capture_sequence(chart, tmp_path / "seq", camera, n_shots=2, gt_exposures_ms=(5.0,),
                               save_radiance=True)
        staging = make_staging_dir(tmp_path, ".x-")
        written = atomic_write_bytes(tmp_path / "plain.bin", b"x")
    finally:
        os.umask(old)
    folders = [out, *(p for p in out.rglob("*") if p.is_dir())]
    files = [p for p in out.rglob("*") if p.is_file()]
    assert len(folders) == 17 and len(files) == 2 * 2 * 3 + 7  # every folder and file of the layout
    assert {stat.S_IMODE(p.stat().st_mode) for p in folders + [staging]} == {folder_mode}
    assert {stat.S_IMODE(p.stat().st_mode) for p in files + [written]} == {file_mode}


@pytest.mark.parametrize("failure", [RuntimeError, KeyboardInterrupt])
def test_interrupted_write_leaves_no_final_file(tmp_path, camera, chart, failure):
    calls = []

    def failing(t, side):
        calls.append(t)
        if len(calls) == 7:
            raise failure("disk pulled")
        return chart(t, side)

    with pytest.raises(failure, match="disk pulled"):
        capture_sequence(failing, tmp_path / "seq", camera, n_cycles=2, save_radiance=True, gt_exposures_ms=(5.0,))
    assert not (tmp_path / "seq").exists()
    assert list(tmp_path.rglob("*.png")) == [] and list(tmp_path.rglob("*.exr")) == []
    assert list(tmp_path.iterdir()) == []  # the staging folder is gone too


def test_failure_while_encoding_leaves_no_final_file(tmp_path, camera, chart, monkeypatch):
    written = []
    real = synth.sequence.write_frame

    def flaky(*args, **kwargs):
        if len(written) == 4:
            raise OSError("no space left on device")
        written.append(real(*args, **kwargs))
        return written[-1]

    monkeypatch.setattr(synth.sequence, "write_frame", flaky)
    with pytest.raises(OSError, match="no space"):
        capture_sequence(chart, tmp_path / "seq", camera, n_shots=6)
    assert len(written) == 4 and not any(p.exists() for p in written)
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------- sources
def test_precomputed_frames_with_rotation(tmp_path, camera):
    rng = np.random.default_rng(0)
    frames = []
    for k in range(4):
        rot = Rotation.from_euler("xyz", [0.1 * k, -0.2, 0.3 + k]).as_matrix()
        left = np.eye(4)
        left[:3, :3], left[:3, 3] = rot, (k, 2.0 * k, -1.0)
        right = left.copy()
        right[:3, 3] += 0.18 * rot[:, 0]
        rad = (rng.random((H, W, 3)) * 100).astype(np.float32)
        frames.append({"left": (rad, left), "right": (rad[:, ::-1].copy(), right)})
    out = capture_sequence(frames, tmp_path / "seq", camera, noise=False)
    assert len(load_sequence(out)[0].frames["right"]) == 4
    for side in ("left", "right"):
        _, values = _read_tum(out / "ground_truth" / f"poses_{side}.txt")
        for (tx, ty, tz, *q), frame in zip(values, frames):
            pose = frame[side][1]
            np.testing.assert_allclose([tx, ty, tz], pose[:3, 3], atol=1e-9)
            np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), pose[:3, :3], atol=1e-8)
            assert q[3] >= 0


def test_mono_capture(tmp_path, camera, chart):
    out = capture_sequence(chart, tmp_path / "mono", camera, n_cycles=1, stereo=False)
    seq = load_sequence(out)
    assert seq.cameras == ("left",) and any("camera_right/ missing" in g for g in seq.gaps)
    assert not (out / "calibration" / "right.yaml").exists()
    assert json.loads((out / "exposim.json").read_text())["baseline_m"] is None


def test_source_errors_name_the_shot(tmp_path, camera, chart):
    def wrong_rig(t, side):
        rad, pose = chart(t, side)
        if side == "right":
            pose = pose.copy()
            pose[1, 3] += 0.05
        return rad, pose

    with pytest.raises(SourceError, match=r"shot 0 \(right camera.*baseline_m = 0.18"):
        capture_sequence(wrong_rig, tmp_path / "a", camera, n_shots=2)

    def bad_radiance(t, side):
        rad, pose = chart(t, side)
        if t > 0.05:
            rad = rad.copy()
            rad[1, 2, 0] = np.nan
        return rad, pose

    with pytest.raises(RadianceError, match=r"shot 2 \(left camera, t = 0.0909.*NaN.*row 1, column 2"):
        capture_sequence(bad_radiance, tmp_path / "b", camera, n_shots=4)
    with pytest.raises(PoseError, match="not a rotation"):
        capture_sequence(lambda t, s: (chart(t, s)[0], np.diag([1.0, 1.0, -1.0, 1.0])), tmp_path / "c", camera,
                         n_shots=1, stereo=False)
    with pytest.raises(SourceError, match=r"must return \(radiance, pose\)"):
        capture_sequence(lambda t, s: chart(t, s)[0], tmp_path / "d", camera, n_shots=1, stereo=False)
    with pytest.raises(SourceError, match="stereo capture needs"):
        capture_sequence([chart(0.0, "left")], tmp_path / "e", camera)
    with pytest.raises(SourceError, match="3 shots need 3 frames"):
        capture_sequence([chart(0.0, "left")], tmp_path / "f", camera, n_shots=3, stereo=False)
    with pytest.raises(SynthError, match="n_cycles or n_shots"):
        capture_sequence(chart, tmp_path / "g", camera)
    with pytest.raises(SynthError, match="gt_captures"):
        capture_sequence(chart, tmp_path / "h", camera, n_shots=1, gt_captures="all")
    assert list(tmp_path.iterdir()) == []


def test_translating_chart_geometry(chart):
    left, pose_l = chart(0.3, "left")
    right, pose_r = chart(0.3, "right")
    assert left.dtype == np.float32 and left.shape == (H, W, 3)
    np.testing.assert_allclose(pose_r[:3, 3] - pose_l[:3, 3], [0.18, 0, 0])
    disparity = chart.focal_length_px * 0.18 / chart.depth_m  # px, the right image is shifted left
    shifted = chart(0.3 + 0.18 / chart.speed_m_s, "left")[0]
    np.testing.assert_allclose(shifted, right, rtol=1e-5)
    assert disparity > 1
    with pytest.raises(SourceError, match="outside"):
        chart(5.0, "left")


def test_hdr_chart_spans_the_dynamic_range_and_has_features():
    import cv2

    rad = synth.procedural.hdr_chart(256, 192, seed=1, dynamic_range_db=100.0)
    assert rad.dtype == np.float32 and rad.shape == (192, 256, 3) and rad.min() > 0
    np.testing.assert_array_equal(rad, synth.procedural.hdr_chart(256, 192, seed=1, dynamic_range_db=100.0))
    assert 20 * math.log10(rad.max() / rad.min()) > 100
    cam = Camera.preset("borealhdr", width=256, height=192)
    raw = synth.capture(rad, 4.0, cam, seed=0)
    keypoints = cv2.SIFT_create().detect((raw >> 4).astype(np.uint8), None)
    assert len(keypoints) > 30
