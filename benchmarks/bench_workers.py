"""Method workers: closed-loop throughput for 1, 2, 4 jobs and inline, and memory per worker; not a test.

Usage: python benchmarks/bench_workers.py [SEQUENCE] [--cycles 90] [--modes borealhdr,paper]
                                          [--configs process:1,process:2,process:4,inline:1,inline:2]
                                          [--frames png,cache] [--rounds 1]
                                          [--cache-level 3]

A recording of ``--cycles`` cycles is replayed from the complete stereo cycles of SEQUENCE (the
shared sample by default; :func:`bench_save.replay_recording`, hard links).  Every configuration
(mode x workers:jobs x frames) runs the seven methods in closed loop, stereo, no saving
(``iter_run(..., emulate_right=True)``), in this process, round-robin over ``--rounds`` so that
other load falls on all alike.  Printed per configuration: wall s of the whole call (workers
started and stopped included), cycles/s over it, steady cycles/s after the first cycle, whether
the exposure trajectories equal those of the first configuration; where the CPU goes (the
run's process, each method's worker); and, for worker runs, each worker's resident and
proportional memory (``/proc/PID/smaps_rollup``: Rss, Pss, private) at
the last cycle.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_save import default_sequence, replay_recording  # noqa: E402
from emulator.io.borealhdr import load_sequence, sequence_response  # noqa: E402
from emulator.playback import RunConfig, RunStats, closed_loop, prepare_run  # noqa: E402
from emulator.playback.workers import MethodWorker  # noqa: E402
from emulator.orchestration.framecache import build_frame_cache  # noqa: E402

INITIAL_MS, RANGE_MS = 4.0, (0.02, 50.0)


def _memory_kib(pid: int) -> dict:
    out = {}
    try:
        text = Path(f"/proc/{pid}/smaps_rollup").read_text()
    except OSError:
        return out
    for line in text.splitlines():
        key, _, rest = line.partition(":")
        if key in ("Rss", "Pss", "Private_Clean", "Private_Dirty"):
            out[key] = int(rest.split()[0])
    out["Private"] = out.pop("Private_Clean", 0) + out.pop("Private_Dirty", 0)
    return out


def _cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process so far (/proc/PID/stat)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def one_run(seq, response, mode, workers, jobs):
    cfg = RunConfig(mode=mode, initial_ms=INITIAL_MS, range_ms=RANGE_MS, jobs=jobs, workers=workers)
    stats = RunStats()
    t0, c0 = time.perf_counter(), time.process_time()
    prep = prepare_run(seq, "all", cfg, response, stats=stats)
    traj = {name: [] for name in prep.methods}
    memory, per_worker = {}, {}
    n = len(seq.cycles)
    for cs in closed_loop(prep.provider, prep.methods, cfg, want_right=True, stats=stats):
        for name, st in cs.steps.items():
            traj[name].append((st.target_ms, st.bracket_ms))
        if cs.cycle == seq.cycles[n - 1].index:
            memory = {name: _memory_kib(m.pid()) for name, m in prep.methods.items() if isinstance(m, MethodWorker)}
            per_worker = {name: _cpu_s(m.pid()) for name, m in prep.methods.items() if isinstance(m, MethodWorker)}
    wall = time.perf_counter() - t0
    timing = stats.as_dict()
    timing["run_cpu_s"] = time.process_time() - c0  # the run's process: decoding, emulation, gray images, rows
    timing["worker_cpu_s"] = per_worker  # each method's worker, whole life (start-up and every call)
    timing["cpu_s"] = timing["run_cpu_s"] + sum(per_worker.values())  # this process and its method workers
    return wall, timing, traj, memory


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequence", nargs="?", type=Path, default=default_sequence())
    ap.add_argument("--cycles", type=int, default=90)
    ap.add_argument("--modes", default="borealhdr,paper")
    ap.add_argument("--configs", default="process:1,process:2,process:4,inline:1,inline:2")
    ap.add_argument("--frames", default="png")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--cache-level", type=int, default=3,
                    help="zstandard level of the frame cache (exposim cache --level; -1 reads fastest)")
    ap.add_argument("--replay-dir", type=Path, default=None,
                    help="build the replayed recording here and keep it (default: a temporary folder)")
    args = ap.parse_args(argv)
    configs = [(w, int(j)) for w, j in (c.split(":") for c in args.configs.split(","))]
    with tempfile.TemporaryDirectory(prefix="exposim-bench-workers-") as tmp:
        rec = args.replay_dir if args.replay_dir is not None else Path(tmp) / "replay"
        if not rec.is_dir():
            replay_recording(args.sequence, rec, args.cycles)
        seqs = {"png": load_sequence(rec, frame_cache=False, imu_warning=False)}
        if "cache" in args.frames:
            build_frame_cache(rec, Path(tmp) / "frames", level=args.cache_level)
            seqs["cache"] = load_sequence(rec, frame_cache=Path(tmp) / "frames", imu_warning=False)
        response = sequence_response(load_sequence(args.sequence, imu_warning=False))  # the source's camera
        print(f"{args.cycles} cycles replayed from {args.sequence.name}; {os.cpu_count()} CPUs; load average "
              f"{os.getloadavg()[0]:.1f} at start", flush=True)
        results: dict = {}
        for rnd in range(args.rounds):
            for mode in args.modes.split(","):
                for frames in args.frames.split(","):
                    for workers, jobs in configs:
                        wall, timing, traj, memory = one_run(seqs[frames], response, mode, workers, jobs)
                        key = (mode, frames, workers, jobs)
                        results.setdefault(key, []).append((wall, timing, traj, memory))
                        print(f"round {rnd + 1} {mode:9s} {frames:5s} {workers:7s} jobs {jobs}: {wall:6.1f} s, "
                              f"{args.cycles / wall:5.2f} cycles/s, steady {timing['steady_cycles_per_s']:5.2f}, "
                              f"CPU {timing['cpu_s'] / args.cycles:.3f} s/cycle, "
                              f"load {os.getloadavg()[0]:.1f}", flush=True)
        print(f"\n{'mode':9s} {'frames':6s} {'workers':7s} {'jobs':>4s} {'cycles/s':>17s} {'steady':>17s} "
              f"{'CPU s/cycle':>17s} same")
        first = {}
        for (mode, frames, workers, jobs), runs in results.items():
            ref = first.setdefault(mode, runs[0][2])
            rates = ", ".join(f"{args.cycles / r[0]:.2f}" for r in runs)
            steady = ", ".join(f"{r[1]['steady_cycles_per_s']:.2f}" for r in runs)
            same = all(r[2] == ref for r in runs)
            cpu = ", ".join(f"{r[1]['cpu_s'] / args.cycles:.3f}" for r in runs)
            print(f"{mode:9s} {frames:6s} {workers:7s} {jobs:4d} {rates:>17s} {steady:>17s} {cpu:>17s} "
                  f"{'yes' if same else 'NO'}")
        print("\nwhere the CPU goes, s per cycle (first round): the run's process (decoding, emulation, gray "
              "images, rows), then each method's worker")
        for (mode, frames, workers, jobs), runs in results.items():
            t = runs[0][1]
            parts = " ".join(f"{name} {cpu / args.cycles:.3f}" for name, cpu in t["worker_cpu_s"].items())
            print(f"  {mode:9s} {frames:5s} {workers:7s} jobs {jobs}: run {t['run_cpu_s'] / args.cycles:.3f}"
                  f"{' | ' + parts if parts else ''}; decoding {t['decodes'] / args.cycles:.1f} images per cycle, "
                  f"{t['decode_ms_per_image']:.1f} ms each (wall)")
        mem = [(k, r[3]) for k, runs in results.items() for r in runs if r[3]]
        if mem:
            (mode, frames, workers, jobs), m = mem[0]
            print(f"\nmemory per worker at the last cycle ({mode}, {frames}, jobs {jobs}), MiB: Rss / Pss / private")
            for name, kib in m.items():
                print(f"  {name:13s} {kib.get('Rss', 0) / 1024:7.1f} {kib.get('Pss', 0) / 1024:7.1f} "
                      f"{kib.get('Private', 0) / 1024:7.1f}")
        print(f"load average {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    sys.exit(main())
