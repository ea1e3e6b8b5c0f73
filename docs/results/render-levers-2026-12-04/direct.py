import sys, time, json
import numpy as np, cv2
import scenes, scenes.image_stats
from scenes._mitsuba import sensor_dict, scene_dict
from scenes.variant import choose_variant, ensure_variant
from validation.common import study_scene
import mitsuba as mi
v = choose_variant(); ensure_variant(v); mi.set_variant(v)
key, W, H = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
scene = scenes.get_scene(study_scene(key).scene, seed=0)
pose = scene.trajectory(13.0).pose(6.0)
mis = mi.load_dict(scene_dict(scene.describe(), json.loads(sys.argv[4])))
fov = scenes.image_stats.synthetic_camera(scene, W, H).fov_x_deg
for label, integ, spp in json.loads(sys.argv[5]):
    sd = sensor_dict(pose, width=W, height=H, fov_deg=fov, spp=spp)
    imgs = []; ts = []
    for seed in (1, 2, 1):
        t = time.perf_counter()
        imgs.append(np.array(mi.render(mis, sensor=mi.load_dict(sd), integrator=mi.load_dict(integ), spp=spp, seed=seed), dtype=np.float64)[..., :3] @ [0.2126, 0.7152, 0.0722])
        ts.append(time.perf_counter() - t)
    t = min(ts[1:])
    a, b = imgs[:2]; dd = (a - b) / np.sqrt(2); m = 0.5 * (a + b)
    rel = np.sqrt(np.mean(dd**2)) / m.mean()
    loc = np.median(np.abs(dd) / np.maximum(m, 1e-3 * m.mean()))
    print(f"{key:>13} {label:>16} spp {spp:4d} mean {m.mean():8.4f} noise {100*rel:6.2f} % median-rel {100*loc:6.2f} % {t:.2f} s  ; var*time {rel**2*t*1e3:.1f} medvar*time {loc**2*t*1e3:.1f}", flush=True)
