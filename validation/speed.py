"""Speed against error: time per image and RMSE for each way of producing an image.

Emulation paths, all from the same noiseless brackets against the same noiseless ground
truth (HigherNoSat's bracket at each exposure):

``lut``
    :func:`emulator.core.emulate`: one gather through the cached per-ratio table (rounded DN);
``lut+build``
    the same with the table built for the ratio first (first use of a ratio);
``float``
    float64 per pixel, no table and no rounding: ``f(k g(raw))`` through ``np.interp``;
``reference``
    the published reference code's per-pixel interpolation reproduced in numpy: float32
    ``np.interp`` through the 256 pcalib knots scaled by 16 with the end knots forced to 0
    and 4095 (DESIGN.md, "How the table is read matters"), clamped, not rounded.

Ground-truth rendering: one render per spp level (uncached, after a warm-up render), its
noiseless captures compared with those of a high-spp reference render.

Timings are wall-clock medians on this machine (not deterministic); emulation timings are
per full BorealHDR frame (1920 x 1200, the bracket tiled) and per study-size image.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from emulator.core.emulate import emulate, validity_mask
from emulator.io.pcalib import PCALIB_TABLE_TOP
from emulator.core.response import CameraResponse
from emulator.core.select import higher_no_sat, saturated_fraction
from validation.common import (
    BRACKETS_MS,
    RESPONSES,
    Progress,
    ValidationError,
    capture,
    gt_exposures,
    make_camera,
    rmse_dn,
    static_radiance,
    study_scene,
    summary_stats,
    to_percent,
)

__all__ = ["SpeedConfig", "run_speed", "emulate_float", "emulate_reference", "EMULATION_PATHS"]

#: Full BorealHDR frame (rows, cols) used for the emulation timings.
FULL_FRAME = (1200, 1920)


def emulate_float(raw: np.ndarray, source_ms: float, target_ms: float, response: CameraResponse) -> np.ndarray:
    """Float path: ``f(k g(raw))`` per pixel in float64, clipped to the levels, not rounded."""
    k = float(target_ms) / float(source_ms)
    out = response.forward(k * response.inverse(raw.astype(np.float64)))
    return np.clip(out, response.black_level, response.white_level)


def reference_knots(response: CameraResponse, n: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """(DN knots, exposure knots) as the reference code builds them.

    ``n`` samples of g evenly over DN 0..4095 (the pcalib samples themselves when the response
    came from a pcalib file), scaled by 16, the first set to 0 and the last to 4095.
    """
    top = float(PCALIB_TABLE_TOP)
    dn = np.linspace(0.0, top, n)
    if response.knots is not None and response.knots.size == n:
        g = np.asarray(response.knots, dtype=np.float64)
    else:
        g = response.inverse(np.minimum(dn, response.white_level)) / response.g[response.white_level] * 255.0
    irr = (g * 16.0).astype(np.float32)
    irr[0] = 0.0
    irr[-1] = top
    return dn.astype(np.float32), irr


def emulate_reference(raw: np.ndarray, source_ms: float, target_ms: float, knots) -> np.ndarray:
    """The reference code's per-pixel emulation in numpy (float32 result, not rounded)."""
    dn, irr = knots
    k = np.float32(target_ms / source_ms)
    rad = np.interp(raw.astype(np.float32), dn, irr).astype(np.float32)
    rad = np.clip(rad * k, 0.0, np.float32(PCALIB_TABLE_TOP))
    return np.interp(rad, irr, dn).astype(np.float32)


EMULATION_PATHS = ("lut", "lut+build", "float", "reference")


@dataclass(frozen=True)
class SpeedConfig:
    """Size of the speed study."""

    scenes: tuple = ("static_lab", "forest_winter")
    response: str = "borealhdr"
    n_exposures: int = 60
    width: int = 96
    height: int = 60
    spp: int = 64
    spp_levels: tuple = (1, 4, 16, 64)
    reference_spp: int = 1024
    timing_repeats: int = 5
    timing_exposures: int = 8
    brackets_ms: tuple = BRACKETS_MS
    cache_dir: str | None = None

    @classmethod
    def quick(cls, **overrides) -> "SpeedConfig":
        base = dict(scenes=("static_lab",), n_exposures=12, width=48, height=30, spp=16, spp_levels=(1, 4, 16),
                    reference_spp=64, timing_repeats=2, timing_exposures=3)
        base.update(overrides)
        return cls(**base)

    def __post_init__(self) -> None:
        for s in self.scenes:
            study_scene(s)
        if self.response not in RESPONSES:
            raise ValidationError(f"unknown camera response {self.response!r}; choose from {', '.join(RESPONSES)}")
        if max(self.spp_levels) >= self.reference_spp:
            raise ValidationError("reference_spp must exceed every spp level")

    def n_steps(self) -> int:
        return len(self.scenes) * (1 + len(EMULATION_PATHS) + len(self.spp_levels) + 1)

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def _time(fn, repeats: int) -> float:
    """Median wall-clock seconds of ``fn()`` over ``repeats`` runs (after one warm-up)."""
    fn()
    ts = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def _tile(img: np.ndarray, shape) -> np.ndarray:
    reps = (-(-shape[0] // img.shape[0]), -(-shape[1] // img.shape[1]))
    return np.ascontiguousarray(np.tile(img, reps)[: shape[0], : shape[1]])


def _render_rows(key: str, config: SpeedConfig, camera, cases: list, tick) -> list[dict]:
    """Ground-truth renders of one scene at each of the study's spp against a high-spp reference (uncached
    renders): seconds per render and the RMSE of their captures at the ``cases``' exposures."""
    import scenes

    white, black = int(camera.white_level), int(camera.black_level)
    rows = []
    spec = study_scene(key)
    scene = spec.build()
    pose = spec.pose(scene)
    kw = dict(width=config.width, height=config.height, seed=0, cache_dir=False)
    ref = scenes.render(scene, pose, spp=config.reference_spp, **{**kw, "cache_dir": config.cache_dir})
    tick(1)
    ref_caps = {t: capture(ref, t, camera, seed=0, noise=False) for t, _, _ in cases}
    for spp in config.spp_levels:
        scenes.render(scene, pose, spp=spp, **{**kw, "seed": 1})  # warm-up: kernels compiled for this spp
        t0 = time.perf_counter()
        img = scenes.render(scene, pose, spp=spp, **kw)
        dt = time.perf_counter() - t0
        errs = [to_percent(rmse_dn(capture(img, t, camera, seed=0, noise=False), ref_caps[t]), white, black)
                for t, _, _ in cases]
        rows.append({"scene": key, "spp": int(spp), "seconds": dt, "rmse": summary_stats(errs)})
        tick(1)
    return rows


def _speed_table(config: SpeedConfig, errors: dict, times_full: dict, times_small: dict, render_rows: list) -> list:
    """One row per emulation path (median times, RMSE) and per render spp (median seconds, RMSE)."""
    table = []
    for name in EMULATION_PATHS:
        table.append({
            "config": name, "kind": "emulation",
            "ms_per_full_frame": 1000.0 * float(np.median(times_full[name])),
            "ms_per_study_image": 1000.0 * float(np.median(times_small[name])),
            "rmse_all": summary_stats(errors[name]["all"]), "rmse_valid": summary_stats(errors[name]["valid"]),
        })
    for spp in config.spp_levels:
        sel = [r for r in render_rows if r["spp"] == spp]
        table.append({
            "config": f"render spp {spp}", "kind": "render", "spp": int(spp),
            "ms_per_study_image": 1000.0 * float(np.median([r["seconds"] for r in sel])),
            "rmse_all": summary_stats([r["rmse"]["median"] for r in sel]),
        })
    return table


def run_speed(config: SpeedConfig, *, progress=None) -> dict:
    """Run the speed study; returns ``{"results": JSON-ready dict, "arrays": {...}}``."""
    tick = Progress(progress)
    camera = make_camera(config.response, width=config.width, height=config.height)
    response = camera.response
    white, black = int(camera.white_level), int(camera.black_level)
    lv = dict(white_level=white, black_level=black)
    knots = reference_knots(response)
    exposures = gt_exposures(config.n_exposures)
    errors = {p: {"all": [], "valid": []} for p in EMULATION_PATHS}
    times_full = {p: [] for p in EMULATION_PATHS}
    times_small = {p: [] for p in EMULATION_PATHS}
    render_rows = []
    for key in config.scenes:
        radiance = static_radiance(key, width=config.width, height=config.height, spp=config.spp,
                                   cache_dir=config.cache_dir)
        tick(1)
        brackets = {b: capture(radiance, b, camera, seed=0, noise=False) for b in config.brackets_ms}
        fractions = {b: saturated_fraction(img, **lv) for b, img in brackets.items()}
        cases = []
        for t in exposures:
            b = higher_no_sat(float(t), fractions, **lv)
            gt = capture(radiance, t, camera, seed=0, noise=False)
            cases.append((float(t), b, gt))

        paths = {
            "lut": lambda raw, b, t: emulate(raw, b, t, response),
            # a fresh response object has an empty table cache: the table is built on this call
            "lut+build": lambda raw, b, t: emulate(raw, b, t, response.with_levels()),
            "float": lambda raw, b, t: emulate_float(raw, b, t, response),
            "reference": lambda raw, b, t: emulate_reference(raw, b, t, knots),
        }
        timing_idx = np.linspace(0, len(cases) - 1, min(config.timing_exposures, len(cases))).round().astype(int)
        for name, fn in paths.items():
            for t, b, gt in cases:
                out = fn(brackets[b], b, t)
                if not np.all(np.isfinite(out)):
                    raise ValidationError(f"{name} produced non-finite values at {t} ms")
                valid = validity_mask(brackets[b], t / b, response)
                errors[name]["all"].append(to_percent(rmse_dn(out, gt), white, black))
                errors[name]["valid"].append(to_percent(rmse_dn(out, gt, valid), white, black))
            for i in timing_idx:
                t, b, _ = cases[i]
                big = _tile(brackets[b], FULL_FRAME)
                times_full[name].append(_time(lambda: fn(big, b, t), config.timing_repeats))
                times_small[name].append(_time(lambda: fn(brackets[b], b, t), config.timing_repeats))
            tick(1)

        render_rows += _render_rows(key, config, camera, cases, tick)

    table = _speed_table(config, errors, times_full, times_small, render_rows)
    results = {
        "table": table,
        "render_rows": render_rows,
        "full_frame": list(FULL_FRAME),
        "study_size": [config.height, config.width],
        "reference_spp": config.reference_spp,
        "note": "timings are medians of wall-clock runs on a shared 2-core machine; RMSE in % of the DN range "
                "against the noiseless ground truth (renders: against the reference-spp render's captures)",
        "config": config.as_dict(),
    }
    arrays = {f"{name}/rmse_all": np.asarray(errors[name]["all"], dtype=np.float64) for name in EMULATION_PATHS}
    return {"results": results, "arrays": arrays}
