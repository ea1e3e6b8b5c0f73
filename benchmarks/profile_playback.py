"""cProfile of the seven-method stereo playback loop on the shared sample (not a test).

Usage: python benchmarks/profile_playback.py [SEQUENCE] [--mode paper|borealhdr] [--top N] [--repeat N]

Runs ``emulator.playback.iter_run`` (all seven methods, left and right emulated, jobs=1, so
the profile sees every call on one thread) ``--repeat`` times after a warm-up run, and
prints the functions with the largest own time and cumulative time, then the loop's own
per-step timers (decode, emulation, per-method ms per frame).
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from emulator.io.borealhdr import load_sequence, sequence_response  # noqa: E402
from emulator.playback import RunStats, iter_run  # noqa: E402
from _timing import SAMPLE_SEQ  # noqa: E402


def loop(seq, response, mode, stats):
    for _ in iter_run(seq, "all", mode=mode, response=response, initial_ms=4.0, range_ms=(0.02, 50.0), jobs=1,
                      emulate_right=True, stats=stats):
        pass


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequence", nargs="?", type=Path, default=SAMPLE_SEQ)
    ap.add_argument("--mode", choices=("paper", "borealhdr"), default="borealhdr")
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args(argv)
    seq = load_sequence(args.sequence)
    response = sequence_response(seq)
    loop(seq, response, args.mode, RunStats())  # warm-up: imports, lookup tables, weights
    stats = RunStats()
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    for _ in range(args.repeat):
        loop(seq, response, args.mode, stats)
    prof.disable()
    wall = time.perf_counter() - t0
    for key in ("tottime", "cumulative"):
        buf = io.StringIO()
        pstats.Stats(prof, stream=buf).sort_stats(key).print_stats(args.top)
        text = buf.getvalue()
        print(f"==== mode {args.mode}, sorted by {key} ====")
        print(text[text.find("ncalls") - 3:] if "ncalls" in text else text)
    d = stats.as_dict()
    print(f"loop timers ({args.repeat} runs, {d['cycles']} cycles, {d['cycles'] / wall:.2f} cycles/s under cProfile):")
    print(f"  decode {d['decode_ms_per_image']:.1f} ms/image ({d['decodes']}), emulation "
          f"{d['emulate_ms_per_image']:.1f} ms/image ({d['emulations']})")
    for name, ms in d["method_ms_per_frame"].items():
        print(f"  {name:13s} {ms:7.1f} ms/frame")


if __name__ == "__main__":
    main()
