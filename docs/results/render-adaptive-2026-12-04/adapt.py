"""Exploration driver: noise_balance with the raw render replaced by scenes.adaptive (ADAPT env: "x4:25%" or "").

PYTHONPATH=REPO ADAPT='x4:25%' python adapt.py SCENE SWEEPS SETTING...   (one line per setting; no cache)
"""
import json, os, sys, time
import numpy as np
import scenes.render as _r
sr = sys.modules["scenes.render"]
from scenes import adaptive as ad

spec = ad.parse_adaptive(os.environ["ADAPT"]) if os.environ.get("ADAPT") else None
STATS = []
if spec is not None:
    def adaptive_uncached(scene, pose, *, width, height, spp, seed, fov_deg, variant):
        import mitsuba as mi
        from scenes._mitsuba import sensor_dict
        from scenes._interrupt import render_array
        with sr._lock:
            if mi.variant() != variant:
                mi.set_variant(variant)
            mis = sr._loaded_scene(scene, variant)
            def one(n, s, crop):
                d = sensor_dict(pose, width=width, height=height, fov_deg=fov_deg, spp=n)
                if crop is not None:
                    x, y, w, h = crop
                    d["film"].update(crop_offset_x=x, crop_offset_y=y, crop_width=w, crop_height=h)
                else:
                    w, h = width, height
                img = render_array(mi, mis, sensor=mi.load_dict(d), spp=n, seed=s)
                return img.reshape(h, w, -1)[..., :3]
            t = time.perf_counter()
            img, info = ad.render_adaptive(one, spec, width=width, height=height, spp=spp, seed=seed,
                                           effective_spp=sr.effective_spp)
            STATS.append({**info, "s": time.perf_counter() - t})
            return img
    sr._render_uncached = adaptive_uncached

from validation.render_study.balance import noise_balance
scene = sys.argv[1]; sweeps = tuple(int(x) for x in sys.argv[2].split(","))
for s in sys.argv[3:]:
    t = time.perf_counter(); STATS.clear()
    r = noise_balance(s, scene_key=scene, sweeps=sweeps, cache_dir=False)
    out = {e: [round(x, 1) for x in v["difference"]] for e, v in r["exposures"].items()}
    extra = ""
    if STATS:
        extra = f" mean_spp {np.mean([x['mean_spp'] for x in STATS]):.1f} crops {np.mean([x['crops'] for x in STATS]):.1f} raw_s {np.mean([x['s'] for x in STATS]):.1f}"
    print(f"{scene} {s:>20} adapt={os.environ.get('ADAPT','')} diff {out} {r['seconds_per_sweep']:.2f} s/sweep (wall {time.perf_counter()-t:.0f}){extra}", flush=True)
