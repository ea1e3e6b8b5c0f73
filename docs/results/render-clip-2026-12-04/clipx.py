"""Exploration: adaptive tile score with luminance clamped at what saturates at CLIP ms (monkeypatched)."""
import sys, time, json
import numpy as np
import scenes
import scenes.adaptive as ad
from scenes.dynamic_range import luminance
from validation.render_study.balance import noise_balance, study_scene
sr = sys.modules["scenes.render"]
scene_key = sys.argv[1]; sweeps = tuple(int(x) for x in sys.argv[2].split(",")); clip_ms = float(sys.argv[3])
spec = study_scene(scene_key)
ref = scenes.get_scene(spec.scene, seed=0, **dict(spec.params)).reference_radiance
clip = ref * 1.0 / clip_ms if clip_ms > 0 else np.inf
print("ref", ref, "clip", clip, flush=True)
_orig = ad.tile_scores
STATS = []
def scores(a, b, tile):
    la, lb = np.minimum(luminance(a), clip), np.minimum(luminance(b), clip)
    STATS.append(float(np.mean(np.maximum(luminance(a), luminance(b)) > clip)))
    return _orig(np.repeat(la[..., None], 3, -1), np.repeat(lb[..., None], 3, -1), tile)
ad.tile_scores = scores
_real = ad.render_adaptive
INFO = []
def rec(*a, **k):
    img, info = _real(*a, **k); INFO.append(info); return img, info
sr.render_adaptive = rec
for s in sys.argv[4:]:
    t = time.perf_counter(); INFO.clear(); STATS.clear()
    r = noise_balance(s, scene_key=scene_key, sweeps=sweeps, cache_dir=False)
    out = {e: [round(x, 1) for x in v["difference"]] for e, v in r["exposures"].items()}
    extra = f" clipped {np.mean(STATS):.3f} mean_spp {np.mean([x['mean_spp'] for x in INFO]):.1f} crops {np.mean([x['crops'] for x in INFO]):.1f}" if INFO else ""
    print(f"{scene_key} clip{clip_ms:g} {s:>26} diff {out} {r['seconds_per_sweep']:.2f} s/sweep (wall {time.perf_counter()-t:.0f}){extra}", flush=True)
