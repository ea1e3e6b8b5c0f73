"""Render flicker and keypoint repeatability of denoiser presets at one walk pose (docs/results/motion-2026-11-25.md).

Usage: python scripts/render_noise_presets.py oidn-fast@2 oidn@16 oidn@36   (REFSPP=64 by default)

Flicker: mean |a - b| of noiseless 32 ms captures of renders with seeds 1, 2, 3, over the mean
|a - b| of two sensor-noise draws of a high-spp reference; repeatability: SIFT keypoint
repeatability between seeds 2 and 3 (the render study's definitions).
"""

import os
import sys
import time

import numpy as np

import scenes
from scenes.image_stats import keypoint_points, keypoint_repeatability, synthetic_camera, synthetic_gray8
from synth import capture


def main(presets) -> None:
    w, h = 480, 300
    scene = scenes.get_scene("forest_summer")
    pose = scene.trajectory(5.0).pose(1.0)
    cam = synthetic_camera(scene, w, h)
    ref = scenes.render(scene, pose, width=w, height=h, spp=int(os.environ.get("REFSPP", "64")), seed=1000,
                        denoise="off")
    sensor = np.mean(np.abs(capture(ref, 32.0, cam, seed=0).astype(float) - capture(ref, 32.0, cam, seed=1)))
    for preset in presets:
        mode, spp = preset.split("@")
        images, times = [], []
        for seed in (1, 2, 3):
            t = time.perf_counter()
            images.append(scenes.render(scene, pose, width=w, height=h, spp=int(spp), seed=seed, denoise=mode,
                                        cache_dir=False))
            times.append(time.perf_counter() - t)
        caps = [capture(i, 32.0, cam, seed=0, noise=False).astype(float) for i in images]
        flicker = np.mean([np.mean(np.abs(a - b)) for a, b in zip(caps[:-1], caps[1:])])
        pts = [keypoint_points(synthetic_gray8(i, scene, exposure_ms=32.0, seed=0, camera=cam)) for i in images]
        print(preset, "time_s", np.round(times, 2), "flicker/sensor", round(flicker / sensor, 3),
              "repeatability", round(keypoint_repeatability(pts[1], pts[2]), 3))


if __name__ == "__main__":
    main(sys.argv[1:])
