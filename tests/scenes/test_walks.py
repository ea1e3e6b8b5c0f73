"""Walks that turn like the real one (scenes.walks): rates, gait, replay, IMU file."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from scenes import trajectory as tr
from scenes import walks
from scenes.errors import SceneError

SHARED_IMU = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "borealhdr_sample" / \
    "backpack_2023-09-25-15-05-03" / "imu" / "imu.csv"
_IMU_CANDIDATES = (SHARED_IMU, Path("/work/shared/data/borealhdr_sample/backpack_2023-09-25-15-05-03/imu/imu.csv"))


def _real_imu() -> Path:
    for p in _IMU_CANDIDATES:
        if p.is_file():
            return p
    from tests.conftest import missing_shared

    missing_shared("the shared BorealHDR sample's imu/imu.csv is not here")


def _rate_percentiles_deg_s(omega) -> np.ndarray:
    return np.percentile(np.degrees(np.linalg.norm(omega, axis=1)), (50, 90, 99))


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_gait_walk_turns_like_the_real_gyro(seed):
    _, real_omega = walks.read_gyro_csv(_real_imu())
    real = _rate_percentiles_deg_s(real_omega)
    traj = walks.gait_walk(200.0, seed=seed)
    syn = _rate_percentiles_deg_s(walks.angular_velocity(traj, np.arange(0.0, 200.0, 0.01)))
    ratio = syn / real
    assert np.all((ratio >= 0.85) & (ratio <= 1.15)), (syn, real)


def _step_frequency_hz(omega, fs_hz: float) -> float:
    from scipy.signal import welch

    f, p = welch(omega - omega.mean(), fs=fs_hz, nperseg=8192)
    band = (f > 1.0) & (f < 2.5)
    return float(f[band][np.argmax(p[band])])


def test_gait_frequency_matches_the_real_gyro():
    t, real_omega = walks.read_gyro_csv(_real_imu())
    real_hz = _step_frequency_hz(real_omega[:, 1], 1.0 / np.median(np.diff(t)))  # pitch: one peak per step
    traj = walks.gait_walk(82.0, seed=0)
    gyro = walks.angular_velocity(traj, np.arange(0.0, 82.0, 0.01)) @ walks.CAMERA_FROM_IMU
    syn_hz = _step_frequency_hz(gyro[:, 1], 100.0)
    assert abs(syn_hz / real_hz - 1.0) < 0.15
    assert abs(syn_hz - walks.GAIT_STEP_HZ) < 0.05


def test_gait_walk_translation_and_bob():
    traj = walks.gait_walk(60.0, seed=3)
    p = traj.poses(np.arange(0.0, 60.0, 0.01))[:, :3, 3]
    speed_mps = np.linalg.norm(p[-1, :2] - p[0, :2]) / 59.99
    assert 0.9 * tr.WALKING_SPEED_MPS < speed_mps <= 1.001 * tr.WALKING_SPEED_MPS  # meander shortens the chord
    assert 0.03 < np.ptp(p[:, 2]) <= 0.04 + 1e-9  # 2 cm bob amplitude
    assert abs(p[:, 2].mean() - 1.6) < 2e-3
    r = traj.poses(np.linspace(0, 60, 50))[:, :3, :3]
    np.testing.assert_allclose(np.einsum("nji,njk->nik", r, r), np.broadcast_to(np.eye(3), r.shape), atol=1e-12)


def test_gait_walk_seeded_and_pose_independent_of_duration():
    a, b = walks.gait_walk(10.0, seed=1), walks.gait_walk(30.0, seed=1)
    np.testing.assert_array_equal(a.pose(4.0), b.pose(4.0))
    assert not np.array_equal(a.pose(4.0), walks.gait_walk(10.0, seed=2).pose(4.0))
    with pytest.raises(SceneError, match="timestamp_s"):
        a.pose(11.0)


def test_angular_velocity_exact_for_a_constant_turn():
    # the gentle walk with no meander and no sway turns at 0; a static camera at 0 too
    still = tr.static(tr.look_pose((0, 0, 1.6), 30.0), duration_s=2.0)
    np.testing.assert_allclose(walks.angular_velocity(still, [0.0, 1.0, 2.0]), 0.0, atol=1e-12)
    rate = math.radians(20.0)  # a replayed constant yaw rate comes back exactly (camera -y is up)
    t = np.arange(0, 201) * 0.01
    omega = np.zeros((t.size, 3))
    omega[:, 2] = rate
    rep = walks.GyroReplay(duration_s=2.0, sample_times_s=t, camera_rates=omega @ walks.CAMERA_FROM_IMU.T,
                           rotations=np.stack([_yaw(rate * ti) for ti in t]), body=walks._BodyPath(2.0, (0, 0), 0, 0.5, 0))
    got = walks.angular_velocity(rep, [0.5, 1.0, 1.5]) @ walks.CAMERA_FROM_IMU
    np.testing.assert_allclose(got, [[0.0, 0.0, rate]] * 3, atol=1e-9)


def _yaw(angle):
    return tr.look_pose((0, 0, 0), math.degrees(angle))[:3, :3]


def test_replay_reproduces_the_recorded_rates(tmp_path):
    real = _real_imu()
    rep = walks.gyro_replay(real, start_s=10.0, duration_s=5.0, remove_mean=False)
    t, omega = walks.read_gyro_csv(real)
    inside = (t > 10.05) & (t < 14.95)
    mid = t[inside] - 10.0 + 3e-4  # inside each sample's piecewise-constant interval
    got = walks.angular_velocity(rep, mid, step_s=2e-4) @ walks.CAMERA_FROM_IMU
    np.testing.assert_allclose(got, omega[inside], atol=1e-9)
    with pytest.raises(SceneError, match="no such gyro file"):
        walks.gyro_replay(tmp_path / "missing.csv")


def test_make_walk_presets_and_scene_default():
    import scenes

    scene = scenes.get_scene("forest_summer")
    assert isinstance(scene.trajectory(5.0), walks.GaitWalk)
    gentle = scene.trajectory(5.0, walk="gentle")
    assert isinstance(gentle, tr.Trajectory)
    np.testing.assert_array_equal(gentle.pose(1.0), tr.walk(5.0, seed=scene.seed, start=scene.start,
                                                           heading_deg=scene.heading_deg,
                                                           stream="forest_summer").pose(1.0))
    with pytest.raises(SceneError, match="unknown walk"):
        walks.make_walk("brisk", 5.0)


def test_a_scenes_walk_stream_includes_the_scene():
    import scenes

    # the same seed in two scenes: different motion (the random stream includes the scene's name) ...
    a = scenes.get_scene("forest_summer", seed=3).trajectory(5.0, start=(0.0, 0.0), heading_deg=0.0)
    b = scenes.get_scene("forest_winter", seed=3).trajectory(5.0, start=(0.0, 0.0), heading_deg=0.0)
    assert a.stream == "forest_summer" and b.stream == "forest_winter"
    assert not np.allclose(a.pose(2.0), b.pose(2.0))
    # ... each one reproducible, and an empty stream is the seed's own (old) stream
    again = walks.gait_walk(5.0, seed=3, stream="forest_summer")
    np.testing.assert_array_equal(a.pose(2.0), again.pose(2.0))
    assert tr.stream_key(3, 21) == [3, 21] and tr.stream_key(3, 21, "x")[:2] == [3, 21]
    np.testing.assert_array_equal(tr.walk(5.0, seed=3).pose(1.0), tr.walk(5.0, seed=3, stream="").pose(1.0))
    assert not np.allclose(tr.walk(5.0, seed=3).pose(2.0), tr.walk(5.0, seed=3, stream="sun_glare").pose(2.0))


def test_imu_samples_at_rest_read_gravity():
    still = tr.static(tr.look_pose((0, 0, 1.6), 30.0, pitch_deg=0.0), duration_s=1.0)
    t, gyro, acc = walks.imu_samples(still, 100.0)
    assert t.size == 101
    np.testing.assert_allclose(gyro, 0.0, atol=1e-12)
    np.testing.assert_allclose(acc, np.tile([0.0, 0.0, 9.80665], (t.size, 1)), atol=1e-9)
