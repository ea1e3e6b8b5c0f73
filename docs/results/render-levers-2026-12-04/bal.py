"""Exploration driver: noise_balance with monkeypatched levers. LEVERS env: JSON {weights:{}, prefilter:bool, sampler:str}"""
import json, os, sys, time
import numpy as np
import sys as _s, scenes.base, scenes._mitsuba as sm, scenes.denoise as sdn, scenes.render
sr = _s.modules["scenes.render"]
lev = json.loads(os.environ.get("LEVERS", "{}"))
if lev.get("weights"):
    orig = sm.scene_dict
    def patched(desc, emitter_weights=None):
        return orig(desc, lev["weights"])
    sm.scene_dict = patched
if lev.get("sampler"):
    sm.SAMPLER = lev["sampler"]
if "clean_aux" in lev or lev.get("prefilter"):
    orig_dn = sdn.denoise_oidn
    def dn(color, albedo, normal, settings, *, reference_radiance):
        from dataclasses import replace
        if lev.get("prefilter"):
            import pyoidn
            albedo = pyoidn.denoise(np.ascontiguousarray(albedo, np.float32)) if hasattr(pyoidn, "denoise") else albedo
        return orig_dn(color, albedo, normal, replace(settings, clean_aux=lev.get("clean_aux", True)), reference_radiance=reference_radiance)
    sr.denoise_oidn = dn
if lev.get("hybrid"):
    hy = lev["hybrid"]
    def hybrid_uncached(scene, pose, *, width, height, spp, seed, fov_deg, variant):
        import mitsuba as mi
        from scenes._mitsuba import sensor_dict
        from scenes._interrupt import render_array
        with sr._lock:
            if mi.variant() != variant: mi.set_variant(variant)
            mis = sr._loaded_scene(scene, variant)
            def one(integ, n, sd_seed):
                sensor = mi.load_dict(sensor_dict(pose, width=width, height=height, fov_deg=fov_deg, spp=n))
                return render_array(mi, mis, sensor=sensor, integrator=mi.load_dict(integ), spp=n, seed=sd_seed).reshape(height, width, -1)[..., :3]
            d = one({"type": "direct", "emitter_samples": hy.get("e", 1), "bsdf_samples": hy["k"]}, spp, seed)
            md = scene.describe().max_depth
            m = int(hy["M"])
            if m > 0 and md > 2:
                p3 = one({"type": "path", "max_depth": md, "rr_depth": md + 1}, m, seed + 7)
                p2 = one({"type": "path", "max_depth": 2, "rr_depth": 3}, m, seed + 7)
                ind = p3 - p2
                d = d + ind
            return np.maximum(d, 0).astype(np.float32).copy()
    sr._render_uncached = hybrid_uncached
from validation.render_study.balance import noise_balance
scene = sys.argv[1]; sweeps = tuple(int(x) for x in sys.argv[2].split(","))
for s in sys.argv[3:]:
    t = time.perf_counter()
    r = noise_balance(s, scene_key=scene, sweeps=sweeps, cache_dir=False)
    out = {e: [round(x, 1) for x in v["difference"]] for e, v in r["exposures"].items()}
    ro = {e: round(v["render_only"][0], 1) for e, v in r["exposures"].items()}
    so = {e: round(v["sensor_only"][0], 1) for e, v in r["exposures"].items()}
    print(f"{scene} {s:>14} {json.dumps(lev)} diff {out} ro {ro} so {so} {r['seconds_per_sweep']:.2f} s/sweep (wall {time.perf_counter()-t:.0f})", flush=True)
