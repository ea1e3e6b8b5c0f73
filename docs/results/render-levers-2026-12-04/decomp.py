import sys, time
import numpy as np, cv2
import scenes, scenes.image_stats
from scenes._mitsuba import sensor_dict
from scenes.variant import choose_variant, ensure_variant
from validation.common import study_scene
import mitsuba as mi
v = choose_variant(); ensure_variant(v); mi.set_variant(v)
key, W, H, spp = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
scene = scenes.get_scene(study_scene(key).scene, seed=0)
pose = scene.trajectory(13.0).pose(6.0)
base = scene.mitsuba_dict()
fov = scenes.image_stats.synthetic_camera(scene, W, H).fov_x_deg
sd = sensor_dict(pose, width=W, height=H, fov_deg=fov, spp=spp)
def meas(d, label, md=3):
    d = dict(d); d["integrator"] = {"type": "path", "max_depth": md, "rr_depth": md + 1}
    mis = mi.load_dict(d); imgs = []
    for seed in (1, 2):
        t = time.perf_counter()
        imgs.append(np.array(mi.render(mis, sensor=mi.load_dict(sd), spp=spp, seed=seed), dtype=np.float64)[..., :3] @ [0.2126, 0.7152, 0.0722])
    t = time.perf_counter() - t
    a, b = imgs; dd = (a - b) / np.sqrt(2); m = 0.5 * (a + b)
    print(f"{key} {label:>16} mean {m.mean():.4f} noise(abs, % of full mean {full:.3f}) {100*np.sqrt(np.mean(dd**2))/full:6.2f} % blurred {100*np.sqrt(np.mean(cv2.GaussianBlur(dd,(0,0),1.6)**2))/full:6.2f} % {t:.2f} s", flush=True)
full = 9.58
nosky = {k: e for k, e in base.items() if k != "sky"}
nosun = {k: e for k, e in base.items() if k != "sun"}
meas(base, "both")
meas(nosky, "sun only")
meas(nosun, "sky only")
meas(nosky, "sun only direct", md=2)
meas(nosun, "sky only direct", md=2)
