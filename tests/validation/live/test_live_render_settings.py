"""The live study's render settings: its defaults, the denoiser it records, and renders sized for live shots."""

from __future__ import annotations

import json

import numpy as np
import pytest

import scenes
from emulator.errors import ExposimError
from scenes.presets import LEGACY_STUDY_PRESET
from validation.live.config import (CONFIGS, LEGACY_STUDY_DENOISE, STUDY_ADAPTIVE, STUDY_DENOISE, STUDY_EMITTER_WEIGHTS,
                                    STUDY_HEIGHT, STUDY_PRESET, STUDY_RENDER_PER, STUDY_SPP, STUDY_WIDTH, LiveConfig,
                                    LiveError, config_from_dict)


def test_the_defaults_are_the_study_render_settings(monkeypatch):
    from scenes.denoise import resolve_denoise
    from scenes.presets import RENDER_PRESETS

    monkeypatch.delenv("EXPOSIM_DENOISE", raising=False)
    cfg = LiveConfig()
    assert (cfg.width, cfg.height, cfg.spp, cfg.denoise, cfg.render_per) == (480, 300, 64, "oidn-hq", "cycle")
    assert (STUDY_WIDTH, STUDY_HEIGHT, STUDY_SPP, STUDY_DENOISE, STUDY_RENDER_PER) == (480, 300, 64, "oidn-hq",
                                                                                         "cycle")
    # the render defaults are the preset's, field by field (kept as literals so that --help imports no scenes)
    preset = RENDER_PRESETS[STUDY_PRESET]
    assert STUDY_PRESET == "study-adaptive30"
    assert (preset.spp, preset.denoise.name, preset.emitter_weights, preset.adaptive.text) == (
        STUDY_SPP, STUDY_DENOISE, STUDY_EMITTER_WEIGHTS, STUDY_ADAPTIVE)
    assert preset.setting == "oidn-hq@64+sun=16~x16:30%@32ms" and preset.denoise == resolve_denoise("oidn-hq")
    assert (cfg.emitter_weights, cfg.adaptive) == ((("sun", 16.0),), "x16:30%@32ms")
    d = cfg.to_dict()
    assert (d["denoise"], d["renders"], d["emitter_weights"], d["adaptive"]) == (
        "oidn-hq", 40 * 2 * 4, {"sun": 16.0}, "x16:30%@32ms")
    legacy = RENDER_PRESETS[LEGACY_STUDY_PRESET]  # the renders of every study before 2026-12, still by name
    assert legacy.setting == "oidn@8" and legacy.denoise == resolve_denoise("oidn")
    # --quick, a pipeline check, renders as the legacy preset
    quick = CONFIGS["quick"]
    assert (quick.spp, quick.denoise, quick.emitter_weights, quick.adaptive) == (
        legacy.spp, legacy.denoise.name, legacy.emitter_weights, legacy.adaptive)
    # a record without lights or an adaptive count (every study before 2026-12) rendered without them, and one
    # without a denoiser (before --denoise) reads as it did before the default moved
    old = config_from_dict({"spp": 8, "denoise": "oidn", "render_per": "cycle"})
    assert (old.emitter_weights, old.adaptive) == ((), None)
    assert "emitter_weights" not in old.to_dict() and "adaptive" not in old.to_dict()
    assert config_from_dict({"spp": 8, "render_per": "shot"}).denoise == LEGACY_STUDY_DENOISE == "oidn"
    monkeypatch.setenv("EXPOSIM_DENOISE", "oidn-fast")  # the environment names the default, resolved and recorded
    assert LiveConfig().denoise == "oidn-fast" and LiveConfig(denoise="off").denoise == "off"
    monkeypatch.setenv("EXPOSIM_DENOISE", "median")
    with pytest.raises(LiveError, match=r"\$EXPOSIM_DENOISE='median' is not a denoiser"):
        LiveConfig()
    monkeypatch.delenv("EXPOSIM_DENOISE")
    with pytest.raises(LiveError, match="denoise must be one of oidn, oidn-fast, oidn-hq, off, got 'nlm'"):
        LiveConfig(denoise="nlm")
    # records from before the options: every shot rendered; a recorded denoiser is kept
    assert config_from_dict({}).render_per == "shot"
    assert config_from_dict({"denoise": "oidn-fast", "render_per": "cycle"}).denoise == "oidn-fast"


def test_the_denoise_option_reaches_the_configuration_and_the_command(monkeypatch):
    from validation.live.cli import build_parser, command_line, config_from_args

    monkeypatch.delenv("EXPOSIM_DENOISE", raising=False)
    args = build_parser().parse_args(["-o", "/tmp/x", "--denoise", "oidn-fast"])
    assert config_from_args(args).denoise == "oidn-fast"
    assert "--denoise oidn-fast" in command_line(args, "exposim validate live")
    assert config_from_args(build_parser().parse_args(["-o", "/tmp/x"])).denoise == STUDY_DENOISE
    with pytest.raises(SystemExit):
        build_parser().parse_args(["-o", "/tmp/x", "--denoise", "nlm"])


@pytest.mark.render
def test_a_walk_sized_for_the_clamp_range_renders_nothing_for_long_live_shots(tmp_path):
    from scenes.synthesize import synthesize
    from scenes.walkshots import walk_radiance

    scene = scenes.get_scene("forest_summer")
    kw = dict(n_cycles=1, width=32, height=20, spp=1, denoise="off", stereo=False, render_per="cycle")
    counts = {}
    for window in (None, 50.0):
        cache = tmp_path / f"cache-{window}"
        out = synthesize(scene, tmp_path / f"ds-{window}", cache_dir=cache, max_window_ms=window, **kw)
        meta = json.loads((out / "exposim.json").read_text())
        assert meta["source"]["render"]["blur_shots"]["max_window_ms"] == (window or 32.0)
        live = walk_radiance(out, scene, cache_dir=cache)
        last = sorted(int(p.stem) for p in (out / "camera_left" / "32.0").glob("*.png"))[-1]  # the sweep's last shot
        before = len(list(cache.rglob("*.exr")))
        img = live(last, "left", 50.0)
        assert img.shape == (20, 32, 3) and np.all(np.isfinite(img))
        counts[window] = len(list(cache.rglob("*.exr"))) - before
    assert counts[None] >= 1 and counts[50.0] == 0  # sized for 32 ms: a render of its own; for 50 ms: none
    with pytest.raises(ExposimError, match=r"max_window_ms must be a number >= the longest exposure \(32 ms\)"):
        synthesize(scene, tmp_path / "bad", cache_dir=tmp_path / "c", max_window_ms=20.0, **kw)
    assert not (tmp_path / "bad").exists()


def test_an_adaptive_sample_count_is_configured_recorded_only_when_set_and_refused_when_malformed(monkeypatch):
    from validation.live.cli import build_parser, config_from_args
    from validation.live.preregistration import preregistration

    monkeypatch.delenv("EXPOSIM_DENOISE", raising=False)
    plain = LiveConfig(adaptive=None)
    assert plain.adaptive is None and "adaptive" not in plain.to_dict()  # earlier records stay as they were
    assert config_from_dict(plain.to_dict()) == plain
    cfg = config_from_args(build_parser().parse_args(["-o", "/tmp/x", "--render", "oidn-hq@64+sun=16~x16:20%@32ms"]))
    assert (cfg.spp, cfg.denoise, dict(cfg.emitter_weights), cfg.adaptive) == (64, "oidn-hq", {"sun": 16.0},
                                                                                "x16:20%@32ms")
    assert cfg.to_dict()["adaptive"] == "x16:20%@32ms" and config_from_dict(cfg.to_dict()) == cfg
    assert LiveConfig(adaptive="x16:20%/30@32.0ms").adaptive == "x16:20%@32ms"  # one canonical text
    assert preregistration(cfg, replicates=2)["render"]["adaptive"] == "x16:20%@32ms"
    assert "adaptive" not in preregistration(plain, replicates=2)["render"]
    for bad in ("x1:20%", "16:20%", "x4:25%@32"):
        with pytest.raises(LiveError, match="adaptive"):
            LiveConfig(adaptive=bad)
    text = "".join(build_parser().format_help().split())  # argparse formats help with %: the setting's % escaped
    assert "~xFACTOR:PERCENT%[@MSms]" in text and "study-adaptive30:thedefault" in text


@pytest.mark.render
def test_a_walk_with_an_adaptive_sample_count_records_it_and_its_live_shots_render_with_it(tmp_path, monkeypatch):
    import sys

    from scenes.synthesize import synthesize
    from scenes.walkshots import walk_radiance

    sr = sys.modules["scenes.render"]
    specs = []
    real = sr.render_adaptive

    def recording(render_pass, spec, **kw):
        specs.append(spec.text)
        return real(render_pass, spec, **kw)

    monkeypatch.setattr(sr, "render_adaptive", recording)
    scene = scenes.get_scene("forest_summer")
    kw = dict(n_cycles=1, width=32, height=20, spp=4, denoise="off", stereo=False, render_per="cycle")
    cache = tmp_path / "cache"
    out = synthesize(scene, tmp_path / "ds", cache_dir=cache, adaptive="x2:50%/10@32ms", **kw)
    assert json.loads((out / "exposim.json").read_text())["source"]["render"]["adaptive"] == "x2:50%/10@32ms"
    assert specs and set(specs) == {"x2:50%/10@32ms"}
    plain = synthesize(scene, tmp_path / "plain", cache_dir=tmp_path / "c2", **kw)
    assert "adaptive" not in json.loads((plain / "exposim.json").read_text())["source"]["render"]
    # the live shots are rebuilt from the description: the writer's adaptive renders, read from the cache
    specs.clear()
    live = walk_radiance(out, scene, cache_dir=cache)
    first = sorted(int(p.stem) for p in (out / "camera_left" / "1.0").glob("*.png"))[0]
    before = sorted(cache.rglob("*.exr"))
    img = live(first, "left", 1.0)
    assert img.shape == (20, 32, 3) and np.all(np.isfinite(img))
    assert sorted(cache.rglob("*.exr")) == before and not specs  # cache hits: the same key, nothing rendered
    with pytest.raises(ExposimError, match="expected ~xFACTOR"):
        synthesize(scene, tmp_path / "bad", cache_dir=tmp_path / "c3", adaptive="x2", **kw)
    assert not (tmp_path / "bad").exists()
