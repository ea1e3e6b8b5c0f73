"""Render presets (scenes.presets), weighted choice of lights (Scene.with_emitter_weights), their cache keys,
the live study's ``--render`` and the Pareto table of the render-noise measure."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import scenes
from scenes.cache import render_key
from scenes.denoise import DenoiseSettings, resolve_denoise
from scenes.errors import RenderError, SceneError
from scenes.presets import LEGACY_STUDY_PRESET, RENDER_PRESETS, parse_setting
from validation.render_study import balance as bal

ROOT = Path(__file__).resolve().parents[2]


pytestmark = pytest.mark.usefixtures("default_render_env")


def test_setting_strings_are_read_and_written_back():
    p = parse_setting("oidn@64/1024+sun=16,sky=0.5")
    assert (p.spp, p.denoise.name, p.denoise.aux_spp) == (64, "oidn", 1024)
    assert p.emitter_weights == (("sky", 0.5), ("sun", 16.0))  # sorted by light
    assert p.setting == "oidn@64/1024+sky=0.5,sun=16" and parse_setting(p.setting) == p.__class__(
        name=p.setting, spp=64, denoise=p.denoise, emitter_weights=p.emitter_weights)
    assert parse_setting("off@2+sun=1").emitter_weights == ()  # a weight of 1 is the default: not kept
    assert parse_setting("oidn-fast@2").setting == "oidn-fast@2"  # the preset's own aux spp is not repeated
    legacy = parse_setting(LEGACY_STUDY_PRESET)
    assert (legacy.spp, legacy.denoise, legacy.emitter_weights) == (8, resolve_denoise("oidn"), ())
    assert legacy.setting == "oidn@8"
    hq = RENDER_PRESETS["study-hq"]
    assert (hq.spp, hq.denoise.aux_spp, hq.denoise.quality) == (256, 1024, "high")
    for bad, words in (("oidn", "DENOISER@SPP"), ("oidn@8+", "DENOISER@SPP"), ("oidn@8+moon=2", "LIGHT=WEIGHT"),
                       ("oidn@8+sun=0", "LIGHT=WEIGHT"), ("oidn@8+sun=2,sun=3", "each once"),
                       ("oidn@8+sun=nan", "LIGHT=WEIGHT"), ("off@4/16", "needs a denoiser"), ("nlm@4", "unknown")):
        with pytest.raises(RenderError, match=words) as err:
            parse_setting(bad)
        assert "\n" not in str(err.value)


def test_emitter_weights_enter_the_key_only_when_set_and_reach_mitsuba():
    scene = scenes.get_scene("forest_winter")
    uniform = scene.with_emitter_weights({"sun": 1.0})
    assert uniform.emitter_weights == () and uniform.key_material() == scene.key_material()
    assert "emitter_weights" not in scene.key_material()  # the keys of every earlier render stay as they were
    weighted = scene.with_emitter_weights({"sun": 16, "area": 0.5})
    assert weighted.emitter_weights == (("area", 0.5), ("sun", 16.0))
    assert weighted.key_material()["emitter_weights"] == {"area": 0.5, "sun": 16.0}
    assert weighted.cache_token() != scene.cache_token() and weighted.params == scene.params
    pose = scene.default_pose()
    common = dict(width=8, height=6, spp=1, seed=0, fov_deg=70.0, variant="scalar_rgb")
    assert render_key(weighted, pose, **common)[0] != render_key(scene, pose, **common)[0]
    for bad in ({"moon": 2.0}, {"sun": 0.0}, {"sun": -1.0}, {"sun": float("inf")}, {"sun": True}, {"sun": "2"}):
        with pytest.raises(SceneError, match="emitter"):
            scene.with_emitter_weights(bad)
    from scenes.mitsuba_objects import scene_dict
    from scenes.variant import choose_variant, ensure_variant

    import mitsuba as mi

    variant = choose_variant()
    ensure_variant(variant)
    mi.set_variant(variant)
    d = scene_dict(weighted.describe(), dict(weighted.emitter_weights))
    assert d["sun"]["sampling_weight"] == 16.0 and "sampling_weight" not in d["sky"]
    plain = scene_dict(scene.describe())
    assert "sampling_weight" not in plain["sun"] and "sampling_weight" not in plain["sky"]


@pytest.mark.render
def test_weighted_lights_keep_the_mean_radiance():
    """The choice of light is unbiased: at 64 spp on 32x20 px the frame means agree within their noise."""
    scene = scenes.get_scene("forest_winter")
    pose = scene.trajectory(5.0).pose(2.0)
    kw = dict(width=32, height=20, spp=64, denoise="off", cache_dir=False)
    lum = np.array([0.2126, 0.7152, 0.0722])
    a = [scenes.render(scene, pose, seed=s, **kw) @ lum for s in (1, 2)]
    b = [scenes.render(scene.with_emitter_weights({"sun": 16}), pose, seed=s, **kw) @ lum for s in (1, 2)]
    # the frame mean's Monte Carlo error, from two seeds of each: |a - b| within 4 standard errors
    se = np.sqrt(np.var([x.mean() for x in a], ddof=1) + np.var([x.mean() for x in b], ddof=1) + 1e-12)
    assert abs(np.mean([x.mean() for x in a]) - np.mean([x.mean() for x in b])) <= max(4 * se, 0.01 * np.mean(a))
    assert not np.array_equal(a[0], b[0])  # another estimator: other noise


def test_the_live_study_takes_a_preset_and_keeps_earlier_records():
    from validation.live.cli import build_parser, command_line, config_from_args
    from validation.live.config import LiveError, config_from_dict

    args = build_parser().parse_args(["-o", "OUT", "--render", "oidn@32+sun=16"])
    cfg = config_from_args(args)
    assert (cfg.spp, cfg.denoise, cfg.emitter_weights) == (32, "oidn", (("sun", 16.0),))
    assert cfg.to_dict()["emitter_weights"] == {"sun": 16.0} and config_from_dict(cfg.to_dict()) == cfg
    assert "--render oidn@32+sun=16" in command_line(args, "exposim validate live")
    assert cfg.adaptive is None and "adaptive" not in cfg.to_dict()  # a setting without one replaces the default's
    plain = config_from_args(build_parser().parse_args(["-o", "OUT", "--render", "study-oidn8"]))
    d = plain.to_dict()  # the study's former renders record what they always did
    assert (d["spp"], d["denoise"]) == (8, "oidn") and "emitter_weights" not in d and "adaptive" not in d
    default = config_from_args(build_parser().parse_args(["-o", "OUT"]))
    assert (default.spp, default.denoise, default.emitter_weights, default.adaptive) == (
        64, "oidn-hq", (("sun", 16.0),), "x16:30%@32ms")  # the preset study-adaptive30
    quick = config_from_args(build_parser().parse_args(["-o", "OUT", "--quick", "--spp", "4"]))
    assert (quick.spp, quick.denoise, quick.emitter_weights, quick.adaptive) == (4, "oidn", (), None)
    adaptive = config_from_args(build_parser().parse_args(["-o", "OUT", "--render", "study-adaptive"]))
    assert (adaptive.spp, adaptive.denoise, adaptive.emitter_weights, adaptive.adaptive) == (
        64, "oidn-hq", (("sun", 16.0),), "x16:20%@32ms")
    hq = config_from_args(build_parser().parse_args(["-o", "OUT", "--render", "study-hq"]))
    assert (hq.spp, hq.denoise) == (256, "oidn-hq")
    for argv, words in ((["--render", "oidn@8", "--spp", "4"], "not both"),
                        (["--render", "oidn@8/512"], "named one"), (["--render", "oidn@8+moon=1"], "LIGHT=WEIGHT")):
        with pytest.raises(LiveError, match=words):
            config_from_args(build_parser().parse_args(["-o", "OUT", *argv]))


def _result(scene, setting, d8, d32, seconds, ratio):
    ex = {e: {"difference": d} for e, d in (("8", d8), ("32", d32))}
    return {"scene": scene, "setting": setting, "exposures": ex, "seconds_per_sweep": seconds,
            "ratio_to_baseline": ratio, "tolerance_points": 3.0}


def test_the_pareto_table_marks_the_front_and_the_goal():
    rows = [_result("a", "cheap", (-10.0, -11.0, -9.0), (-9.0, -10.0, -8.0), 2.0, 1.0),
            _result("a", "dear", (-1.0, -2.0, 0.0), (-2.0, -2.9, -1.1), 30.0, 15.0),
            _result("a", "waste", (-12.0, -13.0, -11.0), (-9.0, -9.5, -8.5), 20.0, 10.0),
            _result("a", "edge", (-1.0, -3.5, 1.5), (0.0, -1.0, 1.0), 29.0, 14.5)]
    lines = bal.pareto_table(rows).splitlines()
    cells = {ln.split("|")[2].strip(): [c.strip() for c in ln.split("|")[1:-1]] for ln in lines[2:]}
    assert cells["`cheap`"][-1] == "front" and cells["`dear`"][-1] == "" and cells["`waste`"][-1] == ""
    assert cells["`edge`"][-1] == "front"  # as close as 'dear' at its worst exposure, and cheaper
    assert cells["`dear`"][4] == "yes" and cells["`edge`"][4] == "no"  # -3.5 leaves the goal
    assert cells["`dear`"][2] == "-1.0 [-2.0, +0.0]" and cells["`dear`"][6] == "15.00"
    # a setting read from the render cache was not timed: no seconds, no ratio, never on the front, and the
    # others' front is judged without it
    cached = bal.pareto_table(rows + [_result("a", "cached", (0.0, -1.0, 1.0), (0.0, -1.0, 1.0), None, None)])
    cells = {ln.split("|")[2].strip(): [c.strip() for c in ln.split("|")[1:-1]] for ln in cached.splitlines()[2:]}
    assert cells["`cached`"][5:] == ["cached", "", ""] and cells["`cached`"][4] == "yes"
    assert cells["`cheap`"][-1] == "front" and cells["`edge`"][-1] == "front"


@pytest.mark.render
def test_the_script_measures_several_scenes_against_a_baseline_in_one_run(tmp_path):
    out = tmp_path / "p.json"
    p = subprocess.run([sys.executable, str(ROOT / "scripts" / "render_noise_balance.py"), "-o", str(out),
                        "off@2+sun=16", "--size", "48x32", "--sweeps", "0,2", "--scenes", "forest_winter,sun_glare",
                        "--baseline", "off@1", "--bias-reference", "off@4", "--cache-dir", str(tmp_path / "c")],
                       capture_output=True, text=True, cwd=ROOT,
                       env={"PYTHONPATH": str(ROOT), "EXPOSIM_MITSUBA_VARIANT": "scalar_rgb"})
    assert p.returncode == 0, p.stderr
    doc = json.loads(out.read_text())
    got = [(r["scene"], r["setting"]) for r in doc["results"]]
    assert got == [("forest_winter", "off@1"), ("forest_winter", "off@2+sun=16"), ("sun_glare", "off@1"),
                   ("sun_glare", "off@2+sun=16")]  # the baseline first on each scene
    for r in doc["results"]:
        base = next(x for x in doc["results"] if x["scene"] == r["scene"] and x["setting"] == "off@1")
        assert r["ratio_to_baseline"] == pytest.approx(r["seconds_per_sweep"] / base["seconds_per_sweep"])
        rows = r["radiance"]["per_pose"]
        assert [x["sweep"] for x in rows] == [0, 22, 44]
        for x in rows:
            assert x["difference_percent"] == pytest.approx(100 * (x["mean"] / x["reference_mean"] - 1))
            if x["sun_excluded_pixels"] == 0:  # nothing above the pass-through level: the same figure
                assert x["difference_percent_sun_excluded"] == pytest.approx(x["difference_percent"])
    assert doc["results"][1]["emitter_weights"] == {"sun": 16.0} and "emitter_weights" not in doc["results"][0]
    # each setting renders into a folder of its own (no raw render shared, so each is timed whole)
    assert sorted(x.name for x in (tmp_path / "c").iterdir()) == ["forest_winter-0", "forest_winter-1", "reference",
                                                                  "sun_glare-0", "sun_glare-1"]
    assert doc["command"].endswith("--cache-dir CACHE")  # no path of this machine in the record
    table = out.with_suffix(".md").read_text().splitlines()
    assert len(table) == 2 + 4 and "mean radiance vs reference" in table[0]
    again = subprocess.run([sys.executable, str(ROOT / "scripts" / "render_noise_balance.py"), "-o", str(out),
                            "off@1"], capture_output=True, text=True, cwd=ROOT, env={"PYTHONPATH": str(ROOT)})
    assert again.returncode == 2 and "exists" in again.stderr


def test_denoise_settings_of_a_preset_are_the_named_ones():
    assert RENDER_PRESETS[LEGACY_STUDY_PRESET].denoise == DenoiseSettings(name="oidn")
    for preset in RENDER_PRESETS.values():
        assert parse_setting(preset.name) is preset and preset.summary
        assert parse_setting(preset.setting).denoise == preset.denoise


def test_adaptive_sampling_is_read_and_written_back_and_refused_when_malformed():
    from scenes.adaptive import DEFAULT_TILE, AdaptiveSampling

    p = parse_setting("oidn-hq@64+sun=16~x4:25%")
    assert (p.spp, p.denoise.name, p.emitter_weights) == (64, "oidn-hq", (("sun", 16.0),))
    assert p.adaptive == AdaptiveSampling(4, 0.25, DEFAULT_TILE) and p.setting == "oidn-hq@64+sun=16~x4:25%"
    assert p.record()["adaptive"] == {"factor": 4, "fraction": 0.25, "tile": 30, "floor": 0.05, "scheme": 1}
    q = parse_setting("off@16~x2:12.5%/60")
    assert (q.adaptive.factor, q.adaptive.fraction, q.adaptive.tile) == (2, 0.125, 60)
    for text in ("oidn@8~x3:50%", "off@4~x2:100%/8", q.setting, p.setting):
        assert parse_setting(parse_setting(text).setting) == parse_setting(text)
    assert parse_setting("oidn@8").adaptive is None and "adaptive" not in parse_setting("oidn@8").record()
    for bad, words in (("oidn@8~", "~xFACTOR:PERCENT%"), ("oidn@8~x1:25%", "factor"), ("oidn@8~x4:0%", "fraction"),
                       ("oidn@8~x4:25", "~xFACTOR"), ("oidn@8~4:25%", "~xFACTOR"), ("oidn@8~x4:25%/2", "tile")):
        with pytest.raises(RenderError, match=words) as err:
            parse_setting(bad)
        assert repr(bad) in str(err.value)
    from validation.live.cli import build_parser, config_from_args

    # the live study carries it (validation/live tests follow it into the dataset)
    cfg = config_from_args(build_parser().parse_args(["-o", "OUT", "--render", "oidn@8~x4:25%"]))
    assert (cfg.spp, cfg.denoise, cfg.adaptive) == (8, "oidn", "x4:25%")


def test_adaptive_sampling_enters_the_cache_key_only_when_set():
    from scenes.adaptive import AdaptiveSampling

    scene = scenes.get_scene("forest_winter")
    pose = scene.default_pose()
    common = dict(width=8, height=6, spp=4, seed=0, fov_deg=70.0, variant="scalar_rgb")
    key, material = render_key(scene, pose, **common)
    assert "adaptive" not in material and render_key(scene, pose, adaptive=None, **common)[0] == key
    k4, m4 = render_key(scene, pose, adaptive=AdaptiveSampling(4, 0.25).key_material(), **common)
    assert k4 != key and m4["adaptive"]["factor"] == 4
    assert render_key(scene, pose, adaptive=AdaptiveSampling(4, 0.5).key_material(), **common)[0] != k4


def test_tiles_are_chosen_where_the_variance_against_radiance_is_highest():
    from scenes.adaptive import select_tiles, tile_crops, tile_scores

    rng = np.random.default_rng(7)
    mean = np.full((20, 30, 3), 2.0)
    noise = np.full((20, 30, 1), 0.01)
    noise[0:10, 20:30] = 0.5   # tile (0, 2): the noisiest
    noise[10:20, 0:10] = 0.2   # tile (1, 0): next
    mean[10:20, 10:20] = 0.01  # tile (1, 1): dark, its noise is large against its radiance but not against the
    noise[10:20, 10:20] = 0.02  # floor (5 % of the frame's mean): without the floor it would come second
    d = rng.choice([-1.0, 1.0], size=(20, 30, 1)) * noise  # random signs, known size
    scores = tile_scores(mean + d, mean - d, 10)
    assert scores.shape == (2, 3)
    assert np.array_equal(select_tiles(scores, 1 / 6), [[False, False, True], [False, False, False]])
    assert np.array_equal(select_tiles(scores, 2 / 6), [[False, False, True], [True, False, False]])
    # variance (2 d)^2 / 4 = d^2 over luminance: the scores are the constructed ratios
    assert scores[0, 2] == pytest.approx(0.25 / 2.0) and scores[1, 0] == pytest.approx(0.04 / 2.0)
    floor = 0.05 * (5 * 2.0 + 0.01) / 6
    assert scores[1, 1] == pytest.approx(0.0004 / floor) and scores[0, 0] == pytest.approx(0.0001 / 2.0)
    assert np.array_equal(select_tiles(np.zeros((2, 2)), 0.5), [[True, True], [False, False]])  # ties: row-major
    mask = np.array([[True, False, True], [False, False, False], [False, True, False]])
    assert tile_crops(mask, 10, 25, 28) == [(0, 0, 25, 10), (10, 20, 10, 8)]  # clipped to the frame
    # merged into their bounding box (25 x 28) when that adds fewer pixels (370) than one more render is worth
    assert tile_crops(mask, 10, 25, 28, merge_px=370) == [(0, 0, 25, 10), (10, 20, 10, 8)]
    assert tile_crops(mask, 10, 25, 28, merge_px=371) == [(0, 0, 25, 28)]


def test_a_clipping_exposure_is_read_back_keyed_and_refused_when_malformed():
    from scenes.adaptive import AdaptiveSampling, render_adaptive
    from scenes.camera import DEFAULT_SATURATE_MS

    p = parse_setting("oidn-hq@64+sun=16~x16:20%@32ms")
    assert p.adaptive == AdaptiveSampling(16, 0.2, 30, 32.0) and p.adaptive.text == "x16:20%@32ms"
    assert parse_setting(p.setting) == p and parse_setting("off@8~x2:50%/10@8.5ms").adaptive.text == "x2:50%/10@8.5ms"
    # the key grows only when clipping is asked for: renders keyed before keep their keys
    assert p.record()["adaptive"] == {"factor": 16, "fraction": 0.2, "tile": 30, "floor": 0.05, "scheme": 1,
                                      "clip_ms": 32.0, "saturate_ms": DEFAULT_SATURATE_MS}
    assert AdaptiveSampling(16, 0.2).key_material() == {"factor": 16, "fraction": 0.2, "tile": 30, "floor": 0.05,
                                                        "scheme": 1}
    # the luminance that fills the well at 32 ms when the reference radiance fills it at 1 ms
    assert p.adaptive.clip_luminance(320.0) == pytest.approx(320.0 * DEFAULT_SATURATE_MS / 32.0)
    assert AdaptiveSampling(4, 0.25).clip_luminance(320.0) == float("inf")
    for bad, words in (("oidn@8~x4:25%@32", "MSms"), ("oidn@8~x4:25%@0ms", "clip_ms"),
                       ("oidn@8~x4:25%@nanms", "clip_ms"), ("oidn@8~x4:25%@-8ms", "clip_ms")):
        with pytest.raises(RenderError, match=words) as err:
            parse_setting(bad)
        assert repr(bad) in str(err.value)
    with pytest.raises(RenderError, match="reference radiance"):  # before any render is paid for
        render_adaptive(lambda *a: pytest.fail("rendered"), p.adaptive, width=8, height=8, spp=4, seed=0)


def test_a_clipping_score_sends_the_samples_to_the_shade_the_sensor_sees():
    from scenes.adaptive import select_tiles, tile_scores

    rng = np.random.default_rng(3)
    mean = np.full((20, 30, 3), 1.0)
    noise = np.full((20, 30, 1), 0.05)
    mean[0:10, 0:10], noise[0:10, 0:10] = 400.0, 300.0  # tile (0, 0): a sun disk, far above the clip level
    noise[10:20, 20:30] = 0.5  # tile (1, 2): noisy shade
    d = rng.choice([-1.0, 1.0], size=(20, 30, 1)) * noise
    a, b = mean + d, mean - d
    plain, clipped = tile_scores(a, b, 10), tile_scores(a, b, 10, clip=10.0)
    assert np.array_equal(select_tiles(plain, 1 / 6), [[True, False, False], [False, False, False]])
    assert np.array_equal(select_tiles(clipped, 1 / 6), [[False, False, False], [False, False, True]])
    # both passes clamp to the same value: the disk's tile has no variance left; the shade's is d^2 over its
    # radiance, and its floor (5 % of the frame's mean) comes from the clamped frame too: the disk no longer
    # lifts it above the shade (plain: 0.05 * (400 * 100 + 1 * 500) / 600 = 3.375 per pixel)
    assert clipped[0, 0] == 0.0 and clipped[1, 2] == pytest.approx(0.25)
    assert plain[1, 2] == pytest.approx(0.25 / (0.05 * (400.0 * 100 + 500) / 600))
    assert np.array_equal(tile_scores(a, b, 10, clip=float("inf")), plain)


def test_adaptive_render_is_the_spp_weighted_mean_of_its_passes(monkeypatch):
    from scenes import adaptive

    sr = sys.modules["scenes.render"]  # the module (scenes.render is also the function)

    passes = []
    real = adaptive.render_adaptive

    def recording(render_pass, spec, **kw):
        def rec(n, s, crop):
            img = render_pass(n, s, crop)
            passes.append((img, n, crop, s))
            return img
        return real(rec, spec, **kw)

    monkeypatch.setattr(sr, "render_adaptive", recording)
    scene = scenes.get_scene("forest_winter")
    pose = scene.trajectory(5.0).pose(2.0)
    kw = dict(width=24, height=16, spp=4, seed=5, denoise="off", cache_dir=False, variant="scalar_rgb")
    img = scenes.render(scene, pose, adaptive="x3:25%/8", **kw)
    assert [p[1] for p in passes[:2]] == [2, 2] and passes[0][2] is None and passes[1][2] is None
    crops = [p[2] for p in passes[2:]]
    assert crops and all(p[1] == 8 for p in passes[2:])  # (3 - 1) x 4 more samples in the crops
    assert sum(c[2] * c[3] for c in crops) >= 0.25 * 24 * 16 and len({p[3] for p in passes}) == len(passes)
    acc, cnt = np.zeros((16, 24, 3)), np.zeros((16, 24, 1))
    for image, n, crop, _ in passes:
        x, y, w, h = (0, 0, 24, 16) if crop is None else crop
        acc[y:y + h, x:x + w] += n * image
        cnt[y:y + h, x:x + w] += n
    np.testing.assert_allclose(img, acc / cnt, rtol=1e-6)
    again = scenes.render(scene, pose, adaptive="x3:25%/8", **kw)
    assert np.array_equal(img, again)  # deterministic seeds: the same bytes
    x, y, w, h = crops[0]
    assert passes[2][0].shape == (h, w, 3)
    passes.clear()  # a clipping score gets the scene's reference radiance from the render path
    seen = []
    monkeypatch.setattr(sr, "render_adaptive",
                        lambda render_pass, spec, **kw: seen.append(kw["reference_radiance"]) or recording(render_pass, spec, **kw))
    clipped = scenes.render(scene, pose, adaptive="x3:25%/8@32ms", **kw)
    assert seen == [scene.reference_radiance] and clipped.shape == img.shape and np.all(np.isfinite(clipped))
