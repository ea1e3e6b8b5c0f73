"""Two-seed noise of integrator components at equal spp (luminance), at pixel scale and blurred."""
import sys, time, json
import numpy as np, cv2
import scenes, scenes.image_stats
from scenes.render import _loaded_scene
from scenes._mitsuba import sensor_dict
from scenes.variant import choose_variant, ensure_variant
from validation.common import study_scene
import mitsuba as mi
v = choose_variant(); ensure_variant(v); mi.set_variant(v)
key, W, H = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
scene = scenes.get_scene(study_scene(key).scene, seed=0)
pose = scene.trajectory(13.0).pose(6.0)
mis = _loaded_scene(scene, v)
fov = scenes.image_stats.synthetic_camera(scene, W, H).fov_x_deg
def run(integ, spp, sampler, seed):
    sd = sensor_dict(pose, width=W, height=H, fov_deg=fov, spp=spp); sd["sampler"]["type"] = sampler
    t = time.perf_counter()
    img = np.array(mi.render(mis, sensor=mi.load_dict(sd), integrator=mi.load_dict(integ), spp=spp, seed=seed), dtype=np.float64)
    return img[..., :3] @ np.array([0.2126, 0.7152, 0.0722]), time.perf_counter() - t
for name, integ, spp, sampler in json.loads(sys.argv[4]):
    a, t = run(integ, spp, sampler, 1); b, _ = run(integ, spp, sampler, 2)
    d = (a - b) / np.sqrt(2); m = 0.5 * (a + b)
    rel = np.sqrt(np.mean(d**2)) / m.mean()
    db = cv2.GaussianBlur(d, (0, 0), 1.6)
    relb = np.sqrt(np.mean(db**2)) / m.mean()
    print(f"{key} {name:>10} {sampler:>12} spp {spp:4d} mean {m.mean():8.4f} noise {100*rel:6.2f} % blurred {100*relb:6.2f} %  {t:6.2f} s", flush=True)
