"""Cost of saving images: ``exposim run --save png8`` against ``--save none`` on a long replay (not a test).

Usage: python benchmarks/bench_save.py [SEQUENCE] [--cycles 90] [--mode paper|borealhdr] [--jobs N]
       [--methods all] [--repeat 1] [--out results.json]

The shared sample has two complete stereo cycles; a recording of ``--cycles`` cycles is made
from them in a temporary BorealHDR folder (the two cycles alternately, every PNG hard-linked
under a timestamp shifted by whole replay periods, so names and times stay increasing).
Each save mode runs :func:`emulator.orchestration.runner.run_to_folder` on it (all seven methods, stereo);
reported: wall seconds of the whole call, the loop's cycles/s, and the steady-state cycles/s
after the first cycle (``timing.steady_cycles_per_s``), and the ratio png8 / none.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from emulator.io.borealhdr import CAMERA_FOLDERS, exposure_folder_name, find_response, load_sequence  # noqa: E402
from emulator.io.files import strict_json  # noqa: E402
from emulator.playback import RunConfig  # noqa: E402
from emulator.orchestration.runner import run_to_folder  # noqa: E402


def default_sequence() -> Path:
    for up in [ROOT, *ROOT.parents]:
        cand = up / "shared" / "data" / "borealhdr_sample" / "backpack_2023-09-25-15-05-03"
        if cand.is_dir():
            return cand
    return Path("/work/shared/data/borealhdr_sample/backpack_2023-09-25-15-05-03")


def replay_recording(source: Path, dest: Path, n_cycles: int) -> Path:
    """A BorealHDR folder of ``n_cycles`` cycles: the complete cycles of ``source`` in turn, hard-linked."""
    seq = load_sequence(source)
    full = [c for c in seq.cycles if all(not c.missing(cam) for cam in seq.cameras)]
    if not full:
        raise SystemExit(f"{source}: no complete cycle to replay")
    starts = [c.timestamp_ns for c in full]
    period = (starts[-1] - starts[0]) + (starts[1] - starts[0] if len(starts) > 1 else 300_000_000)
    for i in range(n_cycles):
        cycle = full[i % len(full)]
        shift = (i // len(full)) * period
        for cam, frames in cycle.frames.items():
            for ms, frame in frames.items():
                out = dest / CAMERA_FOLDERS[cam] / exposure_folder_name(ms) / f"{frame.timestamp_ns + shift}.png"
                out.parent.mkdir(parents=True, exist_ok=True)
                try:
                    os.link(frame.path, out)
                except OSError:
                    shutil.copyfile(frame.path, out)
    return dest


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("sequence", nargs="?", type=Path, default=default_sequence())
    p.add_argument("--cycles", type=int, default=90)
    p.add_argument("--mode", default="paper")
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--methods", default="all")
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args(argv)
    response = find_response(args.sequence)
    results: dict = {"sequence": str(args.sequence), "cycles": args.cycles, "mode": args.mode, "jobs": args.jobs,
                     "methods": args.methods, "runs": []}
    with tempfile.TemporaryDirectory(prefix="exposim-bench-save-") as tmp:
        rec = replay_recording(args.sequence, Path(tmp) / "replay", args.cycles)
        for rep in range(args.repeat):
            for save in ("none", "png8"):
                out = Path(tmp) / f"run-{save}-{rep}"
                config = RunConfig(save=save, mode=args.mode, jobs=args.jobs, response_path=response)
                t0 = time.perf_counter()
                summary = run_to_folder(rec, args.methods, out, config, make_report=False)
                wall = time.perf_counter() - t0
                timing = summary["timing"]
                row = {"save": save, "repeat": rep, "wall_s": wall, "cycles_per_s": timing["cycles_per_s"],
                       "startup_s": timing["startup_s"], "steady_cycles_per_s": timing["steady_cycles_per_s"],
                       "cycles": timing["cycles"]}
                results["runs"].append(row)
                print(json.dumps(row), flush=True)
                shutil.rmtree(out)
    by = {s: [r for r in results["runs"] if r["save"] == s] for s in ("none", "png8")}
    results["wall_ratio_png8_over_none"] = (sum(r["wall_s"] for r in by["png8"]) / sum(r["wall_s"] for r in by["none"]))
    results["steady_ratio_none_over_png8"] = (sum(r["steady_cycles_per_s"] for r in by["none"])
                                              / sum(r["steady_cycles_per_s"] for r in by["png8"]))
    print(json.dumps({k: v for k, v in results.items() if k != "runs"}, indent=1))
    if args.out is not None:
        args.out.write_text(strict_json(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
