"""Mitsuba's CUDA variant on a GPU machine: seconds per frame against spp, determinism, flicker and
keypoint repeatability at high spp (docs/results/render.md, "On a GPU").

Usage: EXPOSIM_MITSUBA_VARIANT=cuda_ad_rgb python scripts/render_gpu_checks.py OUT.json [--budget-s 420]

Measures, on forest_winter (raw path tracing: no denoiser):
- seconds per frame at 480x300 and 1920x1200 for a range of spp (after one warm-up render of each size,
  which holds the kernel compilation, reported apart);
- whether two renders with the same seed give the same bytes;
- at 480x300 and high spp, for 3 walk poses: static-camera flicker (mean |a - b| of noiseless 32 ms
  captures of two render seeds, over the mean |a - b| of two sensor-noise draws of one render), and SIFT
  keypoint repeatability between two render seeds (same sensor-noise seed) against repeatability between
  two sensor-noise draws (same render), at 8 and at 32 ms.
Stops starting new measurements when --budget-s is spent and writes what it has; every figure it writes
comes with the variant and the GPU it ran on.
"""

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import scenes  # noqa: E402
from emulator.io.files import strict_json  # noqa: E402
from scenes.image_stats import keypoint_points, keypoint_repeatability, synthetic_camera, synthetic_gray8  # noqa: E402
from scenes.variant import gpu_description  # noqa: E402
from synth import capture  # noqa: E402

SCENE = "forest_winter"
POSE_TIMES_S = (1.0, 4.0, 7.0)


def _render(scene, pose, w, h, spp, seed):
    return scenes.render(scene, pose, width=w, height=h, spp=spp, seed=seed, cache_dir=False, denoise="off")


def timing(scene, pose, sizes, spps, deadline, out):
    for w, h in sizes:
        key = f"{w}x{h}"
        t0 = time.perf_counter()
        _render(scene, pose, w, h, 1, 0)
        out["warmup_s"][key] = round(time.perf_counter() - t0, 3)
        for spp in spps[key]:
            if time.perf_counter() > deadline:
                out["skipped"].append(f"timing {key} spp {spp}")
                continue
            times = []
            for seed in (1, 2):
                t0 = time.perf_counter()
                _render(scene, pose, w, h, spp, seed)
                times.append(time.perf_counter() - t0)
            out["seconds_per_frame"].setdefault(key, {})[str(spp)] = round(min(times), 4)
            print(key, spp, [round(t, 3) for t in times], flush=True)


def quality(scene, trajectory, w, h, spps, deadline, out):
    cam = synthetic_camera(scene, w, h)
    for spp in spps:
        rows = []
        for t_s in POSE_TIMES_S:
            if time.perf_counter() > deadline:
                out["skipped"].append(f"quality spp {spp} pose {t_s}")
                continue
            pose = trajectory.pose(t_s)
            a, b = _render(scene, pose, w, h, spp, 2), _render(scene, pose, w, h, spp, 3)
            row = {"pose_t_s": t_s}
            sensor = np.mean(np.abs(capture(a, 32.0, cam, seed=0).astype(float) - capture(a, 32.0, cam, seed=1)))
            flick = np.mean(np.abs(capture(a, 32.0, cam, seed=0, noise=False).astype(float)
                                   - capture(b, 32.0, cam, seed=0, noise=False)))
            row["flicker_over_sensor"] = round(float(flick / sensor), 4)
            for ms in (8.0, 32.0):
                pa = keypoint_points(synthetic_gray8(a, scene, exposure_ms=ms, seed=0, camera=cam))
                pb = keypoint_points(synthetic_gray8(b, scene, exposure_ms=ms, seed=0, camera=cam))
                pa1 = keypoint_points(synthetic_gray8(a, scene, exposure_ms=ms, seed=1, camera=cam))
                row[f"render_only_{ms:g}ms"] = round(keypoint_repeatability(pa, pb), 4)
                row[f"sensor_only_{ms:g}ms"] = round(keypoint_repeatability(pa, pa1), 4)
            rows.append(row)
            print("quality", spp, row, flush=True)
        if rows:
            out["quality"][str(spp)] = rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("output", type=Path)
    p.add_argument("--budget-s", type=float, default=420.0)
    p.add_argument("--quality-spp", default="256,1024,4096")
    p.add_argument("--small-spp", default="1,4,16,64,256,1024,4096")
    p.add_argument("--large-spp", default="1,4,16,64,256")
    args = p.parse_args(argv)
    start = time.perf_counter()
    deadline = start + args.budget_s
    variant = scenes.choose_variant() if hasattr(scenes, "choose_variant") else os.environ.get(
        "EXPOSIM_MITSUBA_VARIANT", "")
    out = {"variant": variant, "gpu": gpu_description() or "unknown", "python": platform.python_version(),
           "numpy": np.__version__, "scene": SCENE, "denoise": "off", "warmup_s": {}, "seconds_per_frame": {},
           "quality": {}, "skipped": []}
    import mitsuba
    out["mitsuba"] = mitsuba.__version__
    scene = scenes.get_scene(SCENE)
    trajectory = scene.trajectory(10.0)
    pose = trajectory.pose(1.0)
    try:
        a, b = _render(scene, pose, 480, 300, 64, 5), _render(scene, pose, 480, 300, 64, 5)
        out["same_seed_same_bytes_480x300_64spp"] = bool(a.tobytes() == b.tobytes())
        out["same_seed_max_abs_diff"] = float(np.max(np.abs(a - b)))
        sizes = [(480, 300), (1920, 1200)]
        spps = {"480x300": [int(s) for s in args.small_spp.split(",")],
                "1920x1200": [int(s) for s in args.large_spp.split(",")]}
        timing(scene, pose, sizes, spps, start + 0.45 * args.budget_s, out)
        quality(scene, trajectory, 480, 300, [int(s) for s in args.quality_spp.split(",")], deadline, out)
    finally:
        out["wall_s"] = round(time.perf_counter() - start, 1)
        args.output.write_text(strict_json(out, indent=1) + "\n")
        print(strict_json(out), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
