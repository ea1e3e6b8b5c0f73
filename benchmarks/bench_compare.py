"""This checkout's closed loop against another checkout's, A/B interleaved; not a test.

Usage: python benchmarks/bench_compare.py --baseline DIR [SEQUENCE] [--modes paper,borealhdr]
                                          [--jobs 1,2] [--frames png,cache] [--rounds N]

Runs the seven-method stereo loop (``emulator.playback.iter_run``, left and right emulated,
initial 4 ms, range 0.02-50 ms) of each checkout in its own Python process
(``PYTHONPATH=<checkout>``), alternating baseline and this checkout ``--rounds`` times, so
that the load of other processes falls on both alike.  Each process runs every
configuration (mode x jobs x frames: PNG decoded, or the decoded-frame cache, built by the
same checkout into a temporary folder) once after a warm-up.

Prints, per configuration and checkout: the least CPU seconds per cycle over the rounds (the
run's process, all threads, and its method workers where the checkout has them, counted
through the fork server that starts them once they have ended; the figure to compare on a
shared machine), the median, the best
wall-clock cycles/s (meaningful on an idle machine only), and whether the two checkouts'
exposure trajectories are equal.  The load average is printed at the start and the end.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
INITIAL_MS, RANGE_MS = 4.0, (0.02, 50.0)


def _forkserver_cpu_s() -> float:
    """CPU seconds of the method workers so far: the fork server's own and those of its ended
    children (a checkout whose methods run in worker processes; 0 for one that has none)."""
    try:
        from multiprocessing import forkserver

        pid = forkserver._forkserver._forkserver_pid
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split() if pid else None
    except (ImportError, AttributeError, OSError):
        return 0.0
    if not fields:
        return 0.0
    return sum(int(f) for f in fields[11:15]) / os.sysconf("SC_CLK_TCK")  # utime, stime, cutime, cstime


def _worker(args) -> None:
    """One process of one checkout: every configuration once, one JSON line each."""
    from emulator.io.borealhdr import load_sequence, sequence_response
    from emulator.playback import RunStats, iter_run

    try:
        from emulator.orchestration.framecache import build_frame_cache
    except ImportError:  # checkouts before the tools layer
        from emulator.io.framecache import build_frame_cache

    cache_dir = Path(args.cache_dir)
    if "cache" in args.frames_list and not (cache_dir / ".built").exists():
        build_frame_cache(args.sequence, cache_dir)
        (cache_dir / ".built").write_text("")
    seqs = {"png": load_sequence(args.sequence, frame_cache=False)}
    if "cache" in args.frames_list:
        seqs["cache"] = load_sequence(args.sequence, frame_cache=cache_dir)
    response = sequence_response(seqs["png"])

    def loop(mode, jobs, frames):
        traj = []
        n = 0
        for cs in iter_run(seqs[frames], "all", mode=mode, response=response, initial_ms=INITIAL_MS,
                           range_ms=RANGE_MS, jobs=jobs, emulate_right=True, stats=RunStats()):
            n += 1
            traj.append(sorted((name, st.target_ms, st.bracket_ms) for name, st in cs.steps.items()))
        return n, hashlib.sha256(repr(traj).encode()).hexdigest()[:16]

    for mode in args.modes_list:
        loop(mode, 1, "png")  # warm-up: imports, lookup tables
    for mode in args.modes_list:
        for jobs in args.jobs_list:
            for frames in args.frames_list:
                w0, c0, f0 = time.perf_counter(), time.process_time(), _forkserver_cpu_s()
                n, digest = loop(mode, jobs, frames)
                wall = time.perf_counter() - w0
                cpu = time.process_time() - c0 + _forkserver_cpu_s() - f0  # the run's process and its workers
                print(json.dumps({"mode": mode, "jobs": jobs, "frames": frames, "cycles": n, "wall_s": wall,
                                  "cpu_s": cpu, "trajectories": digest}), flush=True)


def _run(checkout: Path, args, cache_dir: Path) -> list[dict]:
    env = dict(os.environ, PYTHONPATH=str(checkout))
    cmd = [sys.executable, "-W", "ignore", str(HERE / "bench_compare.py"), "--worker", str(args.sequence),
           "--cache-dir", str(cache_dir), "--modes", args.modes, "--jobs", args.jobs, "--frames", args.frames]
    proc = subprocess.run(cmd, env=env, cwd=str(checkout), capture_output=True, text=True)
    if proc.returncode != 0:  # e.g. a recording without a response file that an older checkout needs
        last = (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
        raise SystemExit(f"bench_compare: the run of {checkout} failed: {last}")
    out = proc.stdout
    return [json.loads(line) for line in out.splitlines() if line.startswith("{")]


def main(argv=None):
    sys.path.insert(0, str(HERE))
    from _timing import SAMPLE_SEQ

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequence", nargs="?", type=Path, default=SAMPLE_SEQ)
    ap.add_argument("--baseline", type=Path, help="the other checkout (a git worktree of the old commit)")
    ap.add_argument("--modes", default="paper,borealhdr")
    ap.add_argument("--jobs", default="1,2")
    ap.add_argument("--frames", default="png,cache")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--cache-dir", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    args.modes_list = [m for m in args.modes.split(",") if m]
    args.jobs_list = [int(j) for j in args.jobs.split(",") if j]
    args.frames_list = [f for f in args.frames.split(",") if f]
    if args.worker:
        return _worker(args)
    if args.baseline is None:
        ap.error("--baseline DIR is required")
    trees = {"baseline": args.baseline.resolve(), "this": HERE.parent}
    print(f"baseline {trees['baseline']}, this {trees['this']}; {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.1f} at start", flush=True)
    runs: dict = {}
    with tempfile.TemporaryDirectory(prefix="exposim-compare-") as tmp:
        for rnd in range(args.rounds):
            for label, tree in trees.items():
                for row in _run(tree, args, Path(tmp) / label):
                    key = (row["mode"], row["jobs"], row["frames"])
                    runs.setdefault(key, {}).setdefault(label, []).append(row)
            print(f"  round {rnd + 1}/{args.rounds} done, load average {os.getloadavg()[0]:.1f}", flush=True)
    print(f"\n{'mode':9s} {'jobs':>4s} {'frames':6s} | {'baseline CPU s/cycle min / median':>33s} "
          f"{'cycles/s':>8s} | {'this CPU s/cycle min / median':>29s} {'cycles/s':>8s} | {'CPU change':>10s}  same")
    for (mode, jobs, frames), by in runs.items():
        cells = []
        for label in ("baseline", "this"):
            rows = by[label]
            per = [r["cpu_s"] / r["cycles"] for r in rows]
            best = max(r["cycles"] / r["wall_s"] for r in rows)
            cells.append((min(per), statistics.median(per), best, {r["trajectories"] for r in rows}))
        (b_min, b_med, b_rate, b_tr), (t_min, t_med, t_rate, t_tr) = cells
        same = "yes" if b_tr == t_tr and len(t_tr) == 1 else "NO"
        print(f"{mode:9s} {jobs:4d} {frames:6s} | {b_min:21.3f} / {b_med:.3f} {b_rate:8.2f} | "
              f"{t_min:17.3f} / {t_med:.3f} {t_rate:8.2f} | {100 * (t_min / b_min - 1):+9.1f}%  {same}")
    print(f"\nload average {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
