"""Exposure-time integration of synthetic shots (scenes.blur, scenes.walkshots): prediction, warp geometry, a frame at rest."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scenes import blur
from scenes import trajectory as tr
from scenes.camera import intrinsics_matrix
from scenes.errors import RenderError


def _roll_poses(angle_rad: float, n: int = 5) -> np.ndarray:
    base = tr.look_pose((0.0, 0.0, 1.6), 0.0)
    out = []
    for a in np.linspace(0.0, angle_rad, n):
        m = base.copy()
        c, s = math.cos(a), math.sin(a)
        m[:3, :3] = base[:3, :3] @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        out.append(m)
    return np.stack(out)


def test_predicted_blur_of_a_roll_is_the_corner_arc():
    w, h, theta = 480, 300, math.radians(1.0)
    got = blur.predicted_blur_px(_roll_poses(theta), w, h)
    radius = math.hypot((w - 1) / 2.0, (h - 1) / 2.0)  # the grid's corners are the farthest from the axis
    chord = 4 * 2 * radius * math.sin(theta / 8)  # four equal chords of the arc
    assert got == pytest.approx(chord, rel=1e-9)


def test_subinstants_follow_the_blur():
    assert blur.n_subinstants(0.0) == 1 and blur.n_subinstants(0.2) == 1
    assert blur.n_subinstants(0.3) == 2
    assert blur.n_subinstants(4.5) == 9
    assert blur.n_subinstants(1e6) == blur.MAX_SUBINSTANTS
    with pytest.raises(RenderError, match="blur_px"):
        blur.n_subinstants(float("nan"))
    np.testing.assert_allclose(blur.subinstant_times_s(1.0, 1.032, 4), [1.004, 1.012, 1.020, 1.028])


def _plane_image(pose, k, w, h, depth_m):
    """A camera looking at the textured plane y_world = depth_m (x, z texture coordinates), exact."""
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    rays = np.stack([(u - k[0, 2]) / k[0, 0], (v - k[1, 2]) / k[1, 1], np.ones_like(u)], axis=-1) @ pose[:3, :3].T
    s = (depth_m - pose[1, 3]) / rays[..., 1]
    x = pose[0, 3] + s * rays[..., 0]
    z = pose[2, 3] + s * rays[..., 2]
    img = 1.0 + 0.5 * np.sin(3.0 * x) * np.cos(2.0 * z)
    zc = ((np.stack([x, np.full_like(x, depth_m), z], -1) - pose[:3, 3]) @ pose[:3, :3])[..., 2]
    return img[..., None].astype(np.float32), (1.0 / zc).astype(np.float32)


def test_warp_reproduces_rotation_and_parallax_on_a_plane():
    w, h, m = 96, 60, 12
    k_dst = intrinsics_matrix(w, h)
    k_src = k_dst.copy()
    k_src[0, 2] += m
    k_src[1, 2] += m
    src_pose = tr.look_pose((0.0, 0.0, 1.6), 90.0)  # looks along +y at the plane y = 3 m
    dst_pose = tr.look_pose((0.05, 0.02, 1.62), 90.8, pitch_deg=0.4)
    src, inv_depth = _plane_image(src_pose, k_src, w + 2 * m, h + 2 * m, 3.0)
    want, _ = _plane_image(dst_pose, k_dst, w, h, 3.0)
    got = blur.warp_to_pose(src, inv_depth, src_pose, k_src, dst_pose, k_dst, w, h)
    rotation_only = blur.warp_to_pose(src, inv_depth * 0, src_pose, k_src, dst_pose, k_dst, w, h)
    assert np.abs(got - want).max() < 2e-3  # bilinear on a smooth texture
    assert np.abs(rotation_only - want).max() > 20 * np.abs(got - want).max()  # parallax matters here


def test_warp_to_the_same_pose_is_the_crop():
    rng = np.random.default_rng(0)
    w, h, m = 40, 30, 3
    k_dst = intrinsics_matrix(w, h)
    k_src = k_dst.copy()
    k_src[:2, 2] += m
    src = rng.random((h + 2 * m, w + 2 * m, 3)).astype(np.float32)
    pose = tr.look_pose((1.0, 2.0, 1.6), 30.0)
    got = blur.warp_to_pose(src, np.full(src.shape[:2], 0.3, np.float32), pose, k_src, pose, k_dst, w, h)
    np.testing.assert_allclose(got, src[m:m + h, m:m + w], atol=1e-5)


@pytest.mark.render
def test_a_shot_at_rest_is_one_plain_render(tmp_path):
    import scenes

    scene = scenes.get_scene("static_lab")
    pose = scene.default_pose()
    still = tr.static(pose, duration_s=1.0)
    kw = dict(width=32, height=20, spp=4, seed=3, cache_dir=tmp_path, denoise="off")
    shot = blur.ShotRenderer(scene, still.poses, 0.2, 32.0, **kw)
    image, info = shot.radiance(32.0)
    assert shot.at_rest and info["n_subinstants"] == 1 and info["blur_px"] == 0.0
    np.testing.assert_array_equal(image, scenes.render(scene, pose, **kw))


def _walk_shots(tmp_path, spp: int):
    """forest_summer's 3 s walk, and a maker of its 32 ms shot at 1 s (48x30, seed 1, no denoiser)."""
    import scenes

    scene = scenes.get_scene("forest_summer")
    traj = scene.trajectory(3.0)

    def shot(**extra):
        return blur.ShotRenderer(scene, traj.poses, 1.0, 32.0, width=48, height=30, spp=spp, seed=1,
                                 cache_dir=tmp_path, denoise="off", **extra)

    return traj, shot


@pytest.mark.render
def test_a_moving_shot_blurs_along_the_walk(tmp_path):
    traj, make_shot = _walk_shots(tmp_path, spp=4)
    shot = make_shot()
    long_, info = shot.radiance(32.0)
    short, info_short = shot.radiance(1.0)
    assert not shot.at_rest and shot.info["margin_px"] == shot.margin_px()
    # the render sits at the window's middle: about half the path reaches either end
    assert 2 + 0.4 * shot.max_blur_px <= shot.margin_px() <= math.ceil(0.6 * shot.max_blur_px) + 2
    assert info["n_subinstants"] == blur.n_subinstants(info["blur_px"]) >= 2
    assert info_short["blur_px"] < info["blur_px"] / 10
    assert long_.shape == short.shape == (30, 48, 3) and long_.dtype == np.float32
    assert info_short["n_subinstants"] == blur.n_subinstants(info_short["blur_px"])
    assert info["blur_px"] == pytest.approx(
        blur.predicted_blur_px(traj.poses(np.linspace(1.0, 1.032, 5)), 48, 30), rel=1e-12)


def test_margin_step_rounds_every_margin_up_and_the_render_follows(tmp_path):
    _, make_shot = _walk_shots(tmp_path, spp=1)
    exact = make_shot().margin_px()
    for step in (1, 3, 8):
        shot = make_shot(margin_step_px=step)
        margin = shot.margin_px()
        assert margin % step == 0 and exact <= margin < exact + step
        job = shot.render_job()
        assert (job["width"], job["height"]) == (48 + 2 * margin, 30 + 2 * margin)
    for bad in (0, -8, 2.5, True):
        with pytest.raises(RenderError, match="margin_step_px must be an integer >= 1"):
            make_shot(margin_step_px=bad)


def test_a_walk_rendered_per_cycle_shares_few_render_sizes_with_8_px_steps():
    """What the demo relies on: its 12-sweep forest_winter walk (256x160, margins for 45 ms plus a
    sweep) has one render size per distinct margin (each a new kernel compilation for Dr.Jit); 8 px
    steps leave three of them where 1 px steps leave more than twice as many."""
    import scenes
    from scenes.walkshots import WalkShots

    scene = scenes.get_scene("forest_winter")
    traj = scene.trajectory(12 * 6 / 22.0 + 1.0)
    margins = {}
    for step in (1, 8):
        shots = WalkShots(scene, traj, render=dict(width=256, height=160, spp=8, fov_deg=78.0, cache_dir=False,
                                                   variant="scalar_rgb", denoise="off", render_seed=0),
                          fps=22.0, n_brackets=6, max_window_ms=45.0, baseline_m=0.18, render_per="cycle",
                          margin_step_px=step)
        margins[step] = [shots.renderer(i, cam).margin_px() for i in range(0, 72, 6) for cam in ("left", "right")]
        assert shots.describe()["margin_step_px"] == step
    assert [-(-m // 8) * 8 for m in margins[1]] == margins[8]
    assert len(set(margins[8])) <= 3 and 2 * len(set(margins[8])) < len(set(margins[1]))


@pytest.mark.render
def test_synthesize_blurs_with_one_render_per_cycle(tmp_path):
    import json

    from emulator.io.imu import read_imu
    from scenes.synthesize import synthesize

    counts = {}
    for mode in ("shot", "cycle"):
        cache = tmp_path / f"cache-{mode}"
        out = synthesize("forest_summer", tmp_path / mode, n_cycles=1, width=32, height=20, spp=1, denoise="off",
                         cache_dir=cache, render_per=mode)
        counts[mode] = len(list(cache.rglob("*.exr")))
        meta = json.loads((out / "exposim.json").read_text())
        assert meta["source"]["render"]["exposure_integration"].endswith(f"one render per {mode})")
        assert meta["timestamps"].startswith("trigger instant of each shot = start of its exposure")
        imu = read_imu(out)
        assert imu is not None and abs(imu.rate_hz - 100.0) < 1e-6
        assert imu.timestamp_ns[0] == 1_700_000_000_000_000_000
    assert counts == {"shot": 12, "cycle": 2}  # 6 shots x 2 cameras, or one render per camera


@pytest.mark.render
def test_live_radiance_rebuilds_the_brackets_and_integrates_other_exposures(tmp_path):
    import json

    from emulator.io.exr import read_exr
    from scenes.synthesize import synthesize
    from scenes.walkshots import walk_radiance

    import scenes

    scene = scenes.get_scene("forest_summer")
    cache = tmp_path / "cache"
    out = synthesize(scene, tmp_path / "ds", n_cycles=1, width=32, height=20, spp=1, denoise="off", cache_dir=cache,
                     save_radiance=True, stereo=False, margin_step_px=5)
    brackets = json.loads((out / "exposim.json").read_text())["brackets_ms"]
    live = walk_radiance(out, scene, cache_dir=cache)
    assert live.exposure_aware and live.shots.margin_step_px == 5  # read back, so the renders are the writer's
    stamps = sorted(int(p.stem) for p in (out / "ground_truth" / "radiance" / "camera_left").glob("*.exr"))
    n_renders = len(list(cache.rglob("*.exr")))
    for ts, e in zip(stamps, brackets):
        saved = read_exr(out / "ground_truth" / "radiance" / "camera_left" / f"{ts}.exr")
        np.testing.assert_array_equal(live(ts, "left", e), saved)
    assert not np.array_equal(live(stamps[-1], "left", 1.0), live(stamps[-1], "left", 32.0))
    assert len(list(cache.rglob("*.exr"))) == n_renders  # the writer's renders, nothing new
    assert walk_radiance(synthesize(scene, tmp_path / "sharp", n_cycles=1, width=32, height=20, spp=1,
                                    denoise="off", cache_dir=cache, blur=False, stereo=False), scene) is None


@pytest.mark.render
def test_sharp_twin_shares_the_renders_and_samples_the_trigger_instant(tmp_path):
    import json

    from emulator.io.exr import read_exr
    from scenes.synthesize import synthesize
    from scenes.walkshots import walk_radiance

    import scenes

    scene = scenes.get_scene("forest_summer")
    cache = tmp_path / "cache"
    kw = dict(n_cycles=1, width=32, height=20, spp=1, denoise="off", cache_dir=cache, stereo=False,
              render_per="cycle", save_radiance=True)
    blurred = synthesize(scene, tmp_path / "blurred", **kw)
    n_renders = len(list(cache.rglob("*.exr")))
    sharp = synthesize(scene, tmp_path / "sharp", integrate=False, **kw)
    assert len(list(cache.rglob("*.exr"))) == n_renders  # the blurred walk's render, nothing new
    meta = json.loads((sharp / "exposim.json").read_text())
    assert meta["source"]["render"]["blur_shots"]["integrate"] is False
    assert meta["timestamps"].startswith("trigger instant of each shot; the scene is sampled there")
    live = walk_radiance(sharp, scene, cache_dir=cache)
    stamps = sorted(int(p.stem) for p in (sharp / "ground_truth" / "radiance" / "camera_left").glob("*.exr"))
    last = stamps[-1]  # the 32 ms shot: its window moves, its trigger instant does not
    np.testing.assert_array_equal(live(last, "left", 1.0), live(last, "left", 32.0))
    np.testing.assert_array_equal(live(last, "left", 32.0),
                                  read_exr(sharp / "ground_truth" / "radiance" / "camera_left" / f"{last}.exr"))
    blurred_32 = read_exr(blurred / "ground_truth" / "radiance" / "camera_left" / f"{last}.exr")
    assert not np.array_equal(blurred_32, live(last, "left", 32.0))


@pytest.mark.render
def test_a_supersampled_shot_spends_the_same_samples_and_keeps_the_level(tmp_path):
    _, make_shot = _walk_shots(tmp_path, spp=8)
    plain = make_shot()
    fine = make_shot(supersample=2)
    job, job2 = plain.render_job(), fine.render_job()
    assert (job2["width"], job2["height"]) == (2 * job["width"], 2 * job["height"])
    assert job2["spp"] == 2 and job2["fov_deg"] == pytest.approx(job["fov_deg"], rel=1e-12)  # 4x pixels, spp / 4
    a, b = plain.radiance(32.0)[0], fine.radiance(32.0)[0]
    assert b.shape == a.shape == (30, 48, 3) and fine.info["margin_px"] == plain.info["margin_px"]
    # the same scene through the same window: the mean level agrees to the render noise of the two
    assert abs(float(b.mean()) / float(a.mean()) - 1) < 0.05
    with pytest.raises(RenderError, match="supersample"):
        make_shot(supersample=0)
