"""Speed of the synthetic camera: one 1920x1200 raw capture, on one core.

Usage: python benchmarks/bench_capture.py [--preset borealhdr] [--repeat N]

Prints ms per frame for noisy and noiseless captures of a procedural HDR chart
(``synth.procedural.hdr_chart``, 100 dB, RGB float32) at three bracket exposures; a dark
frame of a camera without read noise (every site through numpy's exact Poisson sampler:
the slowest case, which no preset reaches); and, for scale, a naive pipeline (numpy
Poisson for every site, numpy normals, np.interp through the response).
Target: the camera's frame rate, 22 frames/s, i.e. under 45 ms per noisy frame.

Threads are pinned to one (OMP / BLAS / OpenCV) before numpy loads.  Each figure is the
median and the minimum over ``--repeat`` runs of wall-clock time, and the median and
minimum of the process CPU time; on a shared, loaded machine the minimum is the least
disturbed figure and the load average is printed with the results.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

import synth  # noqa: E402
from synth.imaging import mean_electrons  # noqa: E402
from synth.procedural import hdr_chart  # noqa: E402

cv2.setNumThreads(1)


def timeit(fn, repeat: int) -> tuple[float, float, float, float]:
    """(median wall ms, min wall ms, median CPU ms, min CPU ms)."""
    fn()  # warm caches (vignetting map, gather indices, quantiser tables, normal table)
    wall, cpu = [], []
    for _ in range(repeat):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return (1e3 * statistics.median(wall), 1e3 * min(wall), 1e3 * statistics.median(cpu), 1e3 * min(cpu))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--preset", default="borealhdr", choices=synth.PRESETS)
    ap.add_argument("--repeat", type=int, default=21)
    args = ap.parse_args(argv)

    cam = synth.Camera.preset(args.preset)
    radiance = hdr_chart(cam.width, cam.height, seed=0, dynamic_range_db=100.0)
    seeds = iter(range(10**9))
    # a camera without read noise draws exact Poisson below 25 e-: a dark frame there is
    # the slowest case (every site through numpy's Poisson sampler)
    quiet = cam.replace(read_noise_e=0.0)
    dark = np.full_like(radiance, 10.0 / cam.radiance_scale)  # 10 e- per green site at 1 ms

    print(f"camera {args.preset!r} {cam.width}x{cam.height}, radiance float32 (H, W, 3), one thread; "
          f"wall ms median / min, CPU ms median / min; {args.repeat} runs each (fewer for the slow rows)")
    rows = []
    for t in (1.0, 8.0, 32.0):
        rows.append((f"noisy,     chart, {t:4g} ms",
                     timeit(lambda: synth.capture(radiance, t, cam, seed=next(seeds)), args.repeat)))
        rows.append((f"noiseless, chart, {t:4g} ms",
                     timeit(lambda: synth.capture(radiance, t, cam, seed=None, noise=False), args.repeat)))
    rows.append(("noisy, no read noise, dark (exact Poisson), 1 ms",
                 timeit(lambda: synth.capture(dark, 1.0, quiet, seed=next(seeds)), max(3, args.repeat // 3))))

    g, dn = cam.response.g, np.arange(cam.white_level + 1, dtype=np.float64)

    def naive():
        rng = np.random.default_rng(next(seeds))
        e = mean_electrons(radiance, 8.0, cam, np.float64)
        e = rng.poisson(e) + rng.standard_normal(e.shape) * cam.read_noise_e
        h = e * cam.h_per_electron
        return np.clip(np.floor(np.interp(h, g, dn) + 0.5), cam.black_level, cam.white_level).astype(np.uint16)

    rows.append(("naive (numpy Poisson + normal + interp), 8 ms", timeit(naive, max(3, args.repeat // 5))))
    for label, (med, lo, cpu, cpu_lo) in rows:
        print(f"{label:52s} wall {med:6.1f} / {lo:6.1f}   cpu {cpu:6.1f} / {cpu_lo:6.1f}")
    print(f"target: < {1000 / 22:.1f} ms per noisy frame (22 frames/s); load average now "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
