"""Render noise against sensor noise for features (``validation.render_study.balance``) on tiny images."""

from __future__ import annotations

import json
import os
from dataclasses import replace
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import scenes
from scenes.image_stats import keypoint_points, keypoint_repeatability, synthetic_camera, synthetic_gray8
from validation.common import ValidationError
from validation.render_study import balance as bal

ROOT = Path(__file__).resolve().parents[3]


pytestmark = pytest.mark.usefixtures("default_render_env")


def test_settings_are_parsed_and_bad_ones_refused():
    label, spp, s = bal.parse_setting("oidn-fast@2")
    assert (label, spp, s.name, s.quality, s.aux_spp) == ("oidn-fast@2", 2, "oidn-fast", "balanced", 16)
    _, spp, hq = bal.parse_setting("oidn-hq@256")  # the preset of the measured oidn@256/1024
    _, _, explicit = bal.parse_setting("oidn@256/1024")
    assert spp == 256 and hq.aux_spp == 1024 and replace(hq, name="oidn") == explicit
    _, spp, s = bal.parse_setting("oidn@8/32")
    assert (spp, s.name, s.quality, s.aux_spp) == (8, "oidn", "high", 32)
    assert bal.parse_setting("off@64")[2].enabled is False
    for bad, words in (("oidn", "DENOISER@SPP"), ("oidn@0", "DENOISER@SPP"), ("oidn@x", "DENOISER@SPP"),
                       ("oidn@2/", "DENOISER@SPP"), ("blur@2", "unknown denoiser"), ("off@4/16", "needs a denoiser"),
                       ("oidn@4/0", "aux_spp")):
        with pytest.raises(ValidationError, match=words) as err:
            bal.parse_setting(bad)
        assert bad in str(err.value) and "\n" not in str(err.value)


def test_t_interval_of_known_values():
    m, lo, hi = bal.t_interval([1.0, 2.0, 3.0])
    half = 4.302652729749464 / np.sqrt(3.0)  # t(0.975, 2) * sd 1 / sqrt(3)
    assert m == 2.0 and lo == pytest.approx(2.0 - half, abs=1e-12) and hi == pytest.approx(2.0 + half, abs=1e-12)
    assert bal.t_interval([5.0, float("nan")])[0] == 5.0 and np.isnan(bal.t_interval([5.0])[1])
    assert all(np.isnan(bal.t_interval([])))


def _texture(seed: int, h: int = 96, w: int = 128) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = np.kron(rng.uniform(0.05, 1.0, (h // 8, w // 8)), np.ones((8, 8)))
    return np.repeat(base[..., None], 3, axis=2).astype(np.float32)


def test_one_render_twice_is_perfectly_repeatable_and_the_sensor_is_not():
    scene = scenes.get_scene("forest_winter")
    cam = synthetic_camera(scene, 128, 96)
    img = _texture(0) * scene.reference_radiance * 0.5
    r = bal.balance_at_pose(img, img, scene, cam, exposure_ms=2.0, sensor_seeds=(0, 1, 2))
    assert r["render_only"] == 100.0  # same render, same sensor draw: the same keypoints
    assert r["keypoints"] > 10
    # the sensor-only figure is the mean over consecutive pairs of draws, on both renders
    pts = [keypoint_points(synthetic_gray8(img, scene, exposure_ms=2.0, seed=s, camera=cam)) for s in (0, 1, 2)]
    expected = 100.0 * np.mean([keypoint_repeatability(pts[0], pts[1]), keypoint_repeatability(pts[1], pts[2])])
    assert r["sensor_only"] == pytest.approx(expected, abs=1e-9) and r["sensor_only"] < 100.0
    other = _texture(1) * scene.reference_radiance * 0.5  # a different picture: few keypoints in common
    assert bal.balance_at_pose(img, other, scene, cam, exposure_ms=2.0, sensor_seeds=(0, 1))["render_only"] < 50.0
    with pytest.raises(ValidationError, match="two sensor-noise seeds"):
        bal.balance_at_pose(img, img, scene, cam, exposure_ms=2.0, sensor_seeds=(0,))


@pytest.mark.render
@pytest.mark.parametrize("render_per", ["cycle", "still"])
def test_noise_balance_on_a_tiny_walk_agrees_with_its_rows(tmp_path, render_per):
    kw = dict(width=48, height=32, exposures_ms=(8.0, 32.0), sweeps=(0, 2), sensor_seeds=(0, 1),
              render_per=render_per, cache_dir=tmp_path)
    r = bal.noise_balance("off@1", **kw)
    assert r["denoise"] == {"name": "off"} and r["spp"] == 1 and r["render_per"] == render_per
    assert len(r["per_pose"]) == 4 and r["seconds_per_sweep"] > 0 and r["sweeps_timed"] == 2
    for e in ("8", "32"):
        rows = [x for x in r["per_pose"] if f"{x['exposure_ms']:g}" == e]
        d = [x["render_only"] - x["sensor_only"] for x in rows]
        got = r["exposures"][e]
        assert got["difference"][0] == pytest.approx(np.mean(d), abs=1e-9)
        assert got["difference"][1] <= got["difference"][0] <= got["difference"][2]
        assert got["met"] == (got["difference"][1] >= -bal.GOAL_TOLERANCE_POINTS)  # the whole interval
    again = bal.noise_balance("off@1", **kw)
    assert again["per_pose"] == r["per_pose"]  # the same renders (cache hits) ...
    assert again["seconds_per_sweep"] is None and again["sweeps_timed"] == 0  # ... whose seconds are not a render's
    with pytest.raises(ValidationError, match="not brackets"):
        bal.noise_balance("off@1", **{**kw, "exposures_ms": (10.0,)})
    with pytest.raises(ValidationError, match="render seeds"):
        bal.noise_balance("off@1", **{**kw, "render_seeds": (1, 1)})


def test_script_refuses_bad_input_in_one_line(tmp_path):
    out = tmp_path / "b.json"
    out.write_text("{}")
    script = str(ROOT / "scripts" / "render_noise_balance.py")
    run = lambda *a: subprocess.run([sys.executable, script, *a],  # noqa: E731
                                    capture_output=True, text=True, cwd=ROOT, env={"PYTHONPATH": str(ROOT)})
    p = run("-o", str(out), "oidn@2")
    assert p.returncode == 2 and "exists" in p.stderr and str(out) in p.stderr
    assert json.loads(out.read_text()) == {}
    p = run("-o", str(tmp_path / "c.json"), "oidn@two")
    assert p.returncode == 2 and p.stderr.strip().count("\n") == 0 and "oidn@two" in p.stderr
    assert not (tmp_path / "c.json").exists()


@pytest.mark.render
def test_one_sweep_has_no_interval_and_the_file_is_strict_json(tmp_path):
    import subprocess
    import sys

    out = tmp_path / "one.json"
    p = subprocess.run([sys.executable, str(ROOT / "scripts" / "render_noise_balance.py"), "-o", str(out), "off@1",
                        "--size", "48x32", "--sweeps", "0", "--cache-dir", str(tmp_path / "cache")],
                       capture_output=True, text=True, cwd=ROOT,
                       env={"PYTHONPATH": str(ROOT), "EXPOSIM_DENOISE": "off", "EXPOSIM_MITSUBA_VARIANT": "scalar_rgb"})
    assert p.returncode == 0, p.stderr
    text = out.read_text()
    assert "NaN" not in text
    doc = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-strict JSON constant {c}"))
    diff = doc["results"][0]["exposures"]["8"]["difference"]
    assert isinstance(diff[0], float) and diff[1] is None and diff[2] is None
    assert doc["null_reasons"]["results[0].exposures.8.difference[1]"].startswith("not a finite number")
    import importlib.metadata
    import platform

    import cv2

    # where the figures were made, and the command as a reader reruns it (the output file's name alone)
    assert doc["machine"] == {"render_variant": "scalar_rgb", "gpu": None, "cpu_count": os.cpu_count(),
                              "python": platform.python_version(), "numpy": np.__version__, "opencv": cv2.__version__,
                              "mitsuba": importlib.metadata.version("mitsuba"),
                              "drjit": importlib.metadata.version("drjit")}
    assert doc["command"] == ("EXPOSIM_MITSUBA_VARIANT=scalar_rgb python scripts/render_noise_balance.py "
                              "-o one.json off@1 --size 48x32 --sweeps 0 --cache-dir CACHE")
