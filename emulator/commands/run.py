"""``exposim run``: AE methods in closed loop on a recording (calls :func:`emulator.orchestration.runner.run_to_folder`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from emulator.commands.progress import add_quiet
from emulator.orchestration.distributed import SCHEDULER_HELP
from emulator.playback.config import WORKER_MODES, RunConfig
from emulator.playback.settings import add_arguments
from emulator.autoexposure import METHOD_NAMES, installed_methods
from emulator.autoexposure.classical import N_AUTO_FRAMES
from emulator.commands.body import CommandBody

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run",
        help="run AE methods in closed loop on a recording and write a run folder",
        description=(
            "Per cycle: each method's target exposure selects a bracket (once, on the left camera's "
            "saturation, among brackets present for both cameras), the left and right images are "
            "emulated at the target, the method reads the left image and proposes the next exposure, "
            "clamped to --range-ms. Writes OUTDIR/run.json, OUTDIR/<method>/exposures.csv, optional "
            "images, exposure.png, results.json and report.md."
        ),
    )
    p.add_argument("sequence", type=Path,
                   help="recording folder (BorealHDR layout) or trajectory .zip; with --sequences: a dataset root")
    p.add_argument("--methods", default=None,
                   help=f"'all' (default) or a comma-separated list of: {', '.join(METHOD_NAMES)}. "
                        f"'fixed' runs classical-50 for its first {N_AUTO_FRAMES} frames ({N_AUTO_FRAMES + 1} with "
                        "--mode borealhdr) and then freezes the exposure, so on a short run it looks like classical-50")
    p.add_argument("-o", "--output", type=Path, required=True, help="run folder to create (must not exist or be empty)")
    p.add_argument("--frame-cache", type=Path, default=None, metavar="DIR",
                   help="read decoded frames from this frame cache (made by 'exposim cache SEQ --frame-cache DIR'; "
                        "default: SEQUENCE/.exposim-frames when it exists)")
    p.add_argument("--seed", type=int, default=None, help="seed of kim's Gaussian-process optimizer (default 0)")
    p.add_argument("--option", action="append", default=[], metavar="METHOD.KEY=VALUE",
                   help="a method option, e.g. zhang.percentile_fraction=0.7 or kim.window=8 (VALUE is JSON or text); repeatable")
    add_arguments(p, RunConfig)  # every run setting, declared once as a RunConfig field
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted run in OUTDIR (its run.json gives the configuration)")
    p.add_argument("--sequences", default=None, metavar="all|NAME,...",
                   help="dataset run: SEQUENCE is a dataset root; run every sequence under it ('all') or the named "
                        "ones (folders or trajectory .zip files, a zip named by its stem); OUTDIR gets one folder per "
                        "sequence and a dataset summary (results.json, report.md, methods.png)")
    p.add_argument("--scheduler", default=None, metavar="serial|threads|local|tcp://HOST:PORT|tls://HOST:PORT",
                   help="dataset runs: " + SCHEDULER_HELP + ", or threads (--dataset-workers threads of this process), else "
                        "local (serial without the dask extra); every path gives the same bytes and the same error "
                        "rows; single sequences always run serially")
    p.add_argument("--scheduler-file", type=Path, default=None, metavar="PATH",
                   help="dataset runs: the scheduler file of a running Dask cluster (dask scheduler "
                        "--scheduler-file PATH, dask-jobqueue)")
    p.add_argument("--dataset-workers", type=int, default=None, metavar="N",
                   help="dataset runs: N worker processes (--scheduler local) or threads (--scheduler threads)")
    p.add_argument("--workers", type=_workers_arg, default=None, dest="legacy_workers", help=argparse.SUPPRESS)
    p.add_argument("--group-size", type=int, default=None,
                   help="dataset runs: methods per unit of work (default: all, one unit per sequence, the methods "
                        "sharing decoded images; 1: one (sequence, method) per unit, the finest parallelism)")
    p.add_argument("--retries", type=int, default=2, help="dataset runs on Dask: retries of a failed unit (default 2)")
    add_quiet(p)
    p.add_argument("--json", action="store_true", help="print the results summary as JSON")
    _add_plugin_arguments(p)
    p.set_defaults(func=CommandBody("emulator.commands.run_body:run_json_safe"))


register.order = 30  # place in `exposim --help`


def _add_plugin_arguments(p: argparse.ArgumentParser) -> None:
    """AE method plugins: the installed ones (and broken ones) in --methods' help; failure options."""
    plugins = installed_methods()
    ok = [n for n, pl in plugins.items() if pl.error is None]
    broken = [f"{n} ({pl.error})" for n, pl in plugins.items() if pl.error is not None]
    extra = ((f"; installed plugins: {', '.join(ok)}" if ok else "")
             + "; or an import path package.module:ClassOrFactory (e.g. all,my_pkg.my_module:MyAE), its options "
             "by its name (--option my-ae.gain=2)"
             + (f"; BROKEN plugins: {'; '.join(broken)}" if broken else ""))
    action = p._option_string_actions["--methods"]  # noqa: SLF001 - argparse has no public accessor
    action.help += extra.replace("%", "%%")
    p.add_argument("--strict", action="store_true",
                   help="exit with code 1 when a method failed (default: 0, failures named in the summary)")


def _workers_arg(text: str):
    """``--workers`` (the older spelling of ``--isolation`` and ``--dataset-workers``): process, inline or a count."""
    if text in WORKER_MODES:
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of workers, process or inline, got {text!r}") from None
