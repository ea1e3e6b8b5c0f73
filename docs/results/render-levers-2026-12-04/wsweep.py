import sys, time, json
import numpy as np, cv2
import scenes, scenes.image_stats
from scenes._mitsuba import sensor_dict, scene_dict
from scenes.variant import choose_variant, ensure_variant
from validation.common import study_scene
import mitsuba as mi
v = choose_variant(); ensure_variant(v); mi.set_variant(v)
key, W, H, spp = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
scene = scenes.get_scene(study_scene(key).scene, seed=0)
pose = scene.trajectory(13.0).pose(6.0)
desc = scene.describe()
fov = scenes.image_stats.synthetic_camera(scene, W, H).fov_x_deg
sd = sensor_dict(pose, width=W, height=H, fov_deg=fov, spp=spp)
for wj in json.loads(sys.argv[5]):
    mis = mi.load_dict(scene_dict(desc, wj)); imgs = []
    t = time.perf_counter()
    for seed in (1, 2):
        imgs.append(np.array(mi.render(mis, sensor=mi.load_dict(sd), spp=spp, seed=seed), dtype=np.float64)[..., :3] @ [0.2126, 0.7152, 0.0722])
    t = (time.perf_counter() - t) / 2
    a, b = imgs; dd = (a - b) / np.sqrt(2); m = 0.5 * (a + b)
    # noise relative to local mean (log-ish): what SIFT sees on a log/gamma-ish image
    rel = np.sqrt(np.mean(dd**2)) / m.mean()
    loc = np.median(np.abs(dd) / np.maximum(m, 1e-3 * m.mean()))
    print(f"{key:>13} {json.dumps(wj):>40} mean {m.mean():8.4f} noise {100*rel:6.2f} % median-rel {100*loc:6.2f} % {t:.2f} s/render", flush=True)
