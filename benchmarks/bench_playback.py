"""Throughput of the seven-method stereo closed loop on the shared sample, against a naive loop.

Usage: python benchmarks/bench_playback.py [SEQUENCE] [--mode paper|borealhdr] [--jobs N]
                                           [--repeat N] [--skip-naive] [--ref-methods]

Prints, measured in one run on full-resolution frames:

* PNG decode ms per image, emulation ms per image (lookup table vs per-pixel ``np.interp``);
* per-method ms per frame as measured inside the run;
* the exposim loop (``emulator.playback.iter_run``, all seven methods, left and right images
  emulated): cycles/s with ``--jobs 1`` and ``--jobs N``;
* the naive loop: the methods one after another, each re-reading its cycles the way the
  reference code does (decode every bracket of both cameras, the saturation of every
  bracket), emulating left and right with per-pixel ``np.interp``; the same method code
  (``--ref-methods``: REF-style per-pixel method implementations from
  ``bench_autoexposure.py``, borealhdr semantics);
* the speed-up, and whether both loops produced identical exposure trajectories.

The recorder's own rate is one bracket sweep per ~273 ms: 3.66 cycles/s.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from emulator.autoexposure import METHOD_NAMES, METHODS  # noqa: E402
from emulator.io.borealhdr import load_sequence, sequence_response
from emulator.io.png import read_png16  # noqa: E402
from emulator.core.emulate import apply_lut  # noqa: E402
from emulator.playback import RunStats, iter_run  # noqa: E402
from emulator.core.select import higher_no_sat, saturated_fraction  # noqa: E402
from _timing import SAMPLE_SEQ, median_ms  # noqa: E402

DEFAULT_SEQ = SAMPLE_SEQ
RECORDER_CYCLES_PER_S = 3.66
INITIAL_MS, RANGE_MS = 4.0, (0.02, 50.0)



def build(name, mode, response, ref_methods):
    if ref_methods:
        from bench_autoexposure import ref_methods as refs

        return refs(response)[name]
    kw = {"response": response} if name == "zhang" else {}
    return METHODS[name](mode=mode, range_ms=None, **kw)


def per_pixel_emulation(raw, ratio, response):
    """The reference code's emulation: interpolate f^-1 and f at every pixel, in float."""
    dn = np.arange(response.white_level + 1, dtype=np.float64)
    h = np.interp(raw.astype(np.float64), dn, response.g) * ratio
    out = np.rint(np.interp(h, response.g, dn))
    return np.clip(out, response.black_level, response.white_level).astype(np.uint16)


def naive_run(seq, response, mode, ref_methods):
    """Methods one after another; each cycle re-decodes every bracket of both cameras."""
    white, black = seq.white_level, seq.black_level
    trajectories, method_s = {}, {}
    t_start = time.perf_counter()
    for name in METHOD_NAMES:
        method = build(name, mode, response, ref_methods)
        target, traj, spent = INITIAL_MS, [], 0.0
        for cycle in seq.cycles:
            avail = cycle.available(("left", "right"))
            if not avail:
                continue
            images = {cam: {e: cycle.frames[cam][e].load() for e in avail} for cam in ("left", "right")}
            sats = {e: saturated_fraction(images["left"][e], white_level=white, black_level=black) for e in avail}
            key = higher_no_sat(target, sats, white_level=white, black_level=black)
            ratio = target / key
            left = per_pixel_emulation(images["left"][key], ratio, response)
            per_pixel_emulation(images["right"][key], ratio, response)
            t0 = time.perf_counter()
            proposed = method.next_exposure(left, target)
            spent += time.perf_counter() - t0
            traj.append((target, float(key)))
            target = min(max(proposed, RANGE_MS[0]), RANGE_MS[1])
        trajectories[name] = traj
        method_s[name] = spent
    return time.perf_counter() - t_start, trajectories, method_s


def fast_run(seq, response, mode, jobs):
    stats = RunStats()
    traj = {name: [] for name in METHOD_NAMES}
    t0 = time.perf_counter()
    for cs in iter_run(seq, "all", mode=mode, response=response, initial_ms=INITIAL_MS, range_ms=RANGE_MS,
                       jobs=jobs, emulate_right=True, stats=stats):
        for name, st in cs.steps.items():
            traj[name].append((st.target_ms, st.bracket_ms))
    return time.perf_counter() - t0, traj, stats


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequence", nargs="?", type=Path, default=DEFAULT_SEQ)
    ap.add_argument("--mode", choices=("paper", "borealhdr"), default="paper")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=2, help="repetitions of the exposim loop (best is kept)")
    ap.add_argument("--skip-naive", action="store_true")
    ap.add_argument("--ref-methods", action="store_true",
                    help="naive loop with REF-style per-pixel method implementations (implies --mode borealhdr)")
    args = ap.parse_args(argv)
    if args.ref_methods:
        args.mode = "borealhdr"

    seq = load_sequence(args.sequence)
    response = sequence_response(seq)
    n_cycles = sum(1 for c in seq.cycles if c.available(("left", "right")))
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"sequence {seq.path.name}: {n_cycles} usable cycles, {len(seq.brackets)} brackets, stereo; "
          f"mode {args.mode}; {os.cpu_count()} CPUs, load average {load:.1f} at start")

    frame = seq[1].frames["left"][8.0]
    raw = frame.load()
    decode_ms = median_ms(lambda: read_png16(frame.path), 5)
    table, _ = response.lut(5.3 / 8.0)
    lut_ms = median_ms(lambda: apply_lut(table, raw), 10)
    interp_ms = median_ms(lambda: per_pixel_emulation(raw, 5.3 / 8.0, response), 3)
    assert np.array_equal(apply_lut(table, raw), per_pixel_emulation(raw, 5.3 / 8.0, response))
    print(f"decode {decode_ms:.1f} ms/image; emulation {lut_ms:.1f} ms/image (lookup table) vs "
          f"{interp_ms:.1f} ms/image (per-pixel np.interp)")

    fast_run(seq, response, args.mode, 1)  # warm-up: imports, caches, lookup tables
    results = {}
    for jobs in sorted({1, args.jobs}):
        best = None
        for _ in range(max(1, args.repeat)):
            wall, traj, stats = fast_run(seq, response, args.mode, jobs)
            if best is None or wall < best[0]:
                best = (wall, traj, stats)
        results[jobs] = best
    wall1, traj_fast, stats1 = results[1]
    print("\nper-method ms per full-resolution frame (inside the exposim loop, jobs=1):")
    for name, ms in stats1.as_dict()["method_ms_per_frame"].items():
        print(f"  {name:13s} {ms:8.1f}")
    d = stats1.as_dict()
    print(f"  {'(emulation)':13s} {d['emulate_ms_per_image']:8.1f}   per image, {d['emulations']} images")
    print(f"  {'(decode)':13s} {d['decode_ms_per_image']:8.1f}   per image, {d['decodes']} images decoded")
    print("\nexposim loop, 7 methods, stereo:")
    for jobs, (wall, _, stats) in results.items():
        print(f"  jobs={jobs}: {n_cycles / wall:6.2f} cycles/s ({wall:.2f} s for {n_cycles} cycles, "
              f"{stats.decodes} decodes)  [recorder: {RECORDER_CYCLES_PER_S} cycles/s]")
    if args.skip_naive:
        return
    naive_wall, traj_naive, naive_method_s = naive_run(seq, response, args.mode, args.ref_methods)
    label = "REF-style methods" if args.ref_methods else "same method code"
    n_decodes = 7 * sum(2 * len(c.available(("left", "right"))) for c in seq.cycles)
    print(f"\nnaive loop ({label}, methods one after another, {n_decodes} decodes, per-pixel np.interp):")
    print(f"  {n_cycles / naive_wall:6.3f} cycles/s ({naive_wall:.2f} s; methods themselves "
          f"{sum(naive_method_s.values()):.2f} s)")
    best_jobs = min(results, key=lambda j: results[j][0])
    ratio = naive_wall / results[best_jobs][0]
    print(f"\nspeed-up exposim (jobs={best_jobs}) / naive: {ratio:.1f}x (jobs=1: {naive_wall / wall1:.1f}x)")
    print("same trajectories: " + _compare(traj_fast, traj_naive))


def _compare(a: dict, b: dict) -> str:
    """'identical', or the largest relative difference of the targets and whether brackets agree."""
    if a == b:
        return "identical"
    worst, brackets = 0.0, True
    for name in a:
        if len(a[name]) != len(b[name]):
            return f"NO ({name}: {len(a[name])} vs {len(b[name])} cycles)"
        for (ta, ba), (tb, bb) in zip(a[name], b[name]):
            worst = max(worst, abs(ta - tb) / max(abs(tb), 1e-300))
            brackets &= ba == bb
    return f"targets within {worst:.1e} (relative), brackets {'identical' if brackets else 'DIFFER'}"


if __name__ == "__main__":
    main()
