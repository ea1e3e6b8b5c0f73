"""Render speed of the scenes: seconds per frame for llvm_ad_rgb and scalar_rgb, and the cache-hit cost.

Each variant runs in its own child process (Dr.Jit aborts the whole process
when LLVM is unusable, and the first render of a process pays the JIT compile,
which is reported separately).  Optionally runs the noise-target spp selection
first and reports its spp-vs-noise curve.

Usage::

    python benchmarks/bench_render.py                       # forest_winter, 480x300, 64 spp
    python benchmarks/bench_render.py --spp 64 --frames 3 --scene forest_edge
    python benchmarks/bench_render.py --select --select-size 160x100   # spp from the noise target
    python benchmarks/bench_render.py --json bench.json

Renders here bypass the cache (except the cache-hit measurement, which uses a
temporary folder).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from emulator.io.files import strict_json  # noqa: E402


def _pose(scene):
    return scene.default_pose() if scene.is_static else scene.trajectory(10.0).pose(0.0)


def worker(args) -> dict:
    """Runs in a child process: time renders with one variant."""
    import scenes
    from scenes.render import effective_spp
    from scenes.variant import ensure_variant

    w, h = (int(v) for v in args.size.split("x"))
    jit = not args.worker.startswith("scalar")
    t0 = time.perf_counter()
    ensure_variant(args.worker)
    t_probe = time.perf_counter() - t0
    scene = scenes.get_scene(args.scene, seed=0)
    t0 = time.perf_counter()
    scene.describe()
    t_describe = time.perf_counter() - t0
    pose = _pose(scene)
    times = []
    for i in range(args.frames + (1 if jit else 0)):
        t0 = time.perf_counter()
        img = scenes.render(scene, pose, width=w, height=h, spp=args.spp, seed=i, cache_dir=False,
                            variant=args.worker)
        times.append(time.perf_counter() - t0)
    # a JIT variant compiles its kernels in the first render: time it apart (scalar has nothing to compile)
    t_first = times[0]
    if jit:
        times = times[1:]
    spp = effective_spp(args.spp)
    return {
        "variant": args.worker,
        "scene": args.scene,
        "size": [w, h],
        "spp": spp,
        "probe_s": t_probe,
        "describe_s": t_describe,
        "first_render_s": t_first,
        "s_per_frame": statistics.median(times),
        "frame_times_s": times,
        "msamples_per_s": w * h * spp / statistics.median(times) / 1e6,
        "dynamic_range_db": scenes.dynamic_range_db(img),
    }


def run_worker(variant: str, args) -> dict:
    cmd = [sys.executable, __file__, "--worker", variant, "--scene", args.scene, "--size", args.size,
           "--spp", str(args.spp), "--frames", str(args.frames)]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
        return {"variant": variant, "error": f"exit {proc.returncode}: {' | '.join(tail)}"}
    return json.loads(lines[-1])


def cache_hit_cost(args, variant: str) -> dict:
    """Time render() on a cache hit: in a warm process, and in a fresh process (import included)."""
    import scenes

    w, h = (int(v) for v in args.size.split("x"))
    scene = scenes.get_scene(args.scene, seed=0)
    pose = _pose(scene)
    with tempfile.TemporaryDirectory() as tmp:
        spp = 4  # cheap to fill; a hit costs the same whatever spp made the file
        img = scenes.render(scene, pose, width=w, height=h, spp=spp, seed=0, cache_dir=tmp, variant=variant)
        (path,) = Path(tmp).rglob("*.exr")
        hits = []
        for _ in range(20):
            t0 = time.perf_counter()
            again = scenes.render(scene, pose, width=w, height=h, spp=spp, seed=0, cache_dir=tmp, variant=variant)
            hits.append(time.perf_counter() - t0)
        assert again.tobytes() == img.tobytes()
        code = (
            "import time, sys; t0 = time.perf_counter(); import scenes; t1 = time.perf_counter();"
            f"s = scenes.get_scene({args.scene!r}); p = (s.default_pose() if s.is_static else "
            "s.trajectory(10.0).pose(0.0)); t2 = time.perf_counter();"
            f"scenes.render(s, p, width={w}, height={h}, spp={spp}, seed=0, cache_dir={tmp!r}); "
            "t3 = time.perf_counter(); print(t1 - t0, t3 - t2, 'mitsuba' in sys.modules)"
        )
        env = dict(os.environ, EXPOSIM_MITSUBA_VARIANT=variant)
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env,
                             check=True).stdout.split()
        return {
            "variant": variant,
            "exr_bytes": path.stat().st_size,
            "hit_s_median": statistics.median(hits),
            "fresh_process_import_s": float(out[0]),
            "fresh_process_hit_s": float(out[1]),
            "fresh_process_imported_mitsuba": out[2] == "True",
        }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="forest_winter")
    p.add_argument("--size", default="480x300")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--frames", type=int, default=2, help="timed frames per variant (after one warm-up)")
    p.add_argument("--variants", default="llvm_ad_rgb,scalar_rgb")
    p.add_argument("--scalar-frames", type=int, default=1, help="timed frames for scalar_rgb (slow)")
    p.add_argument("--select", action="store_true", help="run select_spp first and use its spp")
    p.add_argument("--select-size", default="160x100", help="image size for the spp selection")
    p.add_argument("--json", type=Path, default=None, help="also write the results here")
    p.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)

    if args.worker:
        print(json.dumps(worker(args)))
        return 0

    import scenes

    results: dict = {"scene": args.scene, "size": args.size, "cpu_count": os.cpu_count()}
    if args.select:
        sw, sh = (int(v) for v in args.select_size.split("x"))
        scene = scenes.get_scene(args.scene, seed=0)
        t0 = time.perf_counter()
        sel = scenes.select_spp(scene, _pose(scene), width=sw, height=sh, stop_when_met=False,
                                candidates=(1, 4, 16, 64, 256))
        results["spp_selection"] = sel.to_dict()
        results["spp_selection_s"] = time.perf_counter() - t0
        print(f"spp selection on {args.scene} at {args.select_size} (sensor noise at the 32 ms bracket):")
        print("   spp  noise_ratio  render_rel  sensor_rel")
        for row in sel.curve:
            print(f"  {row['spp']:4d}  {row['noise_ratio']:11.3f}  {row['render_noise_rel']:10.4f}  "
                  f"{row['sensor_noise_rel']:10.4f}")
        print(f"  chosen spp {sel.spp} (target met: {sel.met}); 1/spp law predicts {sel.predicted_spp} spp")
        args.spp = sel.spp

    rows = []
    for variant in [v.strip() for v in args.variants.split(",") if v.strip()]:
        frames = args.scalar_frames if variant.startswith("scalar") else args.frames
        sub = argparse.Namespace(**{**vars(args), "frames": frames})
        rows.append(run_worker(variant, sub))
    results["renders"] = rows
    print(f"\n{args.scene} at {args.size}, {os.cpu_count()} CPU(s):")
    print("  variant        spp   s/frame   Msamples/s   first render (incl. JIT)   DR dB")
    for r in rows:
        if "error" in r:
            print(f"  {r['variant']:<13}  unavailable: {r['error']}")
        else:
            print(f"  {r['variant']:<13} {r['spp']:4d}  {r['s_per_frame']:8.2f}  {r['msamples_per_s']:10.3f}  "
                  f"{r['first_render_s']:24.2f}  {r['dynamic_range_db']:6.1f}")
    ok = [r["variant"] for r in rows if "error" not in r]
    if ok:
        hit = cache_hit_cost(args, ok[0])
        results["cache_hit"] = hit
        print(f"\ncache hit ({args.size}, EXR {hit['exr_bytes'] / 1024:.0f} KiB): "
              f"{hit['hit_s_median'] * 1e3:.1f} ms in a warm process; fresh process: import scenes "
              f"{hit['fresh_process_import_s']:.2f} s + hit {hit['fresh_process_hit_s'] * 1e3:.0f} ms "
              f"(Mitsuba imported: {hit['fresh_process_imported_mitsuba']})")
    if args.json:
        args.json.write_text(strict_json(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
