"""Motion between brackets: emulating a target at time t from a bracket shot earlier or later.

The paper validated the emulator on static scenes only.  Here the camera moves; at a shot
instant ``t`` the ground truth is captured at each target exposure from the radiance at
``pose(t)``, and the bracket the selector would use (HigherNoSat on the sweep at ``t``) is
captured from the radiance at ``pose(t + k * 45.45 ms)``, ``k = -5..5`` (up to ~230 ms, one
BorealHDR sweep either side).  Any bracket is placed at any offset: a controlled version of
the real sweep, where each bracket has its own slot.

Two radiance sources:

``mitsuba``
    forest scenes rendered along :func:`scenes.trajectory.walk` (head bob and sway,
    parallax).  Every render uses the same sampler seed, so Monte Carlo noise is largely
    correlated between nearby poses; the floor of uncorrelated render noise (same pose,
    another seed) is measured and the floor-subtracted figure
    ``sqrt(max(err^2 - floor^2, 0))`` reported beside the raw one: the motion error lies
    between the two;
``chart``
    :class:`synth.procedural.TranslatingChart`: a camera sliding sideways past a textured
    HDR chart at ``chart_depth_m``, exact (no render noise), pure translation.

Captures are noiseless (``noise=False``) so that the error is motion plus emulation only;
the noisy-bracket figure against the same noiseless truth is reported beside it.  The
image shift of a given displacement grows with resolution, so errors at these small sizes
understate those of full 1920x1200 frames (the chart rows report the shift in pixels).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from emulator.core.emulate import emulate
from emulator.core.select import higher_no_sat, saturated_fraction
from validation.common import (
    BRACKETS_MS,
    RESPONSES,
    SHOT_INTERVAL_MS,
    Progress,
    ValidationError,
    capture,
    make_camera,
    rmse_dn,
    seed_for,
    study_scene,
    summary_stats,
    to_percent,
)

__all__ = ["MotionConfig", "run_motion"]


@dataclass(frozen=True)
class MotionConfig:
    """Size of the motion study.

    Attributes
    ----------
    scenes : tuple of str
        Rendered (``mitsuba``) scenes, study scene keys (not static ones); may be empty.
    chart : bool
        Also run the exact translating chart (``synth.procedural``).
    chart_depth_m : float
        Distance of the chart, m.
    speeds_mps : tuple of float
        Walking speeds, m/s.
    shot_times_s : tuple of float
        Shot instants t along each walk, s (>= the largest offset, so that t - 230 ms >= 0).
    offsets : tuple of int
        Bracket offsets in shot intervals (``SHOT_INTERVAL_MS`` = 45.45 ms); must hold 0.
    targets_ms : tuple of float
        Target exposures emulated at each shot instant, ms.
    response : str
        Camera response preset.
    width, height, spp : int
        Image size and samples per pixel of the renders (every render goes through the cache).
    """

    scenes: tuple = ("forest_winter", "forest_summer")
    chart: bool = True
    chart_depth_m: float = 5.0
    speeds_mps: tuple = (0.5, 1.0, 1.5, 2.0)
    shot_times_s: tuple = (1.0,)
    offsets: tuple = (-5, -4, -3, -2, -1, 0, 1, 2, 3, 4, 5)
    targets_ms: tuple = (1.5, 3.0, 6.0, 12.0, 24.0)
    response: str = "borealhdr"
    width: int = 96
    height: int = 60
    spp: int = 256
    seed: int = 0
    walk_seed: int = 3
    brackets_ms: tuple = BRACKETS_MS
    cache_dir: str | None = None

    @classmethod
    def quick(cls, **overrides) -> "MotionConfig":
        base = dict(scenes=("forest_winter",), speeds_mps=(0.5, 2.0), offsets=(-5, -1, 0, 1, 5),
                    targets_ms=(3.0, 12.0), width=48, height=30, spp=16)
        base.update(overrides)
        return cls(**base)

    def __post_init__(self) -> None:
        for s in self.scenes:
            if study_scene(s).scene == "static_lab":
                raise ValidationError(f"motion study needs a walkable scene, {s!r} is static")
        if not self.scenes and not self.chart:
            raise ValidationError("motion study needs at least one scene or the chart")
        if self.response not in RESPONSES:
            raise ValidationError(f"unknown camera response {self.response!r}; choose from {', '.join(RESPONSES)}")
        if 0 not in self.offsets:
            raise ValidationError("offsets must include 0 (the static baseline)")
        lead = max(abs(k) for k in self.offsets) * SHOT_INTERVAL_MS / 1000.0
        for t in self.shot_times_s:
            if t - lead < 0:
                raise ValidationError(f"shot time {t} s is earlier than the largest offset ({lead:.3f} s)")
        for v in self.speeds_mps:
            if not v > 0:
                raise ValidationError(f"walking speeds must be > 0 m/s, got {v!r}")

    def n_renders(self) -> int:
        """Mitsuba renders the study asks for (one per scene, speed, shot and offset, plus a floor each)."""
        return len(self.scenes) * len(self.speeds_mps) * len(self.shot_times_s) * (len(self.offsets) + 1)

    def n_steps(self) -> int:
        return self.n_renders() + (len(self.speeds_mps) if self.chart else 0)

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def _rotation_deg(a: np.ndarray, b: np.ndarray) -> float:
    c = (np.trace(a[:3, :3].T @ b[:3, :3]) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def run_motion(config: MotionConfig, *, progress=None) -> dict:
    """Run the motion study; returns ``{"results": JSON-ready dict, "arrays": {...}}``."""
    import scenes
    from synth.procedural import TranslatingChart

    tick = Progress(progress)
    camera = make_camera(config.response, width=config.width, height=config.height)
    response = camera.response
    white, black = int(camera.white_level), int(camera.black_level)
    pct = lambda v: None if v is None else float(to_percent(v, white, black))  # noqa: E731
    lv = dict(white_level=white, black_level=black)
    offsets = sorted(int(k) for k in config.offsets)
    dt_s = SHOT_INTERVAL_MS / 1000.0
    duration = max(config.shot_times_s) + max(abs(k) for k in offsets) * dt_s + 0.5
    rows = []
    renders = 0

    def one_instant(source: str, key: str, v: float, t0: float, frame, floor_frame=None, px_per_m=None):
        """Ground truth from frame(t0), brackets from frame(t0 + offset); appends to rows."""
        r0, p0 = frame(t0)
        gts = {tm: capture(r0, tm, camera, seed=0, noise=False) for tm in config.targets_ms}
        sweep0 = {b: capture(r0, b, camera, seed=0, noise=False) for b in config.brackets_ms}
        fractions = {b: saturated_fraction(img, **lv) for b, img in sweep0.items()}
        chosen = {tm: higher_no_sat(tm, fractions, **lv) for tm in config.targets_ms}
        floors = {}
        if floor_frame is not None:
            r_alt = floor_frame(t0)
            for tm in config.targets_ms:
                emu = emulate(capture(r_alt, chosen[tm], camera, seed=0, noise=False), chosen[tm], tm, response)
                floors[tm] = pct(rmse_dn(emu, gts[tm]))
        for k in offsets:
            tk = t0 + k * dt_s
            rk, pk = (r0, p0) if k == 0 else frame(tk)
            disp = float(np.linalg.norm(pk[:3, 3] - p0[:3, 3]))
            for tm in config.targets_ms:
                b = chosen[tm]
                emu, valid = emulate(capture(rk, b, camera, seed=0, noise=False), b, tm, response, return_mask=True)
                src_n = capture(rk, b, camera, seed=seed_for(config.seed, key, v, t0, k, b))
                emu_n, valid_n = emulate(src_n, b, tm, response, return_mask=True)
                gt = gts[tm]
                clean = pct(rmse_dn(emu, gt))
                floor = floors.get(tm)
                rows.append({
                    "source": source, "scene": key, "speed_mps": float(v), "t_s": float(t0), "offset": k,
                    "offset_ms": float(k * SHOT_INTERVAL_MS), "target_ms": float(tm), "bracket_ms": float(b),
                    "displacement_m": disp, "rotation_deg": _rotation_deg(p0, pk),
                    "shift_px": None if px_per_m is None else disp * px_per_m,
                    "clean_all": clean, "clean_valid": pct(rmse_dn(emu, gt, valid)),
                    "valid_fraction": float(valid.mean()),
                    "render_floor_all": floor,
                    "clean_all_floor_subtracted": (None if floor is None or k == 0 else
                                                   float(np.sqrt(max(clean * clean - floor * floor, 0.0)))),
                    "noisy_all": pct(rmse_dn(emu_n, gt)), "noisy_valid": pct(rmse_dn(emu_n, gt, valid_n)),
                })

    for key in config.scenes:
        scene = study_scene(key).build()
        for v in config.speeds_mps:
            traj = scene.trajectory(duration_s=duration, speed_mps=float(v), seed=config.walk_seed)

            def frame(t, seed=0, traj=traj, scene=scene):
                nonlocal renders
                pose = traj.pose(t)
                img = scenes.render(scene, pose, width=config.width, height=config.height, spp=config.spp,
                                    seed=seed, cache_dir=config.cache_dir)
                renders += 1
                tick(1)
                return img, pose

            for t0 in config.shot_times_s:
                one_instant("mitsuba", key, v, t0, frame, floor_frame=lambda t, frame=frame: frame(t, seed=1)[0])

    if config.chart:
        for v in config.speeds_mps:
            chart = TranslatingChart(config.width, config.height, seed=config.seed, speed_m_s=float(v),
                                     depth_m=config.chart_depth_m, fov_x_deg=camera.fov_x_deg, duration_s=duration)
            for t0 in config.shot_times_s:
                one_instant("chart", f"chart@{config.chart_depth_m:g}m", v, t0, chart, px_per_m=chart.pixels_per_m)
            tick(1)
    return {"results": _assemble(config, rows, renders), "arrays": _arrays(rows)}


def _arrays(rows) -> dict:
    keys = ("speed_mps", "offset_ms", "displacement_m", "rotation_deg", "target_ms", "bracket_ms", "clean_all",
            "clean_valid", "noisy_all", "valid_fraction", "render_floor_all", "clean_all_floor_subtracted", "shift_px")
    out = {k: np.array([np.nan if r[k] is None else r[k] for r in rows], dtype=np.float64) for k in keys}
    out["is_chart"] = np.array([r["source"] == "chart" for r in rows])
    return out


def _assemble(config: MotionConfig, rows, renders: int) -> dict:
    offsets = sorted(set(int(o) for o in config.offsets))
    top = max(abs(k) for k in offsets)
    by_source = {}
    for source in ("mitsuba", "chart"):
        src_rows = [r for r in rows if r["source"] == source]
        if not src_rows:
            continue
        table, by_abs = {}, {}
        for v in config.speeds_mps:
            for k in offsets:
                sel = [r for r in src_rows if r["speed_mps"] == float(v) and r["offset"] == k]
                table.setdefault(f"{v:g}", {})[str(k)] = {
                    "offset_ms": float(k * SHOT_INTERVAL_MS),
                    "displacement_m": summary_stats([r["displacement_m"] for r in sel])["median"],
                    "clean_all": summary_stats([r["clean_all"] for r in sel]),
                    "clean_all_floor_subtracted": summary_stats([r["clean_all_floor_subtracted"] for r in sel]),
                    "clean_valid": summary_stats([r["clean_valid"] for r in sel]),
                    "noisy_all": summary_stats([r["noisy_all"] for r in sel]),
                }
            for a in sorted(set(abs(k) for k in offsets)):
                sel = [r for r in src_rows if r["speed_mps"] == float(v) and abs(r["offset"]) == a]
                by_abs.setdefault(f"{v:g}", {})[str(a)] = {
                    "offset_ms": float(a * SHOT_INTERVAL_MS),
                    "displacement_m": summary_stats([r["displacement_m"] for r in sel])["median"],
                    "shift_px": summary_stats([r["shift_px"] for r in sel])["median"],
                    "median_clean_all": summary_stats([r["clean_all"] for r in sel])["median"],
                    "max_clean_all": summary_stats([r["clean_all"] for r in sel])["max"],
                    "median_clean_all_floor_subtracted":
                        summary_stats([r["clean_all_floor_subtracted"] for r in sel])["median"],
                    "median_noisy_all": summary_stats([r["noisy_all"] for r in sel])["median"],
                }
        static = summary_stats([r["clean_all"] for r in src_rows if r["offset"] == 0])
        d = np.array([r["displacement_m"] for r in src_rows])
        e = np.array([r["clean_all"] for r in src_rows])
        base = static["median"] or 0.0
        slope = float(np.dot(d, e - base) / np.dot(d, d)) if np.dot(d, d) > 0 else None
        by_source[source] = {
            "static_baseline_clean_all": static,
            "largest_offset_clean_all": summary_stats([r["clean_all"] for r in src_rows if abs(r["offset"]) == top]),
            "largest_offset_floor_subtracted": summary_stats(
                [r["clean_all_floor_subtracted"] for r in src_rows if abs(r["offset"]) == top]),
            "one_shot_offset_clean_all": summary_stats([r["clean_all"] for r in src_rows if abs(r["offset"]) == 1]),
            "render_noise_floor_all": summary_stats([r["render_floor_all"] for r in src_rows if r["offset"] == 0]),
            "error_per_metre_percent": slope,
            "by_speed_and_abs_offset": by_abs,
            "by_speed_and_offset": table,
        }
    return {
        "method": "noiseless captures; ground truth at pose(t); the HigherNoSat bracket (chosen on the sweep at t) "
                  "captured at pose(t + offset); rendered scenes use one sampler seed for every render",
        "renders": renders,
        "shot_interval_ms": SHOT_INTERVAL_MS,
        "sources": by_source,
        "rows": rows,
        "config": config.as_dict(),
    }
