"""What one render through a crop window costs (forest_winter, one pose, 520x340 frame, llvm_ad_rgb, sun=16).

PYTHONPATH=REPO python crop_cost.py   (one line per render: (spp, seed, crop) and its seconds)
"""
import sys, time, numpy as np
import scenes
sr = sys.modules["scenes.render"]
import mitsuba as mi
from scenes._mitsuba import sensor_dict
from scenes._interrupt import render_array
from scenes.variant import choose_variant, ensure_variant
v = choose_variant(); ensure_variant(v); mi.set_variant(v)
scene = scenes.get_scene("forest_winter").with_emitter_weights({"sun": 16})
pose = scene.trajectory(5.0).pose(2.0)
mis = sr._loaded_scene(scene, v)
W, H = 520, 340
def one(n, s, crop):
    d = sensor_dict(pose, width=W, height=H, fov_deg=70.0, spp=n)
    if crop:
        x, y, w, h = crop; d["film"].update(crop_offset_x=x, crop_offset_y=y, crop_width=w, crop_height=h)
    t = time.perf_counter(); render_array(mi, mis, sensor=mi.load_dict(d), spp=n, seed=s); return time.perf_counter() - t
RUNS = [(35, 1, None), (35, 2, None), (64, 3, None), (195, 4, (0, 0, 90, 30)), (195, 5, (0, 30, 90, 30)),
        (195, 6, (0, 60, 120, 30)), (195, 7, (30, 90, 120, 30)), (195, 8, (0, 0, 520, 30)),
        (4, 9, (0, 0, 90, 30)), (4, 10, (0, 0, 91, 30)),  # the first process ended here
        (4, 9, (0, 0, 90, 30)), (4, 11, (0, 0, 90, 30)), (4, 12, (0, 30, 90, 30)), (4, 13, (30, 30, 120, 30)),
        (4, 14, (30, 30, 120, 30)), (195, 15, (0, 0, 90, 30)), (195, 16, (60, 60, 90, 30))]
for args in RUNS:
    print(args, f"{one(*args):.2f} s", flush=True)
