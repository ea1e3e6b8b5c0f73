"""Command line of the AE study: ``python -m validation.ae_study OUT`` and ``exposim validate ae-study -o OUT``."""

from __future__ import annotations

import argparse
import shlex
import sys
from dataclasses import replace
from pathlib import Path

from emulator.commands.progress import add_json, add_quiet, bars_enabled, print_json
from emulator.commands import argtypes
from emulator.errors import ExposimError
from scenes.commands.render import add_scheduler_option
from scenes.parallel import check_scheduler
from validation.ae_study.config import CONFIGS
from validation.ae_study.study import redraw, run_replicated_study, run_study
from validation.protocol import DefaultsFormatter, Study

#: The one-paragraph description of ``python -m validation.ae_study --help``.
DESCRIPTION = "Synthetic AE study: the paper's section V-D benchmarks on synthetic stereo walks."

__all__ = ["STUDY", "add_arguments", "run_from_args", "summary_lines", "main"]






def add_arguments(p: argparse.ArgumentParser, *, output_option: bool = False) -> None:
    """The study's options on parser ``p`` (``output_option``: ``-o/--output`` instead of a positional).

    Options left out keep the configuration's value; the help gives the ``full`` and the
    ``--quick`` values (from :data:`~validation.ae_study.config.CONFIGS`).
    """
    full, quick = CONFIGS["full"], CONFIGS["quick"]
    out_help = "output folder (results.json, report.md, figures, runs)"
    if output_option:
        p.add_argument("-o", "--output", type=Path, required=True, help=out_help)
    else:
        p.add_argument("output", type=Path, help=out_help)
    p.add_argument("--quick", action="store_true",
                   help=f"{quick.n_cycles} cycles per scene instead of {full.n_cycles} (a pipeline check, a few minutes)")
    p.add_argument("--cycles", type=int,
                   help=f"bracket cycles per scene (default: {full.n_cycles}; {quick.n_cycles} with --quick)")
    p.add_argument("--size", type=argtypes.size, help=f"image size WxH (default: {full.width}x{full.height})")
    p.add_argument("--spp", type=int, help=f"render samples per pixel (default: {full.spp})")
    p.add_argument("--scenes", type=argtypes.names, help=f"comma-separated scenes (default: {','.join(full.scenes)})")
    p.add_argument("--replicates", type=int, default=1,
                   help="run the study on this many seeds (scene, camera and render seeds +0, +1, ...): each scene "
                        "of each is an independent walk of the findings' statistics (default 1; a verdict needs "
                        ">= 10 walks)")
    add_scheduler_option(p)
    p.add_argument("--force", action="store_true", help="overwrite an existing results.json")
    add_quiet(p, "no progress bars")
    p.add_argument("--redraw", action="store_true",
                   help="only re-evaluate the findings and rewrite report.md and the figure from OUT/results.json")


def run_from_args(args: argparse.Namespace, command: str) -> dict:
    """Run (or ``--redraw``) the study from parsed :func:`add_arguments` options; returns results.json's content.

    Raises
    ------
    emulator.errors.ExposimError
        A bad configuration, an existing study without ``--force``, nothing to redraw.
    """
    if args.redraw:
        return redraw(args.output)
    changes = {}
    if args.cycles is not None:
        changes["n_cycles"] = args.cycles
    if args.size is not None:
        changes["width"], changes["height"] = args.size
    if args.spp is not None:
        changes["spp"] = args.spp
    if args.scenes:
        changes["scenes"] = args.scenes
    cfg = replace(CONFIGS["quick" if args.quick else "full"], **changes)
    replicates = getattr(args, "replicates", 1)
    if replicates < 1:
        raise ExposimError(f"--replicates must be >= 1, got {replicates}")
    if replicates > 1:
        return run_replicated_study(args.output, cfg, replicates, force=args.force, progress=bars_enabled(args.quiet),
                                    command=command, scheduler=check_scheduler(args.scheduler))
    return run_study(args.output, cfg, force=args.force, progress=bars_enabled(args.quiet), command=command,
                     scheduler=check_scheduler(args.scheduler))


def summary_lines(args: argparse.Namespace, results: dict) -> list[str]:
    """What the command prints when done."""
    lines = [results["findings_paragraph"]]
    if not args.redraw:
        lines.append(f"wrote {args.output / 'results.json'}, {args.output / 'report.md'} "
                     f"in {results['timings']['total_s'] / 60:.1f} min")
    return lines


def main(argv=None) -> int:
    """``python -m validation.ae_study``: rc 0, or 1 with one line on stderr for a known error."""
    p = argparse.ArgumentParser(prog="python -m validation.ae_study", description=DESCRIPTION)
    add_arguments(p)
    args = p.parse_args(argv)
    command = "python -m validation.ae_study " + " ".join(shlex.quote(a) for a in (sys.argv[1:] if argv is None else argv))
    try:
        results = run_from_args(args, command)
    except ExposimError as exc:
        print(f"ae_study: {exc}", file=sys.stderr)
        return 1
    print("\n".join(summary_lines(args, results)))
    return 0


def _validate_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``exposim validate ae-study``: the study's, with ``-o/--output`` and ``--json``."""
    add_arguments(p, output_option=True)
    add_json(p)


def run_validate(args: argparse.Namespace) -> int:
    """``exposim validate ae-study``: run (or redraw) the study, print its summary (or ``--json``)."""
    words = ["exposim", "validate", "ae-study", "-o", str(args.output)]
    words += [w for flag, on in (("--quick", args.quick), ("--redraw", args.redraw)) if on for w in [flag]]
    for flag, value in (("--cycles", args.cycles), ("--spp", args.spp)):
        if value is not None:
            words += [flag, str(value)]
    if args.size is not None:
        words += ["--size", f"{args.size[0]}x{args.size[1]}"]
    if args.scenes:
        words += ["--scenes", ",".join(args.scenes)]
    results = run_from_args(args, shlex.join(words))
    if args.json:
        print_json(results)
        return 0
    print("\n".join(summary_lines(args, results)))
    return 0


_HELP = ("the paper's section V-D benchmarks (features, stereo VO, RPE) for the seven AE methods on synthetic "
         "stereo walks, with a verdict on each of the paper's findings")

#: ``exposim validate ae-study``.
STUDY = Study("ae-study", _HELP, _validate_arguments, run_validate, formatter_class=DefaultsFormatter)
