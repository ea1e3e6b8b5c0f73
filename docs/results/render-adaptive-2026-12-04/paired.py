"""Adaptive against study-sun64, paired by sweep: the adaptive setting read back from its cache (CACHE below was
/work/cache-adaptive on the measuring machine), study-sun64 from render-levers-2026-12-04; PYTHONPATH=REPO python paired.py."""
import json, sys
import numpy as np
from validation.render_study.balance import noise_balance, t_interval
L = "docs/results/render-levers-2026-12-04/"
for scene, folder, old in (("forest_edge", "final-A", L + "balance-forest_edge.json"), ("sun_glare", "final-B", L + "balance-sun_glare.json")):
    r = noise_balance("oidn-hq@64+sun=16~x4:25%", scene_key=scene, cache_dir=f"/work/cache-adaptive/{folder}/{scene}-1")
    o = next(x for x in json.load(open(old))["results"] if x["setting"] == "oidn-hq@64+sun=16")
    for e in (8.0, 32.0):
        a = {p["sweep"]: p["render_only"] - p["sensor_only"] for p in r["per_pose"] if p["exposure_ms"] == e}
        b = {p["sweep"]: p["render_only"] - p["sensor_only"] for p in o["per_pose"] if p["exposure_ms"] == e}
        sb = {p["sweep"]: p["sensor_only"] for p in o["per_pose"] if p["exposure_ms"] == e}
        sa = {p["sweep"]: p["sensor_only"] for p in r["per_pose"] if p["exposure_ms"] == e}
        d = [a[k] - b[k] for k in sorted(a)]
        print(scene, e, "adaptive", [round(a[k], 1) for k in sorted(a)], "sun64", [round(b[k], 1) for k in sorted(b)],
              "paired diff", [round(x, 2) for x in t_interval(d)], "sensor-only same:", all(abs(sa[k] - sb[k]) < 1e-9 for k in sa), flush=True)
