"""``exposim run``: AE methods in closed loop on a recording (calls :func:`emulator.playback.run_to_folder`)."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

from emulator.errors import ExposimError

__all__ = ["register", "parse_option"]


def register(sub: argparse._SubParsersAction) -> None:
    from emulator.autoexposure import DEFAULT_RANGE_MS, METHOD_NAMES

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
                   help=f"'all' (default) or a comma-separated list of: {', '.join(METHOD_NAMES)}")
    p.add_argument("-o", "--output", type=Path, required=True, help="run folder to create (must not exist or be empty)")
    p.add_argument("--save", choices=("none", "png16", "png8"), default=None,
                   help="save emulated images: none (default), png16 (12-bit Bayer DN) or png8 (8-bit gray)")
    p.add_argument("--jobs", type=int, default=1, help="threads across methods (same output for any value)")
    p.add_argument("--mode", choices=("paper", "borealhdr"), default=None,
                   help="method behaviour: paper (default, reference defects corrected) or borealhdr (reference code)")
    p.add_argument("--initial-ms", type=float, default=None, help="initial exposure of every method (default 4.0)")
    p.add_argument("--range-ms", type=float, nargs=2, metavar=("LOW", "HIGH"), default=None,
                   help="clamp of every proposal, ms (default %s %s)" % DEFAULT_RANGE_MS)
    p.add_argument("--selector", choices=("higher-no-sat", "closest", "reference"), default=None,
                   help="bracket selector (default higher-no-sat)")
    p.add_argument("--response", type=Path, default=None, help="pcalib file (default: found beside the recording)")
    p.add_argument("--seed", type=int, default=None, help="seed of kim's Gaussian-process optimizer (default 0)")
    p.add_argument("--option", action="append", default=[], metavar="METHOD.KEY=VALUE",
                   help="a method option, e.g. zhang.percentile=0.7 or kim.window=8 (VALUE is JSON or text); repeatable")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted run in OUTDIR (its run.json gives the configuration)")
    p.add_argument("--sequences", default=None, metavar="all|NAME,...",
                   help="dataset run: SEQUENCE is a dataset root; run every sequence under it ('all') or the named "
                        "ones (folders or trajectory .zip files, a zip named by its stem); OUTDIR gets one folder per "
                        "sequence and a dataset summary (results.json, report.md, methods.png)")
    p.add_argument("--scheduler", default=None, metavar="serial|local|tcp://HOST:PORT",
                   help="dataset runs: serial, local (a Dask LocalCluster sized to the machine; default) or the "
                        "address of a running Dask scheduler; single sequences always run serially")
    p.add_argument("--workers", type=int, default=None, help="dataset runs on --scheduler local: worker processes")
    p.add_argument("--group-size", type=int, default=None,
                   help="dataset runs: methods per unit of work (default: all, one unit per sequence, the methods "
                        "sharing decoded images; 1: one (sequence, method) per unit, the finest parallelism)")
    p.add_argument("--retries", type=int, default=2, help="dataset runs on Dask: retries of a failed unit (default 2)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print the results summary as JSON")
    p.set_defaults(func=_run)


register.order = 30  # place in `exposim --help`


def parse_option(text: str) -> tuple[str, str, object]:
    """``METHOD.KEY=VALUE`` -> (method, key, value); VALUE parsed as JSON when it can be."""
    head, sep, value = text.partition("=")
    method, dot, key = head.partition(".")
    if not sep or not dot or not method or not key:
        raise ExposimError(f"--option {text!r}: expected METHOD.KEY=VALUE, e.g. kim.seed=3")
    try:
        parsed = json.loads(value)
    except json.JSONDecodeError:
        parsed = value
    return method.strip(), key.strip(), parsed


def _command(args) -> str:
    """The command line that reproduces this run (rebuilt from the parsed arguments)."""
    parts = ["exposim", "run", str(args.sequence), "-o", str(args.output)]
    for flag, value in (("--methods", args.methods), ("--save", args.save), ("--mode", args.mode),
                        ("--initial-ms", args.initial_ms), ("--selector", args.selector),
                        ("--response", args.response), ("--seed", args.seed)):
        if value is not None:
            parts += [flag, str(value)]
    if args.range_ms is not None:
        parts += ["--range-ms", *(str(v) for v in args.range_ms)]
    for text in args.option:
        parts += ["--option", text]
    if args.jobs != 1:
        parts += ["--jobs", str(args.jobs)]
    if args.resume:
        parts.append("--resume")
    return shlex.join(parts)


def _run(args) -> int:
    if args.sequences is not None:
        return _run_dataset(args)
    if args.scheduler not in (None, "serial"):
        raise ExposimError(f"--scheduler {args.scheduler}: a single sequence runs serially; "
                           "pass --sequences all for a dataset run")
    from emulator.autoexposure import DEFAULT_RANGE_MS
    from emulator.io.runfolder import RUN_FILE, read_run_json
    from emulator.playback import DEFAULT_INITIAL_MS, DEFAULT_SELECTOR, run_to_folder

    given = {
        "methods": args.methods,
        "save": args.save,
        "mode": args.mode,
        "initial_ms": args.initial_ms,
        "range_ms": args.range_ms,
        "selector": args.selector,
    }
    options: dict[str, dict] = {}
    for text in args.option:
        method, key, value = parse_option(text)
        options.setdefault(method, {})[key] = value
    if args.seed is not None:
        options.setdefault("kim", {})["seed"] = args.seed
    defaults = {
        "methods": "all",
        "save": "none",
        "mode": "paper",
        "initial_ms": DEFAULT_INITIAL_MS,
        "range_ms": list(DEFAULT_RANGE_MS),
        "selector": DEFAULT_SELECTOR,
    }
    response_path = args.response
    if args.resume:
        # The recorded configuration wins; arguments given explicitly must agree with it.
        if not (args.output / RUN_FILE).is_file():
            raise ExposimError(f"{args.output / RUN_FILE}: no run to resume (run.json missing)")
        recorded = read_run_json(args.output)
        for key, value in given.items():
            if value is None:
                given[key] = recorded.get(key, defaults[key])
        if not options:
            options = recorded.get("options") or {}
        if response_path is None and recorded.get("response") and Path(recorded["response"]).is_file():
            response_path = Path(recorded["response"])
    cfg = {k: (defaults[k] if v is None else v) for k, v in given.items()}

    progress = None
    bar = None
    if not args.no_progress:
        from tqdm import tqdm

        bar = tqdm(total=None, unit="cycle", desc="exposim run", file=sys.stderr, dynamic_ncols=True)

        def progress(done: int, total: int) -> None:
            if bar.total != total:
                bar.total = total
            bar.n = done
            bar.refresh()

    try:
        summary = run_to_folder(
            args.sequence,
            cfg["methods"],
            args.output,
            save=cfg["save"],
            response_path=response_path,
            initial_ms=cfg["initial_ms"],
            range_ms=tuple(cfg["range_ms"]),
            selector=cfg["selector"],
            mode=cfg["mode"],
            options=options,
            jobs=args.jobs,
            resume=args.resume,
            progress=progress,
            command=_command(args),
        )
    finally:
        if bar is not None:
            bar.close()
    if args.json:
        print(json.dumps(summary, indent=1))
        return 0
    print(f"run folder  {args.output}")
    print(f"cycles      {summary['cycles_done']}/{summary['n_cycles']}"
          + (f" ({len(summary['skipped_cycles'])} skipped)" if summary["skipped_cycles"] else ""))
    for name, m in summary["methods"].items():
        mean = m["mean_exposure_ms"]
        print(f"  {name:13s} mean {mean:8.3f} ms  final {m['final_exposure_ms']:8.3f} ms  "
              f"sat {m['mean_saturated_fraction']:.2%}" if mean is not None else f"  {name:13s} no cycle")
    timing = summary.get("timing") or {}
    if timing.get("cycles_per_s"):
        print(f"speed       {timing['cycles_per_s']:.2f} cycles/s")
    return 0


def _run_dataset(args) -> int:
    """``exposim run ROOT --sequences ...``: every (sequence, method group) unit, then the dataset summary."""
    from emulator.datasetrun import DATASET_FILE, run_dataset
    from emulator.io.files import read_metadata

    recorded = read_metadata(args.output / DATASET_FILE) if args.resume else {}
    rec_opts = recorded.get("options", {})
    options: dict = dict(rec_opts.get("options") or {})
    for text in args.option:
        method, key, value = parse_option(text)
        options.setdefault(method, {})[key] = value
    if args.seed is not None:
        options.setdefault("kim", {})["seed"] = args.seed
    run_options = {}
    for key, value in (("mode", args.mode), ("selector", args.selector), ("initial_ms", args.initial_ms),
                       ("range_ms", args.range_ms), ("save", args.save), ("response_path", args.response)):
        if value is not None:
            run_options[key] = str(value) if key == "response_path" else value
        elif key in rec_opts:
            run_options[key] = rec_opts[key]
    if args.jobs != 1 or "jobs" in rec_opts:
        run_options["jobs"] = args.jobs if args.jobs != 1 else rec_opts["jobs"]
    if options:
        run_options["options"] = options
    methods = args.methods or ",".join(recorded.get("methods", [])) or "all"
    group_size = args.group_size or recorded.get("group_size")
    scheduler = args.scheduler or "local"

    bar = None
    progress = None
    if not args.no_progress:
        from tqdm import tqdm

        def progress(done: int, total: int) -> None:
            nonlocal bar
            if bar is None:  # made at the first report, after the run's checks passed
                bar = tqdm(total=total, unit="unit", desc="exposim run (sequence, methods)", file=sys.stderr,
                           dynamic_ncols=True)
            bar.n = done
            bar.refresh()

    try:
        summary = run_dataset(args.sequence, args.output, sequences=args.sequences, methods=methods,
                              group_size=group_size, options=run_options, scheduler=scheduler,
                              n_workers=args.workers, retries=args.retries, resume=args.resume, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        t = summary["throughput"]
        print(f"dataset run {args.output}  ({len(summary['sequences'])} sequences, {len(summary['units'])} units, "
              f"scheduler {scheduler})")
        for name, m in summary["per_method"].items():
            mean = m["mean_exposure_ms"]
            print(f"  {name:13s} {m['cycles']:6d} cycles  mean {mean:8.3f} ms" if mean is not None
                  else f"  {name:13s} no cycle")
        if t["cycles_per_s_one_worker"]:
            print(f"speed       {t['cycles_per_s_one_worker']:.2f} cycles/s, {t['images_per_s_one_worker']:.1f} images/s "
                  "per worker (all methods)")
    if summary["errors"]:
        first = summary["errors"][0]
        raise ExposimError(f"{len(summary['errors'])} unit(s) failed (see {args.output / 'report.md'}); "
                           f"first: {first['unit']}: {first['error']}")
    return 0
