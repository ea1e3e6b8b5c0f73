"""Measurements behind docs/results/motion-2026-11-25.md and motion-2026-11-26.md that go beyond one ``exposim validate blur`` run.

    python scripts/blur_study_checks.py sharpness OUT.json        # 4 fastest + 4 median-rate instants
    python scripts/blur_study_checks.py variants T0 [T0 ...]      # consistent emulation: smoothing x resampler
    python scripts/blur_study_checks.py reference OUT.json        # reference error per resampler, fastest instant
    python scripts/blur_study_checks.py cost OUT.json [REPEATS]   # CPU-second render cost, fastest + median rate
    python scripts/blur_study_checks.py versus OUT_DIR            # the live-versus-emulated table alone
    python scripts/blur_study_checks.py table OUT_DIR             # that table from the walks finished so far
    python scripts/blur_study_checks.py consistent OUT.json [WxH ...]  # forms of consistent emulation, per size

At the full configuration of :class:`validation.blur.config.BlurConfig`, at 480x300 except
``consistent`` (its sizes), with the study's own functions (:mod:`validation.blur.measure`,
:mod:`validation.blur.versus`).  ``sharpness`` and ``variants`` reproduce the 2026-11-25 figures:
they use the form of consistent emulation of that day (uniform sub-instants, Gaussian structure).
"""

from __future__ import annotations

import json
import os
import resource
import sys
import time

import numpy as np


def _setup():
    import scenes
    from validation.blur.config import BlurConfig
    from validation.common import make_camera

    cfg = BlurConfig()
    scene = scenes.get_scene(cfg.scene, seed=cfg.seed)
    traj = scene.trajectory(cfg.walk_s + 1.0, walk=cfg.walk)
    camera = make_camera("borealhdr", width=cfg.width, height=cfg.height).saturating_at(scene.reference_radiance, 1.0)
    return cfg, scene, traj, camera


def _consistent(traj, camera, sigma: float, resample: str = "linear"):
    """Consistent emulation in the form of 2026-11-25 (uniform sub-instants, Gaussian structure)."""
    from validation.blur import measure

    return measure.consistent_from_walk(traj, camera, placement="uniform", structure_sigma_px=sigma,
                                        resample=resample, structure="gaussian")


def _median_instants(traj, walk_s: float, exposure_ms: float, n: int = 4, gap_s: float = 5.0) -> list[float]:
    from scenes.walks import angular_velocity

    t = np.arange(0.5, walk_s - 1.0, 0.01)
    speed = np.linalg.norm(angular_velocity(traj, t + 0.5e-3 * exposure_ms), axis=1)
    chosen: list[float] = []
    for i in np.argsort(np.abs(speed - np.median(speed))):
        if all(abs(t[i] - c) >= gap_s for c in chosen):
            chosen.append(float(t[i]))
        if len(chosen) == n:
            break
    return sorted(chosen)


def sharpness(out_path: str) -> dict:
    from validation.blur import measure

    cfg, scene, traj, camera = _setup()
    rows = []
    for kind, instants in (("fastest", measure.fastest_instants(traj, cfg.walk_s, 4, cfg.exposure_ms)),
                           ("median", _median_instants(traj, cfg.walk_s, cfg.exposure_ms))):
        for t0 in instants:
            r = measure.sharpness_comparison(scene, traj, t0, cfg, camera, _consistent(traj, camera, 1.0))
            r0 = measure.sharpness_comparison(scene, traj, t0, cfg, camera, _consistent(traj, camera, 0.0))
            r.update(kind=kind, consistent_sigma0_error_percent=r0["consistent_error_percent"])
            rows.append(r)
    out = {"rows": rows, "load": os.getloadavg()}
    _write(out_path, out)
    return out


def variants(t0s) -> list[dict]:
    from validation.blur import measure

    cfg, scene, traj, camera = _setup()
    rows = []
    for t0 in t0s:
        row = {"t0_s": t0}
        for sigma in (0.0, 0.5, 1.0):
            for rs in ("linear", "cubic"):
                r = measure.sharpness_comparison(scene, traj, t0, cfg, camera, _consistent(traj, camera, sigma, rs))
                row[f"sigma{sigma:g}-{rs}"] = r["consistent_error_percent"]
        row["plain"] = r["plain_error_percent"]
        rows.append(row)
        print(json.dumps(row), flush=True)
    return rows


def reference(out_path: str) -> dict:
    from validation.blur import measure

    cfg, scene, traj, camera = _setup()
    t0 = measure.fastest_instants(traj, cfg.walk_s, 1, cfg.exposure_ms)[0]
    out = {"t0_s": t0, "reference": measure.reference_comparison(scene, traj, t0, cfg, camera), "load": os.getloadavg()}
    _write(out_path, out)
    return out


def cost(out_path: str, repeats: int = 3) -> dict:
    from dataclasses import replace

    from validation.blur import measure

    cfg, scene, traj, camera = _setup()
    cfg = replace(cfg, timing_repeats=int(repeats))
    t0 = measure.fastest_instants(traj, cfg.walk_s, 1, cfg.exposure_ms)[0]
    tm = measure.median_rate_instant(traj, cfg.walk_s, cfg.exposure_ms)
    out = {"fastest": measure.cost_comparison(scene, traj, t0, cfg, camera),
           "median_rate": measure.cost_comparison(scene, traj, tm, cfg, camera)}
    _write(out_path, out)
    return out


def versus(out_dir: str) -> dict:
    from validation.blur.config import BlurConfig
    from validation.blur.report import versus_markdown
    from validation.blur.versus import run_versus

    cfg = BlurConfig()
    t, load0 = time.time(), os.getloadavg()
    r = run_versus(out_dir, cfg)
    ru = resource.getrusage(resource.RUSAGE_SELF)
    r["timing"] = {"wall_s": time.time() - t, "cpu_s": ru.ru_utime + ru.ru_stime, "load_start": load0,
                   "load_end": os.getloadavg()}
    r["config"] = cfg.as_dict()
    _write(os.path.join(out_dir, "versus.json"), r)
    with open(os.path.join(out_dir, "versus.md"), "w") as f:
        f.write("\n".join(versus_markdown(r)) + "\n")
    return r


#: The forms of blur-consistent emulation compared by ``consistent``: (name, placement, structure, kwargs).
FORMS = (("default", "tiled", "wiener", {}),
         ("noiseless", "tiled", "wiener", {"noise_var": 0.0}),
         ("before", "uniform", "gaussian", {}),
         ("uniform-noiseless", "uniform", "wiener", {"noise_var": 0.0}))


def consistent(out_path: str, sizes) -> dict:
    """Plain and blur-consistent emulation against live, by sharpness and RMS DN, at each size.

    The 8 instants of ``sharpness`` (4 fastest, 4 at the median turn rate); 32 ms live against
    32 ms emulated from the 8 ms window of the same render (noiseless captures).  Forms: the
    default (tiled copies, Wiener structure with the noise measured on the image), the same with
    the known noise (none), the form before tiled copies (uniform sub-instants, 1-px Gaussian
    structure), and uniform sub-instants with the known noise.
    """
    from dataclasses import replace

    from emulator.core.emulate import emulate
    from validation.blur import measure
    from validation.common import make_camera

    cfg0, scene, traj, _ = _setup()
    cfg0 = replace(cfg0, cache_dir=os.environ.get("EXPOSIM_CACHE"))
    instants = [("fastest", t) for t in measure.fastest_instants(traj, cfg0.walk_s, 4, cfg0.exposure_ms)]
    instants += [("median", t) for t in _median_instants(traj, cfg0.walk_s, cfg0.exposure_ms)]
    rows = []
    for size in sizes:
        w, h = (int(v) for v in size.split("x"))
        camera = make_camera("borealhdr", width=w, height=h).saturating_at(scene.reference_radiance, 1.0)
        resp = camera.response
        hooks = {name: measure.consistent_from_walk(traj, camera, placement=placement, structure=structure, **kw)
                 for name, placement, structure, kw in FORMS}
        for kind, t0 in instants:
            shot, src, live, info = measure.source_and_live(scene, traj, t0, cfg0, camera)
            plain, valid = emulate(src, cfg0.source_ms, cfg0.exposure_ms, resp, return_mask=True)
            score = measure.against_live(live, plain, valid, resp.white_level)
            row = {"size": size, "kind": kind, "t0_s": t0, "blur_px": info["blur_px"]}
            row["plain_error_percent"], row["plain_rms_dn"] = score(plain)[1:]
            for name, hook in hooks.items():
                img = hook(src, cfg0.source_ms, cfg0.exposure_ms, resp, shot)
                row[f"{name}_error_percent"], row[f"{name}_rms_dn"] = score(img)[1:]
            rows.append(row)
            print(json.dumps(row), flush=True)
    summary = {}
    for size in sizes:
        for kind in ("fastest", "median", "all"):
            sel = [r for r in rows if r["size"] == size and kind in ("all", r["kind"])]
            summary[f"{size} {kind}"] = {
                key: float(np.median([abs(r[key]) for r in sel if r[key] is not None]))
                for key in sel[0] if key.endswith(("_error_percent", "_rms_dn"))}
    out = {"rows": rows, "median_abs": summary, "load": os.getloadavg()}
    _write(out_path, out)
    return out


def table(out_dir: str) -> dict:
    """The table of :func:`validation.blur.versus.compare` over ``OUT_DIR/versus/seed*/walk.json``."""
    from pathlib import Path

    from emulator.io.files import read_results
    from validation.blur.config import BlurConfig
    from validation.blur.report import versus_markdown
    from validation.blur.versus import RUNS, SCENE_BLUR, compare

    cfg = BlurConfig()
    walks = [read_results(p) for p in sorted(Path(out_dir).glob("versus/seed*/walk.json"))]
    r = {"walks": walks, "table": compare(walks, cfg.versus_methods, seed=cfg.seed),
         "settings": {"runs": list(RUNS), "scene_blur": list(SCENE_BLUR), "live_timing": "same-instant"}}
    _write(os.path.join(out_dir, "table.json"), r)
    with open(os.path.join(out_dir, "table.md"), "w") as f:
        f.write("\n".join(versus_markdown(r)) + "\n")
    return r


def _write(path: str, obj) -> None:
    from emulator.io.files import write_results

    write_results(path, obj, float_digits=12)


def main(argv) -> int:
    what, args = argv[1], argv[2:]
    jobs = {"sharpness": lambda: sharpness(args[0]), "variants": lambda: variants([float(a) for a in args]),
            "reference": lambda: reference(args[0]), "cost": lambda: cost(args[0], *args[1:2]), "versus": lambda: versus(args[0]),
            "table": lambda: table(args[0]), "consistent": lambda: consistent(args[0], args[1:] or ["480x300"])}
    if what not in jobs:
        print(__doc__, file=sys.stderr)
        return 2
    jobs[what]()
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv))
