"""Command line of the calibration study: ``exposim validate calibration -o OUT`` and
``python -m validation.calibration_study OUT``."""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

from validation.calibration_study.study import run_study
from validation.protocol import Study

__all__ = ["HELP", "STUDY", "add_arguments", "run_from_args", "main"]

HELP = "Validation of the inverse-response calibration: synthetic stacks, OpenCV, in situ, real sample."


def add_arguments(p: argparse.ArgumentParser, *, output_option: bool = False) -> None:
    """The study's options on ``p`` (``output_option``: ``-o/--output`` instead of a positional folder)."""
    out_help = "output folder (results.json, report.md, plots)"
    if output_option:
        p.add_argument("-o", "--output", type=Path, required=True, help=out_help)
    else:
        p.add_argument("output", type=Path, help=out_help)
    p.add_argument("--quick", action="store_true", help="small images, 16 exposures, 4 sweeps")
    p.add_argument("--force", action="store_true", help="overwrite an existing results.json")
    p.add_argument("--radiance", choices=("static_lab", "chart"), default="static_lab",
                   help="radiance of the static stacks (default static_lab, falls back to the chart)")
    p.add_argument("--parts", default="static,insitu,real", help="comma-separated subset of static,insitu,real")


def run_from_args(args: argparse.Namespace, command: str) -> int:
    """Run the study from parsed :func:`add_arguments` options, progress lines on stdout; exit code 0."""
    parts = tuple(s.strip() for s in args.parts.split(",") if s.strip())
    t0 = time.perf_counter()
    run_study(args.output, quick=args.quick, force=args.force, radiance_source=args.radiance, parts=parts,
              command=command, progress=lambda m: print(f"[{time.perf_counter() - t0:7.1f} s] {m}", flush=True))
    print(f"wrote {args.output / 'results.json'}, {args.output / 'report.md'}, {args.output / 'report.html'}")
    return 0


def main(argv=None) -> int:
    """``python -m validation.calibration_study OUT [options]``."""
    p = argparse.ArgumentParser(prog="python -m validation.calibration_study", description=HELP)
    add_arguments(p)
    args = p.parse_args(argv)
    command = "python -m validation.calibration_study " + " ".join(shlex.quote(a) for a in (argv or sys.argv[1:]))
    return run_from_args(args, command)


def run_validate(args: argparse.Namespace) -> int:
    """``exposim validate calibration -o OUT [options]``."""
    words = ["exposim", "validate", "calibration", "-o", str(args.output)]
    words += [flag for flag, on in (("--quick", args.quick), ("--force", args.force)) if on]
    words += ["--radiance", args.radiance, "--parts", args.parts]
    return run_from_args(args, shlex.join(words))


#: ``exposim validate calibration``.
STUDY = Study("calibration", "the inverse-response calibration on synthetic stacks, OpenCV, in situ and the real "
              "sample", lambda p: add_arguments(p, output_option=True), run_validate, description=HELP)
