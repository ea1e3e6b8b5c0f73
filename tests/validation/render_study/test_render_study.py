"""``validation.render_study`` plumbing on tiny images, and ``scenes.image_stats``; full studies are not tests."""

from __future__ import annotations

import json
import sys
from dataclasses import replace

import numpy as np
import pytest

import scenes
from emulator.errors import OutputExistsError
from scenes import denoise as dn
from scenes import image_stats as ist
from validation import render_study as rs
from validation.common import ValidationError


pytestmark = pytest.mark.usefixtures("default_render_env")


TINY = rs.RenderStudyConfig(scenes=("static_lab",), width=24, height=16, spp_levels=(1, 2), reference_spp=8,
                            error_exposures_ms=(8.0,), texture_scenes=("static_lab",), texture_sizes=((24, 16),),
                            texture_spp=1, texture_poses=1, real_sequence=None, cache_dir="off")


# ---------------------------------------------------------------------------------- image statistics
def test_image_statistics_on_known_images():
    ramp = np.tile(np.arange(0, 64, 2, dtype=np.uint8), (16, 1))
    assert ist.median_gradient(ramp) == 16.0  # Sobel weighs a unit step by 8; the ramp climbs 2 per pixel
    assert ist.median_gradient(np.full((8, 8), 77, np.uint8)) == 0.0
    assert ist.keypoint_repeatability([[0, 0], [10, 10]], [[1, 1], [30, 30]]) == 0.5
    assert ist.keypoint_repeatability([[0, 0]], [[1.5, 0]]) == 1.0  # the 1.5 px tolerance is inclusive
    assert np.isnan(ist.keypoint_repeatability(np.zeros((0, 2)), [[0, 0]]))
    assert ist.keypoint_repeatability([[0, 0]], np.zeros((0, 2))) == 0.0
    blob = np.zeros((64, 64), np.uint8)
    blob[28:36, 28:36] = 200
    st = ist.image_stats(blob)
    assert st.keypoints >= 1 and st.keypoints_per_mp == pytest.approx(st.keypoints / (64 * 64 / 1e6))
    assert ist.gray8_at(blob, (32, 32)).shape == (32, 32) and ist.gray8_at(blob, None) is blob
    with pytest.raises(scenes.SceneError, match="uint8"):
        ist.median_gradient(np.zeros((8, 8), np.float32))


# ---------------------------------------------------------------------------------- measures
def test_bright_errors_core_and_halo():
    ref = np.full((20, 20, 3), 1.0, np.float32)
    ref[10, 10] = 1000.0  # the brightest 0.1 % of 400 pixels: one pixel
    same = rs.bright_errors(ref, ref)
    assert same == {"bright_rel_err": 0.0, "bright_halo": 0.0}
    dim = ref.copy()
    dim[10, 10] = 500.0
    assert rs.bright_errors(dim, ref)["bright_rel_err"] == pytest.approx(0.5)
    smeared = ref.copy()
    smeared[7:14, 7:14] *= 1.1  # the 3 px ring around the core gains 10 %
    smeared[10, 10] = 1000.0
    assert rs.bright_errors(smeared, ref, halo_px=3)["bright_halo"] == pytest.approx(0.1, rel=1e-5)


def test_walk_repeatability_follows_the_geometry():
    w, h, fov = 64, 40, 78.0
    fx, _, cx, cy = scenes.intrinsics(w, h, fov)
    depth = np.full((h, w), 5.0, np.float32)
    # camera looking along +z of the world (identity pose), points on the optical axis plane z = 5
    pa = np.array([[32.0, 20.0], [20.0, 10.0], [40.0, 30.0]])
    pa_ray = np.stack([(pa[:, 0] - cx) / fx, (pa[:, 1] - cy) / fx, np.ones(3)], -1)
    depth_at = 5.0 * np.linalg.norm(pa_ray, axis=1)  # ray distance to the plane z = 5
    for (u, v), d in zip(pa.astype(int), depth_at):
        depth[v, u] = d
    pose_a = np.eye(4)
    pose_b = np.eye(4)
    pose_b[0, 3] = 0.5  # 50 cm to the right: points move left by fx * 0.5 / 5 px
    shift = fx * 0.5 / 5.0
    moved = pa - [shift, 0.0]
    assert rs.walk_repeatability(pa, depth, pose_a, pose_b, moved, width=w, height=h, fov_deg=fov) == 1.0
    assert shift > 1.5
    assert rs.walk_repeatability(pa, depth, pose_a, pose_b, pa, width=w, height=h, fov_deg=fov) == 0.0
    sky = np.zeros_like(depth)
    assert np.isnan(rs.walk_repeatability(pa, sky, pose_a, pose_b, pa, width=w, height=h, fov_deg=fov))


def test_speedups_interpolate_and_flag_extrapolation():
    rows = [{"scene": "s", "denoise": "off", "spp": s, "time_s": t, "rmse_pct": 10.0 * t ** -0.5}
            for s, t in ((1, 1.0), (4, 4.0), (16, 16.0))]
    rows += [{"scene": "s", "denoise": "oidn", "spp": 1, "time_s": 2.0, "rmse_pct": 2.5},
             {"scene": "s", "denoise": "oidn", "spp": 4, "time_s": 2.0, "rmse_pct": 1.25}]
    inside, beyond = rs.speedups(rows)
    assert inside["raw_time_same_error_s"] == pytest.approx(16.0) and not inside["extrapolated"]
    assert inside["speedup"] == pytest.approx(8.0)
    assert beyond["raw_time_same_error_s"] == pytest.approx(64.0) and beyond["extrapolated"]


def test_config_is_validated():
    with pytest.raises(ValidationError, match="reference_spp"):
        rs.RenderStudyConfig(spp_levels=(1, 64), reference_spp=64)
    with pytest.raises(ValidationError, match="unknown study scene"):
        rs.RenderStudyConfig(scenes=("nowhere",))
    with pytest.raises(ValidationError, match="three distinct"):
        rs.RenderStudyConfig(seeds=(1, 1, 2))
    assert rs.CONFIGS["full"].reference_spp >= 1024 and rs.CONFIGS["full"].spp_levels[-1] == 64


# ---------------------------------------------------------------------------------- end to end, tiny
@pytest.mark.render
def test_tiny_study_writes_table_plot_and_json(tmp_path):
    steps = []
    res = rs.run_render_study(tmp_path / "out", TINY, progress=steps.append, command="test")
    assert sum(steps) == rs.total_steps(TINY)
    assert [(r["spp"], r["denoise"]) for r in res["rows"]] == [
        (s, d) for s in (1, 2) for d in ("off", "oidn", "oidn-fast")]
    for r in res["rows"]:
        assert r["time_s"] > 0 and r["rmse_pct"] >= 0 and 0 <= r["repeat_seeds"] <= 1 and r["flicker_pct"] >= 0
    on = json.loads((tmp_path / "out" / "results.json").read_text())
    assert on["provenance"]["config"]["reference_spp"] == 8 and [(x["spp"], x["denoise"]) for x in on["speedups"]] == [
        (1, "oidn"), (1, "oidn-fast"), (2, "oidn"), (2, "oidn-fast")]
    assert on["texture"][0]["kp_met"] is None  # no real sequence: no verdict
    report = (tmp_path / "out" / "report.md").read_text()
    assert "| 2 | " in report and "static_lab" in report and report == rs.render_study_table(on) + "\n"
    assert (tmp_path / "out" / "time_vs_error.png").stat().st_size > 1000
    with pytest.raises(OutputExistsError, match="refusing to overwrite"):
        rs.run_render_study(tmp_path / "out", TINY)
    assert on["scenes"]["static_lab"]["reference_cached"] is False and "from the render cache" not in report


@pytest.mark.render
def test_a_cached_reference_is_reported_as_cached(tmp_path):
    cfg = replace(TINY, spp_levels=(1,), texture_scenes=(), cache_dir=str(tmp_path / "cache"))
    first = rs.run_render_study(tmp_path / "a", cfg)["scenes"]["static_lab"]
    second = rs.run_render_study(tmp_path / "b", cfg)["scenes"]["static_lab"]
    assert (first["reference_cached"], second["reference_cached"]) == (False, True)
    assert "Reference 8 spp (from the render cache, " in (tmp_path / "b" / "report.md").read_text()


@pytest.mark.render
def test_study_reports_the_denoiser_fallback(tmp_path, monkeypatch):
    dn._reset()
    monkeypatch.setitem(sys.modules, "pyoidn", None)
    try:
        with pytest.warns(dn.DenoiserUnavailableWarning):
            res = rs.run_render_study(tmp_path / "out", TINY)
    finally:
        monkeypatch.delitem(sys.modules, "pyoidn")
        dn._reset()
    assert "pyoidn" in res["scenes"]["static_lab"]["fallback"]
    assert {r["denoise_applied"] for r in res["rows"]} == {"off"}
    assert "OIDN fell back" in (tmp_path / "out" / "report.md").read_text()


def test_cli_turns_bad_input_into_one_line(tmp_path, capsys):
    assert rs.main([str(tmp_path / "x"), "--scenes", "nowhere", "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("render_study: unknown study scene") and err.count("\n") == 1


def test_exposim_validate_render_help_shows_the_defaults(capsys):
    from emulator.commands.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["validate", "render", "--help"])
    assert exc.value.code == 0
    out = " ".join(capsys.readouterr().out.split())
    full, quick = rs.CONFIGS["full"], rs.CONFIGS["quick"]
    assert "-o OUTPUT, --output OUTPUT" in out
    assert f"(default {full.width}x{full.height}; --quick {quick.width}x{quick.height})" in out
    assert f"(default {','.join(map(str, full.spp_levels))}; --quick {','.join(map(str, quick.spp_levels))})" in out
    assert f"(default {full.reference_spp}; --quick {quick.reference_spp})" in out


def test_exposim_validate_render_bad_scene_is_one_line(tmp_path, capsys):
    from emulator.commands.cli import main

    assert main(["validate", "render", "-o", str(tmp_path / "x"), "--scenes", "nowhere", "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("exposim validate: error: unknown study scene") and err.count("\n") == 1
    assert not (tmp_path / "x").exists()


@pytest.mark.render
def test_exposim_validate_render_runs_the_study(tmp_path, capsys):
    from emulator.commands.cli import main

    args = ["validate", "render", "-o", str(tmp_path / "out"), "--scenes", "static_lab", "--size", "24x16",
            "--spp", "1,2", "--reference-spp", "8", "--texture-scenes", "", "--real", str(tmp_path / "none"),
            "--cache-dir", "off", "--no-progress"]
    assert main(args) == 0
    res = json.loads((tmp_path / "out" / "results.json").read_text())
    assert res["provenance"]["experiment"] == (
        f"exposim validate render -o {tmp_path / 'out'} --scenes static_lab --size 24x16 --spp 1,2 "
        f"--reference-spp 8 --texture-scenes '' --real {tmp_path / 'none'}")
    assert [(r["spp"], r["denoise"]) for r in res["rows"]] == [
        (s, d) for s in (1, 2) for d in ("off", "oidn", "oidn-fast")]
    assert res["texture"] == [] and res["real"] == {"24x16": None}
    assert "wrote " + str(tmp_path / "out" / "results.json") in capsys.readouterr().out
    assert main(args) == 1  # an earlier results.json is never overwritten without --force
    assert "refusing to overwrite" in capsys.readouterr().err
