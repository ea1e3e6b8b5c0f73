"""Exploration driver: the render-noise measure (validation.render_study.balance.noise_balance) of a few
settings, no cache, one line each, with the adaptive pass's statistics (mean spp, crops, raw seconds).

PYTHONPATH=REPO python adapt.py SCENE SWEEPS SETTING...     e.g. forest_edge 0,22,44 'oidn-hq@64+sun=16~x4:25%'
"""
import json, sys, time
import numpy as np
import scenes
sr = sys.modules["scenes.render"]
STATS = []
_real = sr.render_adaptive


def recording(render_pass, spec, **kw):
    t = time.perf_counter()
    img, info = _real(render_pass, spec, **kw)
    STATS.append({**info, "s": time.perf_counter() - t})
    return img, info


sr.render_adaptive = recording
from validation.render_study.balance import noise_balance
scene = sys.argv[1]; sweeps = tuple(int(x) for x in sys.argv[2].split(","))
for s in sys.argv[3:]:
    t = time.perf_counter(); STATS.clear()
    r = noise_balance(s, scene_key=scene, sweeps=sweeps, cache_dir=False)
    out = {e: [round(x, 1) for x in v["difference"]] for e, v in r["exposures"].items()}
    extra = ""
    if STATS:
        extra = (f" mean_spp {np.mean([x['mean_spp'] for x in STATS]):.1f} crops {np.mean([x['crops'] for x in STATS]):.1f}"
                 f" raw_s {np.mean([x['s'] for x in STATS]):.1f}")
    print(f"{scene} {s:>26} diff {out} {r['seconds_per_sweep']:.2f} s/sweep (wall {time.perf_counter()-t:.0f}){extra}",
          flush=True)
