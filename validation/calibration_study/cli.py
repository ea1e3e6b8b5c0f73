"""Command line of the calibration study: ``python -m validation.calibration_study OUT``."""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

from validation.calibration_study.study import run_study

__all__ = ["main"]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m validation.calibration_study",
                                description="Validation of the inverse-response calibration: synthetic stacks, OpenCV, in situ, real sample.")
    p.add_argument("output", type=Path, help="output folder (results.json, report.md, plots)")
    p.add_argument("--quick", action="store_true", help="small images, 16 exposures, 4 sweeps")
    p.add_argument("--force", action="store_true", help="overwrite an existing results.json")
    p.add_argument("--radiance", choices=("static_lab", "chart"), default="static_lab",
                   help="radiance of the static stacks (default static_lab, falls back to the chart)")
    p.add_argument("--parts", default="static,insitu,real", help="comma-separated subset of static,insitu,real")
    args = p.parse_args(argv)
    parts = tuple(s.strip() for s in args.parts.split(",") if s.strip())
    command = "python -m validation.calibration_study " + " ".join(shlex.quote(a) for a in (argv or sys.argv[1:]))
    t0 = time.perf_counter()
    run_study(args.output, quick=args.quick, force=args.force, radiance_source=args.radiance, parts=parts,
              command=command, progress=lambda m: print(f"[{time.perf_counter() - t0:7.1f} s] {m}", flush=True))
    print(f"wrote {args.output / 'results.json'}, {args.output / 'report.md'}, {args.output / 'report.html'}")
    return 0
