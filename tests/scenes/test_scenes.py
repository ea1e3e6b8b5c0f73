"""Tests of the ``scenes`` package: procedural scenes, trajectories, rendering, cache, CLI.

Renders are tiny (at most 64x40); the dynamic-range checks use 100 spp at
64x40 so that no pixel is left black by Monte Carlo noise (a zero would pin the
figure at its 200 dB floor and make the check meaningless).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import scenes
from emulator.errors import ExposimError
from scenes import trajectory as tr
from scenes import variant as var
from scenes.base import Scene
from scenes.denoise import resolve_denoise
from scenes.description import SceneDescription, Shape
from emulator.io.exr import read_exr, write_exr
from emulator.io.tum import read_tum, write_tum
from scenes.cache import store_entry
from scenes.errors import RenderError, SceneError
from synth.errors import PoseError

SCENE_NAMES = ("forest_winter", "forest_summer", "sun_glare", "forest_edge", "static_lab")


@pytest.fixture(autouse=True)
def _default_variant(monkeypatch):
    """Every test starts from the automatic Mitsuba variant (the render cache is conftest's)."""
    monkeypatch.delenv("EXPOSIM_MITSUBA_VARIANT", raising=False)


def test_the_suite_renders_into_a_temporary_cache(render_cache, tmp_path_factory):
    cache = scenes.default_cache_dir()
    assert cache == render_cache and cache.is_dir()
    assert tmp_path_factory.getbasetemp() in cache.parents
    assert Path.home() / ".cache" not in cache.parents


@pytest.fixture(scope="module")
def built():
    """One Scene per name (each builds its geometry and textures once)."""
    return {name: scenes.get_scene(name, seed=0) for name in SCENE_NAMES}


def _start_pose(scene: Scene) -> np.ndarray:
    return scene.default_pose() if scene.is_static else scene.trajectory(10.0).pose(0.0)


def _marker_scene(point, radius=0.05) -> Scene:
    """A scene holding only a small glowing ball at ``point`` (for projection checks)."""

    def describe(seed, params):
        return SceneDescription(materials={}, shapes=(Shape("sphere", center=tuple(point), radius=radius,
                                                            radiance=(1.0, 1.0, 1.0)),),
                                sun=None, sky=None, max_depth=2, reference_radiance=1.0)

    return Scene(name="test_marker", params={"point": [float(p) for p in point]}, seed=0, is_static=True,
                 start=(0.0, 0.0), heading_deg=0.0, _describe=describe)


# --------------------------------------------------------------------------------------------
# import cost, registry, parameters
# --------------------------------------------------------------------------------------------

def test_import_is_cheap():
    code = ("import sys, scenes; bad = [m for m in ('mitsuba', 'drjit', 'colour', 'OpenEXR') if m in sys.modules];"
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))))


def test_registry_holds_the_five_scenes():
    assert set(SCENE_NAMES) <= set(scenes.SCENES)
    for name in SCENE_NAMES:
        s = scenes.get_scene(name)
        assert s.name == name and s.seed == 0
        assert set(s.params) == set(scenes.SCENES[name].defaults)
    assert scenes.get_scene("static_lab").is_static
    assert not scenes.get_scene("forest_winter").is_static


def test_unknown_scene_lists_the_valid_names():
    with pytest.raises(SceneError, match="valid scenes: .*forest_edge.*static_lab"):
        scenes.get_scene("jungle")
    assert issubclass(SceneError, ExposimError) and issubclass(SceneError, ValueError)


def test_bad_parameters_are_refused_by_name():
    with pytest.raises(SceneError, match="unknown parameter.*tree_count.*valid:.*tree_density_per_ha"):
        scenes.get_scene("forest_winter", tree_count=3)
    with pytest.raises(SceneError, match="sun_elevation_deg must be a number"):
        scenes.get_scene("forest_winter", sun_elevation_deg="high")
    with pytest.raises(SceneError, match="seed"):
        scenes.get_scene("forest_winter", seed=-1)
    with pytest.raises(SceneError, match="sun_elevation_deg must be in"):
        scenes.get_scene("forest_winter", sun_elevation_deg=120.0).describe()
    with pytest.raises(SceneError, match="texture_px must be an integer"):
        scenes.get_scene("forest_winter", texture_px=10.5)


def test_scene_identity_follows_name_params_seed():
    a = scenes.get_scene("forest_winter", seed=1, sky_fraction=0.1)
    assert a == scenes.get_scene("forest_winter", seed=1) and hash(a) == hash(scenes.get_scene("forest_winter", seed=1))
    assert a != scenes.get_scene("forest_winter", seed=2)
    assert a != scenes.get_scene("forest_winter", seed=1, sky_fraction=0.2)


# --------------------------------------------------------------------------------------------
# daylight, textures, geometry (no rendering)
# --------------------------------------------------------------------------------------------

def test_luminance_weights_match_colour_science():
    import colour

    y_row = colour.RGB_COLOURSPACES["ITU-R BT.709"].matrix_RGB_to_XYZ[1]
    np.testing.assert_allclose(scenes.lighting.LUMINANCE_WEIGHTS_REC709, y_row, atol=1e-4)


def test_daylight_colour_from_colour_science():
    from scenes.lighting import LUMINANCE_WEIGHTS_REC709, daylight_rgb

    for cct in (4500.0, 6504.0, 12000.0):
        assert float(np.dot(daylight_rgb(cct), LUMINANCE_WEIGHTS_REC709)) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(daylight_rgb(6504.0), 1.0, atol=2e-3)  # D65 is the Rec.709 white
    low_sun, sky = daylight_rgb(4500.0), daylight_rgb(12000.0)
    assert low_sun[0] > low_sun[2] and sky[2] > sky[0]
    with pytest.raises(SceneError, match="cct_k"):
        daylight_rgb(2000.0)


def test_sun_disk_carries_the_sun_irradiance(built):
    sun = built["sun_glare"].describe().sun
    assert sun.disk_visible
    half = math.radians(sun.angular_diameter_deg) / 2
    solid_angle = 2 * math.pi * (1 - math.cos(half))
    np.testing.assert_allclose(sun.disk_radiance_rgb * solid_angle, sun.irradiance_rgb, rtol=1e-12)
    assert not built["forest_winter"].describe().sun.disk_visible


def test_sky_envmap_is_scaled_to_the_diffuse_irradiance():
    from scenes.lighting import daylight_rgb, envmap_direction, sky_envmap, sun_direction

    sky = sky_envmap(horizontal_irradiance=100.0, sky_rgb=daylight_rgb(12000.0), sun_dir=sun_direction(30, 0),
                     height=64, width=128)
    d = envmap_direction(64, 128)
    assert d[0, 0, 2] > 0.99 and d[-1, 0, 2] < -0.99  # first row is the zenith
    y = sky.astype(np.float64) @ scenes.lighting.LUMINANCE_WEIGHTS_REC709
    v = (np.arange(64) + 0.5) / 64
    d_omega = (np.pi / 64) * (2 * np.pi / 128) * np.sin(np.pi * v)[:, None]
    e = float(np.sum(np.where(d[..., 2] > 0, y * d[..., 2], 0.0) * d_omega))
    assert e == pytest.approx(100.0, rel=1e-4)


def test_fractal_noise_is_seeded_and_in_range():
    from scenes.textures import fractal_noise, snow_texture

    a = fractal_noise((64, 48), 3)
    assert a.dtype == np.float32 and a.shape == (64, 48) and 0.0 < a.min() and a.max() < 1.0
    np.testing.assert_array_equal(a, fractal_noise((64, 48), 3))
    assert not np.array_equal(a, fractal_noise((64, 48), 4))
    snow = snow_texture(0, 128)
    assert snow.shape == (128, 128, 3) and snow.dtype == np.float32 and 0.0 < snow.min() and snow.max() <= 1.0
    with pytest.raises(SceneError, match="shape"):
        fractal_noise((2, 64), 0)


def test_meshes_are_consistent(built):
    from scenes.geometry import cones, icosphere

    m = cones([[0, 0, 0], [5, 0, 1]], [1.0, 2.0], [3.0, 4.0], segments=8)
    assert m.faces.shape == (2 * 2 * 8, 3) and m.faces.max() < m.vertices.shape[0]
    assert m.vertices[:, 2].max() == pytest.approx(5.0)
    sphere = icosphere((1, 2, 3), 2.0)
    np.testing.assert_allclose(np.linalg.norm(sphere.vertices - [1, 2, 3], axis=1), 2.0, rtol=1e-6)
    for name, scene in built.items():
        desc = scene.describe()
        for shape in desc.shapes:
            if shape.mesh is not None:
                assert np.all(np.isfinite(shape.mesh.vertices)), name
        assert desc.reference_radiance > 0


# --------------------------------------------------------------------------------------------
# camera model
# --------------------------------------------------------------------------------------------

def test_intrinsics_match_the_borealhdr_camera():
    fx, fy, cx, cy = scenes.intrinsics(1920, 1200)
    assert fx == pytest.approx(1180.0, rel=1e-12) and fy == fx
    assert (cx, cy) == (959.5, 599.5)
    k = scenes.intrinsics_matrix(64, 40, 90.0)
    np.testing.assert_allclose(k, [[32.0, 0, 31.5], [0, 32.0, 19.5], [0, 0, 1]], rtol=1e-12)
    with pytest.raises(RenderError, match="width"):
        scenes.intrinsics(0, 10)
    with pytest.raises(RenderError, match="fov_deg"):
        scenes.intrinsics(10, 10, 180.0)


@pytest.mark.render
@pytest.mark.parametrize("offset", [(1.0, -0.5), (-1.2, 0.6)])
def test_a_point_projects_where_the_intrinsics_say(offset):
    """Camera x right and y down: a point right of / above the axis lands right of / above the centre."""
    pose = tr.look_pose((2.0, -1.0, 1.6), heading_deg=30.0)
    point_cam = np.array([offset[0], offset[1], 5.0])
    point = pose[:3, :3] @ point_cam + pose[:3, 3]
    w, h = 64, 40
    img = scenes.render(_marker_scene(point), pose, width=w, height=h, spp=16, seed=0, cache_dir=False)
    y = scenes.luminance(img)
    rows, cols = np.nonzero(y > 0)
    weights = y[rows, cols]
    u, v = np.average(cols, weights=weights), np.average(rows, weights=weights)
    expected = scenes.project(point, pose, w, h)[0]
    assert abs(u - expected[0]) < 0.5 and abs(v - expected[1]) < 0.5
    assert (u > w / 2) == (offset[0] > 0)  # right of the axis -> right half
    assert (v < h / 2) == (offset[1] < 0)  # above the axis (y up is -y camera) -> top half


@pytest.mark.render
def test_effective_spp_matches_the_mitsuba_sampler():
    import mitsuba as mi

    from scenes.mitsuba_objects import SAMPLER

    if mi.variant() is None:
        mi.set_variant("scalar_rgb")
    for n in (1, 2, 3, 5, 8, 10, 16, 32, 64, 100, 128, 256, 1000):
        sampler = mi.load_dict({"type": SAMPLER, "sample_count": scenes.effective_spp(n)})
        assert sampler.sample_count() == scenes.effective_spp(n) >= n
    assert scenes.effective_spp(128) == 132 and scenes.effective_spp(256) == 256


def test_bad_pose_is_refused():
    with pytest.raises(PoseError, match=r"pose must be a finite 4x4 matrix, got shape \(3, 3\)"):
        scenes.render("static_lab", np.eye(3), width=8, height=8, spp=1, cache_dir=False)
    skew = np.eye(4)
    skew[0, 1] = 0.5
    with pytest.raises(PoseError, match="rotation"):
        scenes.render("static_lab", skew, width=8, height=8, spp=1, cache_dir=False)
    with pytest.raises(RenderError, match="spp"):
        scenes.render("static_lab", np.eye(4), width=8, height=8, spp=0, cache_dir=False)


# --------------------------------------------------------------------------------------------
# trajectories
# --------------------------------------------------------------------------------------------

def test_walk_speed_and_height():
    traj = tr.walk(60.0, seed=3)
    t = np.linspace(0.0, 59.9, 600)
    p0 = traj.poses(t)[:, :3, 3]
    p1 = traj.poses(t + 0.01)[:, :3, 3]
    horizontal = np.linalg.norm((p1 - p0)[:, :2], axis=1) / 0.01
    np.testing.assert_allclose(horizontal, 2.0 / 3.6, rtol=1e-3)  # 2 km/h
    z = p0[:, 2]
    assert np.abs(z - 1.6).max() <= 0.015 + 1e-9  # head bob of 1.5 cm around 1.6 m
    assert z.mean() == pytest.approx(1.6, abs=2e-3) and z.std() > 0.005
    travelled = np.linalg.norm(traj.pose(60.0)[:2, 3] - traj.pose(0.0)[:2, 3])
    assert 0.97 * 60 * 2 / 3.6 < travelled <= 60 * 2 / 3.6 + 1e-9  # smooth: barely meanders
    for m in traj.poses(t[::50]):
        np.testing.assert_allclose(m[:3, :3].T @ m[:3, :3], np.eye(3), atol=1e-12)
        assert np.linalg.det(m[:3, :3]) == pytest.approx(1.0)
        assert m[2, 1] < 0  # image y (down) points down in the world: the camera is upright


def test_walk_is_seeded_and_validated():
    np.testing.assert_array_equal(tr.walk(10, seed=1).pose(4.0), tr.walk(10, seed=1).pose(4.0))
    assert not np.array_equal(tr.walk(10, seed=1).pose(4.0), tr.walk(10, seed=2).pose(4.0))
    with pytest.raises(SceneError, match="duration_s"):
        tr.walk(-1.0)
    with pytest.raises(SceneError, match="timestamp_s"):
        tr.walk(10.0).pose(11.0)


def test_right_camera_is_one_baseline_to_the_right():
    pose = tr.walk(20.0, seed=5).pose(7.3)
    right = tr.stereo_right(pose)
    rel = np.linalg.inv(pose) @ right
    np.testing.assert_allclose(rel[:3, :3], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(rel[:3, 3], [0.18, 0.0, 0.0], atol=1e-12)
    # heading +x: the camera's right is world -y
    level = tr.look_pose((0, 0, 1.6), 0.0)
    np.testing.assert_allclose(tr.stereo_right(level)[:3, 3], [0.0, -0.18, 1.6], atol=1e-12)


def test_static_trajectory_and_tum_round_trip(tmp_path):
    fixed = tr.look_pose((1, 2, 1.4), 15.0, -3.0)
    st = tr.static(fixed, duration_s=5.0)
    np.testing.assert_array_equal(st.pose(0.0), st.pose(5.0))
    walk = tr.walk(3.0, seed=2)
    ts = walk.timestamps(4.0)
    assert ts.tolist() == [i / 4 for i in range(13)]
    stamps_ns = [round(t * 1e9) for t in ts]
    path = write_tum(tmp_path / "poses.txt", stamps_ns, walk.poses(ts))
    first = path.read_text().splitlines()[0].split()
    assert len(first) == 8 and float(first[0]) == 0.0
    back = read_tum(path)
    np.testing.assert_array_equal(back.timestamps_s, ts)
    assert back.timestamps_ns.tolist() == stamps_ns
    assert np.all(back.quaternions_xyzw[:, 3] >= 0)
    np.testing.assert_allclose(back.poses, walk.poses(ts), atol=1e-12)


# --------------------------------------------------------------------------------------------
# dynamic range figure
# --------------------------------------------------------------------------------------------

def test_dynamic_range_db_reference_values():
    img = np.ones((10, 100))
    img[:, :50] = 1000.0
    assert scenes.dynamic_range_db(img) == pytest.approx(60.0, abs=1e-12)
    rgb = np.repeat(img[..., None], 3, axis=-1)
    assert scenes.dynamic_range_db(rgb) == pytest.approx(60.0, abs=1e-9)
    assert scenes.dynamic_range_db(np.full((4, 4, 3), 2.0)) == pytest.approx(0.0, abs=1e-12)
    black = img.copy()
    black[:, :10] = 0.0
    assert scenes.dynamic_range_db(black) == pytest.approx(200.0)  # documented floor
    assert scenes.dynamic_range_db(black, max_db=120.0) == pytest.approx(120.0)
    with_nan = img.copy()
    with_nan[0, 0] = np.nan
    with_nan[0, 1] = np.inf
    assert math.isfinite(scenes.dynamic_range_db(with_nan))
    assert scenes.dynamic_range_db(np.zeros((3, 3))) == 0.0
    with pytest.raises(RenderError, match="finite"):
        scenes.dynamic_range_db(np.full((3, 3), np.nan))
    with pytest.raises(RenderError, match="percentile"):
        scenes.dynamic_range_db(img, low_percentile=50, high_percentile=10)


# Lower bounds of the dynamic range at 64x40 / 100 spp, from the start of each
# scene's default trajectory.  Each is the physical ratio the scene is built
# around, less a margin for the coarse pixels (a 64x40 pixel averages a dark
# crevice with its neighbours, so small renders read lower than 480x300), for
# the sampler seed and for the scene seed.  Measured here with sampler seeds
# 0 / 1 and scene seed 1 (llvm_ad_rgb): winter 77.5 / 74.5 / 84.3, summer
# 66.0 / 69.6 / 60.4, glare 101.8 / 100.4 / 105.0, edge 107.9 / 109.6 / 112.1,
# lab 62.1 / 61.5 / 61.9 dB.
#  - forest_winter: sunlit snow (0.9 x ~570 W m^-2 / pi ~ 160) against needle
#    cavities and bark in crown shade lit by < 0.1 % of that: >= 60 dB
#    (target >= 70 dB holds at 480x300: 81 dB at 256 spp).
#  - forest_summer: sun patches on litter (<= 0.25 x ~830 / pi ~ 65) against
#    litter and leaf clumps in shade lit by a few % of the sky: >= 48 dB.
#  - sun_glare: the glint of the sun on ice (>= 1e4) against shaded snow and
#    bark (~0.1): >= 85 dB.
#  - forest_edge: sunlit snow through the opening (~180) against bark inside the
#    closed stand, lit by 0.05 % canopy transmittance (albedo <= 0.1 x 0.34 / pi
#    ~ 0.01 and below): >= 95 dB (target >= 100 dB: 113 dB at 480x300).
#  - static_lab: the 1..32 ms brackets span 30 dB; so that every bracket sees
#    both near-white and dark pixels the scene must add a single exposure's
#    useful range (~20 dB): >= 50 dB.
DR_LOWER_BOUND_DB = {"forest_winter": 60.0, "forest_summer": 48.0, "sun_glare": 85.0, "forest_edge": 95.0,
                     "static_lab": 50.0}


@pytest.mark.render
@pytest.mark.parametrize("name", SCENE_NAMES)
def test_scene_render_is_valid_and_has_its_dynamic_range(built, name):
    scene = built[name]
    # the scene's own range: the unbiased raw estimate (at 64x40 the 0.1st percentile is 2-3 pixels,
    # which the denoiser lifts towards their neighbours: forest_winter 64 dB raw, 58 dB denoised)
    img = scenes.render(scene, _start_pose(scene), width=64, height=40, spp=100, seed=0, cache_dir=False,
                        denoise="off")
    assert img.dtype == np.float32 and img.shape == (40, 64, 3)
    assert np.all(np.isfinite(img)) and img.min() >= 0.0
    y = scenes.luminance(img)
    assert np.mean(y <= 0) < 0.001  # the 0.1st percentile is a real radiance, not the floor
    assert scenes.dynamic_range_db(img) >= DR_LOWER_BOUND_DB[name]


# --------------------------------------------------------------------------------------------
# rendering: determinism, cache, variants
# --------------------------------------------------------------------------------------------

@pytest.mark.render
def test_render_is_deterministic_per_seed(built):
    scene, pose = built["static_lab"], built["static_lab"].default_pose()
    a = scenes.render(scene, pose, width=48, height=30, spp=4, seed=7, cache_dir=False)
    b = scenes.render(scene, pose, width=48, height=30, spp=4, seed=7, cache_dir=False)
    c = scenes.render(scene, pose, width=48, height=30, spp=4, seed=8, cache_dir=False)
    assert a.tobytes() == b.tobytes()
    assert not np.array_equal(a, c)


@pytest.mark.render
def test_cache_hit_is_byte_identical_and_skips_rendering(built, tmp_path, monkeypatch):
    import importlib

    render_module = importlib.import_module("scenes.render")

    scene, pose = built["static_lab"], built["static_lab"].default_pose()
    first = scenes.render(scene, pose, width=48, height=30, spp=2, seed=1, cache_dir=tmp_path, denoise="off")
    files = list(tmp_path.rglob("*.exr"))
    assert len(files) == 1
    stored = files[0].read_bytes()

    def no_render(*args, **kwargs):
        raise AssertionError("a cache hit must not render")

    monkeypatch.setattr(render_module, "_render_uncached", no_render)
    second = scenes.render(scene, pose, width=48, height=30, spp=2, seed=1, cache_dir=tmp_path, denoise="off")
    assert second.dtype == np.float32 and second.tobytes() == first.tobytes()
    assert files[0].read_bytes() == stored
    with pytest.raises(AssertionError, match="cache hit"):  # any other input is a miss
        scenes.render(scene, pose, width=48, height=30, spp=2, seed=2, cache_dir=tmp_path, denoise="off")


@pytest.mark.render
def test_denoised_render_is_cached_beside_its_raw_estimate(built, tmp_path, monkeypatch):
    import importlib

    monkeypatch.delenv("EXPOSIM_DENOISE", raising=False)

    from scenes.denoise import oidn_status

    if not oidn_status()[0]:
        pytest.skip(f"OIDN unavailable: {oidn_status()[1]}")
    render_module = importlib.import_module("scenes.render")
    scene, pose = built["static_lab"], built["static_lab"].default_pose()
    raw = scenes.render(scene, pose, width=48, height=30, spp=2, seed=1, cache_dir=tmp_path, denoise="off")
    calls = []
    real_render = render_module._render_uncached
    monkeypatch.setattr(render_module, "_render_uncached", lambda *a, **k: calls.append(1) or real_render(*a, **k))
    den, info = render_module.render_with_info(scene, pose, width=48, height=30, spp=2, seed=1, cache_dir=tmp_path)
    # the raw estimate came from the cache: only the albedo/normal pass and OIDN ran
    assert calls == [] and info["denoise"] == "oidn" and not info["cache_hit"] and info["aux_s"] > 0
    assert den.shape == raw.shape and np.all(np.isfinite(den)) and den.min() >= 0 and not np.array_equal(den, raw)
    # two entries, named by keys that differ only in the denoiser (name, version, settings)
    common = dict(width=48, height=30, spp=2, seed=1, fov_deg=scenes.DEFAULT_FOV_DEG, variant=scenes.choose_variant())
    settings = resolve_denoise("oidn")
    raw_key, _ = scenes.render_key(scene, pose, **common)
    den_key, material = scenes.render_key(scene, pose, denoise=settings.key_material(), **common)
    assert material["denoise"]["name"] == "oidn" and material["denoise"]["version"]["pyoidn"] != "missing"
    assert sorted(p.stem for p in tmp_path.rglob("*.exr")) == sorted([raw_key, den_key])
    other = scenes.render_key(scene, pose, denoise=replace(settings, quality="fast").key_material(), **common)[0]
    assert other not in (raw_key, den_key)
    # second call: one file read, nothing rendered or denoised
    monkeypatch.setattr(render_module, "_render_aux_uncached", lambda *a, **k: (_ for _ in ()).throw(
        AssertionError("a cache hit must not render the aux pass")))
    monkeypatch.setattr(render_module, "denoise_oidn", lambda *a, **k: (_ for _ in ()).throw(
        AssertionError("a cache hit must not denoise")))
    again, info2 = render_module.render_with_info(scene, pose, width=48, height=30, spp=2, seed=1,
                                                  cache_dir=tmp_path)
    assert info2["cache_hit"] and again.tobytes() == den.tobytes() and calls == []


@pytest.mark.render
def test_unreadable_cache_file_is_rendered_again(built, tmp_path):
    scene, pose = built["static_lab"], built["static_lab"].default_pose()
    first = scenes.render(scene, pose, width=16, height=10, spp=1, seed=0, cache_dir=tmp_path, denoise="off")
    (path,) = tmp_path.rglob("*.exr")
    path.write_bytes(b"not an exr")
    again = scenes.render(scene, pose, width=16, height=10, spp=1, seed=0, cache_dir=tmp_path, denoise="off")
    assert again.tobytes() == first.tobytes()
    assert read_exr(path).tobytes() == first.tobytes()


@pytest.mark.render
def test_unwritable_cache_warns_and_keeps_the_render(built, tmp_path):
    scene, pose = built["static_lab"], built["static_lab"].default_pose()
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("x")
    with pytest.warns(RuntimeWarning, match="could not write"):
        img = scenes.render(scene, pose, width=16, height=10, spp=1, seed=0, cache_dir=blocker)
    assert img.shape == (10, 16, 3) and np.all(np.isfinite(img))


def test_exr_bytes_are_deterministic(tmp_path):
    img = np.random.default_rng(0).random((5, 7, 3), dtype=np.float32) * 1e4
    a = store_entry(tmp_path / "a.exr", img, {"note": "x"})
    from scenes.cache import SHA_ATTRIBUTE, pixels_sha256

    b = write_exr(tmp_path / "b.exr", img, attributes={"note": "x", SHA_ATTRIBUTE: pixels_sha256(img)})
    assert a.read_bytes() == b.read_bytes()
    assert read_exr(a).tobytes() == img.tobytes()
    assert not list(tmp_path.glob("*.tmp"))
    with pytest.raises(RenderError, match="float32"):
        store_entry(tmp_path / "c.exr", img.astype(np.float64))
    with pytest.raises(FileNotFoundError):
        read_exr(tmp_path / "missing.exr")


def test_cache_key_covers_everything_that_changes_pixels(built):
    scene = built["static_lab"]
    pose = scene.default_pose()
    base = dict(width=64, height=40, spp=4, seed=0, fov_deg=78.0, variant="scalar_rgb")
    key, material = scenes.render_key(scene, pose, **base)
    assert key == scenes.render_key(scene, pose.copy(), **base)[0]
    assert material["versions"]["mitsuba"] and material["scene"]["code"] == scenes.code_fingerprint()
    moved = pose.copy()
    moved[0, 3] += 1e-6
    others = [scenes.render_key(scene, moved, **base)[0],
              scenes.render_key(scenes.get_scene("static_lab", seed=1), pose, **base)[0],
              scenes.render_key(scenes.get_scene("static_lab", albedo_min=0.02), pose, **base)[0]]
    for k, v in (("width", 65), ("height", 41), ("spp", 8), ("seed", 1), ("fov_deg", 70.0),
                 ("variant", "llvm_ad_rgb")):
        others.append(scenes.render_key(scene, pose, **{**base, k: v})[0])
    assert len(set(others)) == len(others) and key not in others


@pytest.mark.render
def test_scalar_variant_agrees_with_the_default(built):
    scene, pose = built["static_lab"], built["static_lab"].default_pose()
    scalar = scenes.render(scene, pose, width=32, height=20, spp=16, seed=0, cache_dir=False, variant="scalar_rgb")
    default = scenes.render(scene, pose, width=32, height=20, spp=16, seed=0, cache_dir=False)
    assert scalar.dtype == np.float32 and np.all(np.isfinite(scalar)) and scalar.min() >= 0
    assert scalar.mean() == pytest.approx(default.mean(), rel=0.05)  # same scene, independent noise


@pytest.fixture
def _restore_variant_state():
    saved = (dict(var._probed), var._chosen)
    yield
    var._probed.clear()
    var._probed.update(saved[0])
    var._chosen = saved[1]


def test_variant_probe_falls_back_when_llvm_aborts(monkeypatch, _restore_variant_state):
    """Simulate an old LLVM: the probe child aborts (SIGABRT). This process must survive and pick scalar."""
    monkeypatch.setattr(var, "_PROBE_SCRIPT", "import os, sys\nif sys.argv[1].startswith('llvm'): os.abort()\n"
                                              "print('exposim-variant-probe-ok')")
    assert var.probe_variant("llvm_ad_rgb") is False
    assert scenes.choose_variant(refresh=True) == "scalar_rgb"
    assert var._probed["llvm_ad_rgb"] is False
    with pytest.raises(RenderError, match="does not work"):
        var.ensure_variant("llvm_ad_rgb")
    monkeypatch.setenv("EXPOSIM_MITSUBA_VARIANT", "llvm_ad_rgb")
    assert scenes.choose_variant() == "llvm_ad_rgb"  # forced: named without a probe...
    with pytest.raises(RenderError, match="does not work"):  # ...but never loaded unprobed
        scenes.render("static_lab", np.eye(4), width=8, height=8, spp=1, cache_dir=False)


def test_cuda_variant_chosen_only_with_a_driver_and_a_passing_probe(monkeypatch, _restore_variant_state):
    """The GPU variant comes first where an NVIDIA driver is present and its probe renders; else llvm."""
    monkeypatch.delenv("EXPOSIM_MITSUBA_VARIANT", raising=False)
    probed = []
    monkeypatch.setattr(var, "probe_variant", lambda v, **kw: probed.append(v) or v in ok)
    ok = {"cuda_ad_rgb", "llvm_ad_rgb"}
    monkeypatch.setattr(var, "_has_nvidia_driver", lambda: False)
    assert scenes.choose_variant(refresh=True) == "llvm_ad_rgb" and probed == ["llvm_ad_rgb"]
    monkeypatch.setattr(var, "_has_nvidia_driver", lambda: True)
    probed.clear()
    assert scenes.choose_variant(refresh=True) == "cuda_ad_rgb" and probed == ["cuda_ad_rgb"]
    ok = {"llvm_ad_rgb"}  # a driver but no working CUDA variant (old driver, no GPU memory)
    probed.clear()
    assert scenes.choose_variant(refresh=True) == "llvm_ad_rgb" and probed == ["cuda_ad_rgb", "llvm_ad_rgb"]


def test_gpu_description_is_nvidia_smis_line_or_none(monkeypatch, tmp_path):
    """What measurement records name as the GPU: nvidia-smi's name and driver, None where it is absent,
    fails or says nothing."""
    monkeypatch.setenv("PATH", str(tmp_path))  # no nvidia-smi
    assert var.gpu_description() is None
    smi = tmp_path / "nvidia-smi"
    smi.write_text("#!/bin/sh\necho 'NVIDIA H200, 580.159.04'\n")
    smi.chmod(0o755)
    assert var.gpu_description() == "NVIDIA H200, 580.159.04"
    smi.write_text("#!/bin/sh\nexit 9\n")
    assert var.gpu_description() is None


def test_variant_probe_failure_modes(monkeypatch, _restore_variant_state):
    monkeypatch.setattr(var, "_PROBE_SCRIPT", "raise SystemExit(3)")
    assert var.probe_variant("llvm_ad_rgb") is False
    monkeypatch.setattr(var, "_PROBE_SCRIPT", "import time; time.sleep(30)")
    assert var.probe_variant("llvm_ad_rgb", timeout_s=0.5) is False


def test_variant_override_and_validation(monkeypatch, _restore_variant_state, tmp_path):
    def no_probe(variant, **kwargs):
        raise AssertionError("no probe expected here")

    monkeypatch.setattr(var, "probe_variant", no_probe)
    monkeypatch.setenv("EXPOSIM_MITSUBA_VARIANT", "scalar_rgb")
    assert scenes.choose_variant() == "scalar_rgb"
    # a cache hit with a forced JIT variant reads the file without probing it
    var._probed.clear()
    scene = scenes.get_scene("static_lab")
    key, material = scenes.render_key(scene, np.eye(4), width=4, height=2, spp=1, seed=0,
                                      fov_deg=scenes.DEFAULT_FOV_DEG, variant="llvm_ad_rgb",
                                      denoise=resolve_denoise("oidn").key_material())
    img = np.arange(24, dtype=np.float32).reshape(2, 4, 3)
    from scenes.cache import KEY_ATTRIBUTE, canonical_json  # an entry carries its key (checked on read)

    store_entry(tmp_path / key[:2] / f"{key}.exr", img, {KEY_ATTRIBUTE: canonical_json(material)})
    monkeypatch.setenv("EXPOSIM_MITSUBA_VARIANT", "llvm_ad_rgb")
    monkeypatch.delenv("EXPOSIM_DENOISE", raising=False)
    hit = scenes.render(scene, np.eye(4), width=4, height=2, spp=1, seed=0, cache_dir=tmp_path)  # denoised key
    assert hit.tobytes() == img.tobytes() and "llvm_ad_rgb" not in var._probed
    monkeypatch.setenv("EXPOSIM_MITSUBA_VARIANT", "vulkan_rgb")
    with pytest.raises(RenderError, match="valid: llvm_ad_rgb, scalar_rgb"):
        scenes.choose_variant()


# --------------------------------------------------------------------------------------------
# samples per pixel from a noise target
# --------------------------------------------------------------------------------------------

@pytest.mark.render
def test_select_spp_reports_the_noise_curve(built):
    scene, pose = built["static_lab"], built["static_lab"].default_pose()
    sel = scenes.select_spp(scene, pose, width=32, height=20, candidates=(1, 4, 16), stop_when_met=False,
                            target_ratio=1e-9)
    assert [row["spp"] for row in sel.curve] == [1, 4, 16]
    ratios = [row["noise_ratio"] for row in sel.curve]
    assert ratios[0] > ratios[1] > ratios[2] > 0  # more samples, less noise
    assert not sel.met and sel.spp == 16 and sel.predicted_spp > 16
    assert all(row["pixels"] > 0 and row["sensor_noise_rel"] > 0 for row in sel.curve)
    easy = scenes.select_spp(scene, pose, width=32, height=20, candidates=(1, 4, 16), target_ratio=1e9)
    assert easy.met and easy.spp == 1 and len(easy.curve) == 1
    json.dumps(easy.to_dict())
    with pytest.raises(RenderError, match="candidates"):
        scenes.select_spp(scene, pose, width=8, height=8, candidates=(4, 2))


# --------------------------------------------------------------------------------------------
# command line
# --------------------------------------------------------------------------------------------

@pytest.mark.render
def test_cli_render_writes_frames_poses_and_json(tmp_path, capsys):
    from emulator.commands.cli import main

    out = tmp_path / "run"
    argv = ["render", "static_lab", "--size", "32x20", "--spp", "2", "--duration", "0.5", "--rate", "2",
            "--stereo", "--quiet", "-o", str(out)]
    assert main(argv) == 0
    for cam in ("left", "right"):
        names = sorted(p.name for p in (out / "frames" / cam).iterdir())
        assert names == ["0.exr", "500000000.exr"]
        assert read_exr(out / "frames" / cam / "0.exr").shape == (20, 32, 3)
    left_file = read_tum(out / "poses_left.txt")
    ts, poses = left_file.timestamps_s, left_file.poses
    right = read_tum(out / "poses_right.txt").poses
    assert ts.tolist() == [0.0, 0.5]
    np.testing.assert_allclose((np.linalg.inv(poses[0]) @ right[0])[:3, 3], [0.18, 0, 0], atol=1e-9)
    info = json.loads((out / "scene.json").read_text())
    assert info["scene"] == "static_lab" and info["spp"] == 2 and len(info["frames"]) == 4
    assert info["intrinsics"]["cx"] == 15.5 and info["dynamic_range_db"]["min"] > 0
    assert info["params"] == scenes.get_scene("static_lab").params

    assert main(argv) == 1  # refuses to overwrite
    assert "--force" in capsys.readouterr().err
    assert main(argv + ["--force"]) == 0
    assert main(["render", "static_lab", "--size", "32by20", "-o", str(tmp_path / "x")]) == 1
    assert "WIDTHxHEIGHT" in capsys.readouterr().err
    assert main(["render", "static_lab", "--param", "albedo_min=2", "--size", "8x8", "--spp", "1",
                 "--duration", "0", "-o", str(tmp_path / "y")]) == 1
    assert "albedo_min" in capsys.readouterr().err
