"""``exposim run``: AE methods in closed loop on a recording (calls :func:`emulator.runner.run_to_folder`)."""

from __future__ import annotations

import argparse
import functools
import shlex
import sys
from pathlib import Path

from emulator.commands.progress import add_quiet, bars_enabled, log_lines
from emulator.commands.run_summary import print_run_summary
from emulator.distributed import SCHEDULER_HELP, resolve_scheduler
from emulator.errors import ExposimError

__all__ = ["register", "config_from_args"]


def register(sub: argparse._SubParsersAction) -> None:
    from emulator.autoexposure import DEFAULT_RANGE_MS, METHOD_NAMES
    from emulator.autoexposure.classical import N_AUTO_FRAMES

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
    p.add_argument("--save", choices=("none", "png16", "png8"), default=None,
                   help="save emulated images: none (default), png16 (12-bit Bayer DN) or png8 (8-bit gray)")
    p.add_argument("--png-level", type=int, default=None, metavar="0..9",
                   help="zlib level of the saved images (default 0: stored, the fastest; 1..9 smaller files, the "
                        "same decoded images)")
    p.add_argument("--jobs", type=int, default=1,
                   help="how many methods compute at once, each in its own process (same output for any value)")
    p.add_argument("--mode", choices=("paper", "borealhdr"), default=None,
                   help="method behaviour: paper (default, reference defects corrected) or borealhdr (reference code)")
    p.add_argument("--initial-ms", type=float, default=None,
                   help="initial exposure of every method, ms (default 4.0; clamped to --range-ms, with a warning)")
    p.add_argument("--range-ms", type=float, nargs=2, metavar=("LOW", "HIGH"), default=None,
                   help="clamp of every proposal, ms (default %s %s)" % DEFAULT_RANGE_MS)
    p.add_argument("--selector", choices=("higher-no-sat", "closest", "reference"), default=None,
                   help="bracket selector (default higher-no-sat)")
    p.add_argument("--response", type=Path, default=None, help="pcalib file (default: found beside the recording)")
    p.add_argument("--frame-cache", type=Path, default=None, metavar="DIR",
                   help="read decoded frames from this frame cache (made by 'exposim cache SEQ --frame-cache DIR'; "
                        "default: SEQUENCE/.exposim-frames when it exists)")
    p.add_argument("--seed", type=int, default=None, help="seed of kim's Gaussian-process optimizer (default 0)")
    p.add_argument("--option", action="append", default=[], metavar="METHOD.KEY=VALUE",
                   help="a method option, e.g. zhang.percentile_fraction=0.7 or kim.window=8 (VALUE is JSON or text); repeatable")
    p.add_argument("--noise", choices=("none", "consistent"), default=None,
                   help="none (default): exact emulation (eq. 2); consistent: add the noise a capture at the "
                        "target exposure would have where the source bracket is cleaner (needs a noise model)")
    p.add_argument("--blur", choices=("none", "consistent"), default=None,
                   help="none (default): exact emulation; consistent: add the gyro's blur of the extra exposure time "
                        "where the target is longer than the bracket, and record each image's excess blur in blur.csv "
                        "(needs imu/imu.csv and a camera calibration; docs/blur.md)")
    p.add_argument("--blur-aware", action="store_true",
                   help="with --blur consistent and --selector higher-no-sat: of the two brackets around the "
                        "target, take the shorter one when the longer one's extra motion blur (predicted from the "
                        "gyro) costs more than the shorter one's extra noise; one pixel of blur weighs as much as "
                        "twice the relative noise of a capture at the target (docs/blur.md)")
    p.add_argument("--noise-model", type=Path, default=None, metavar="FILE.json",
                   help="noise model for --noise consistent (`exposim calibrate --noise`); default: the model "
                        "a synthetic recording's exposim.json carries")
    p.add_argument("--noise-seed", type=int, default=None,
                   help="seed of the added noise (default 0); the same seed gives the same bytes")
    p.add_argument("--skip-partial", action="store_true",
                   help="leave out every cycle missing a bracket on either camera (default: use the brackets that are "
                        "there; partial cycles and upward ratios above 8 are flagged in the report either way)")
    p.add_argument("--rate", choices=("cycle", "native"), default=None,
                   help="cycle (default): each method proposes once per bracket sweep, as in the paper; native: after "
                        "every recorded frame, at the recorder's frame rate, each frame emulated from its own bracket "
                        "or a nearby frame's, turned to its instant with the gyro (docs/native.md)")
    p.add_argument("--latency-frames", type=int, default=None, metavar="N",
                   help="with --rate native: a proposal made after reading frame k is first used at frame k + 1 + N "
                        "(default 1, as a live camera)")
    p.add_argument("--warp", choices=("flow-sharp", "rotation", "flow", "none"), default=None, help="--rate native: "
                   "rotation: gyro; flow: then the neighbours' flow; flow-sharp (default): flow unless under 1 px")
    p.add_argument("--native-blur-aware", action="store_true", help="with --rate native: the selector also weighs "
                   "the motion blur a candidate carries beyond the target's, from the gyro (docs/native.md)")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted run in OUTDIR (its run.json gives the configuration)")
    p.add_argument("--sequences", default=None, metavar="all|NAME,...",
                   help="dataset run: SEQUENCE is a dataset root; run every sequence under it ('all') or the named "
                        "ones (folders or trajectory .zip files, a zip named by its stem); OUTDIR gets one folder per "
                        "sequence and a dataset summary (results.json, report.md, methods.png)")
    p.add_argument("--scheduler", default=None, metavar="serial|threads|local|tcp://HOST:PORT|tls://HOST:PORT",
                   help="dataset runs: " + SCHEDULER_HELP + ", or threads (--workers threads of this process), else "
                        "local (serial without the dask extra); every path gives the same bytes and the same error "
                        "rows; single sequences always run serially")
    p.add_argument("--scheduler-file", type=Path, default=None, metavar="PATH",
                   help="dataset runs: the scheduler file of a running Dask cluster (dask scheduler "
                        "--scheduler-file PATH, dask-jobqueue)")
    p.add_argument("--workers", type=_workers_arg, default=None, metavar="N|process|inline",
                   help="process (default): every AE method in its own process, stopped past --method-timeout-s; "
                        "inline: in the run's process (debugging only: a method can then stall or change the run); "
                        "dataset runs: N worker processes (--scheduler local) or threads (--scheduler threads)")
    p.add_argument("--group-size", type=int, default=None,
                   help="dataset runs: methods per unit of work (default: all, one unit per sequence, the methods "
                        "sharing decoded images; 1: one (sequence, method) per unit, the finest parallelism)")
    p.add_argument("--retries", type=int, default=2, help="dataset runs on Dask: retries of a failed unit (default 2)")
    add_quiet(p)
    p.add_argument("--json", action="store_true", help="print the results summary as JSON")
    _add_plugin_arguments(p)
    p.set_defaults(func=_run_json_safe)


register.order = 30  # place in `exposim --help`


def _add_plugin_arguments(p: argparse.ArgumentParser) -> None:
    """AE method plugins: the installed ones (and broken ones) in --methods' help; failure options."""
    from emulator.autoexposure import installed_methods

    plugins = installed_methods()
    ok = [n for n, pl in plugins.items() if pl.error is None]
    broken = [f"{n} ({pl.error})" for n, pl in plugins.items() if pl.error is not None]
    extra = ((f"; installed plugins: {', '.join(ok)}" if ok else "")
             + "; or an import path package.module:ClassOrFactory (e.g. all,my_pkg.my_module:MyAE), its options "
             "by its name (--option my-ae.gain=2)"
             + (f"; BROKEN plugins: {'; '.join(broken)}" if broken else ""))
    action = p._option_string_actions["--methods"]  # noqa: SLF001 - argparse has no public accessor
    action.help += extra.replace("%", "%%")
    p.add_argument("--method-timeout-s", "--method-timeout", dest="method_timeout_s", type=float, default=None,
                   metavar="S",
                   help="per-call wall-time limit of a method, s: a call still running then is stopped and the method "
                   "fails (its rows stop, the others go on); default 120 (--workers inline: checked only after the "
                   "call returns, no default; --method-timeout: deprecated alias)")
    p.add_argument("--strict", action="store_true",
                   help="exit with code 1 when a method failed (default: 0, failures named in the summary)")


def _warn_broken_plugins() -> None:
    """One stderr line per installed AE method plugin that cannot load (never swallowed)."""
    from emulator.autoexposure import installed_methods

    for name, plugin in installed_methods().items():
        if plugin.error is not None:
            print(f"exposim run: warning: AE method plugin '{name}' is broken ({plugin.error})", file=sys.stderr)


def _workers_arg(text: str):
    """``--workers``: a count (dataset runs) or how methods run (process, inline)."""
    if text in ("process", "inline"):
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of workers, process or inline, got {text!r}") from None


def _command(args) -> str:
    """The command line that reproduces this run (rebuilt from the parsed arguments)."""
    parts = ["exposim", "run", str(args.sequence), "-o", str(args.output)]
    for flag, value in (("--methods", args.methods), ("--save", args.save), ("--mode", args.mode),
                        ("--initial-ms", args.initial_ms), ("--selector", args.selector),
                        ("--response", args.response), ("--seed", args.seed), ("--noise", args.noise),
                        ("--blur", args.blur), ("--noise-model", args.noise_model), ("--noise-seed", args.noise_seed),
                        ("--png-level", args.png_level), ("--warp", getattr(args, "warp", None))):
        if value is not None:
            parts += [flag, str(value)]
    if args.range_ms is not None:
        parts += ["--range-ms", *(str(v) for v in args.range_ms)]
    for text in args.option:
        parts += ["--option", text]
    if args.jobs != 1:
        parts += ["--jobs", str(args.jobs)]
    if getattr(args, "workers", None) == "inline":
        parts += ["--workers", "inline"]
    for flag in ("--blur-aware", "--skip-partial", "--native-blur-aware"):
        parts += [flag] if getattr(args, flag[2:].replace("-", "_"), False) else []
    for flag, value in (("--rate", getattr(args, "rate", None)), ("--latency-frames", getattr(args, "latency_frames", None))):
        if value is not None:
            parts += [flag, str(value)]
    if args.resume:
        parts.append("--resume")
    if getattr(args, "method_timeout_s", None) is not None:
        parts += ["--method-timeout-s", str(args.method_timeout_s)]
    return shlex.join(parts)


#: RunConfig field -> the flag that sets it (errors name the flag).
_FLAGS = {"initial_ms": "--initial-ms", "range_ms": "--range-ms", "jobs": "--jobs", "noise_seed": "--noise-seed",
          "png_level": "--png-level", "blur": "--blur", "blur_aware": "--blur-aware",
          "method_timeout_s": "--method-timeout-s", "selector": "--selector", "mode": "--mode", "save": "--save",
          "noise": "--noise", "skip_partial": "--skip-partial", "rate": "--rate", "latency_frames": "--latency-frames",
          "native_warp": "--warp", "native_blur_aware": "--native-blur-aware"}


def _given(args) -> dict:
    """The run settings given on the command line (None: not given)."""
    from emulator.playback import parse_options

    options = parse_options(args.option)
    if args.seed is not None:
        options.setdefault("kim", {})["seed"] = args.seed
    return {"initial_ms": args.initial_ms, "range_ms": tuple(args.range_ms) if args.range_ms else None,
            "selector": args.selector, "mode": args.mode, "options": options or None, "jobs": args.jobs,
            "save": args.save, "noise": args.noise, "noise_model": args.noise_model, "noise_seed": args.noise_seed,
            "method_timeout_s": args.method_timeout_s,
            "workers": args.workers if isinstance(getattr(args, "workers", None), str) else None,
            "response_path": str(args.response) if args.response is not None else None,
            "png_level": args.png_level, "blur": args.blur, "blur_aware": True if args.blur_aware else None,
            "skip_partial": True if getattr(args, "skip_partial", False) else None,
            "rate": getattr(args, "rate", None), "latency_frames": getattr(args, "latency_frames", None),
            "native_warp": getattr(args, "warp", None),
            "native_blur_aware": True if getattr(args, "native_blur_aware", False) else None}


def config_from_args(args, base=None):
    """The :class:`~emulator.playback.RunConfig` of the command line over ``base`` (a recorded one, on
    ``--resume``); a bad value is refused by RunConfig, named here by its flag."""
    from emulator.errors import PlaybackError
    from emulator.playback import RunConfig

    given = _given(args)
    try:
        return RunConfig.from_kwargs(base, **given)
    except PlaybackError as exc:
        field = str(exc).split(" ", 1)[0]
        flag = _FLAGS.get(field)
        if flag is None or given.get(field) is None:  # not given here (a recorded value): no flag to name
            raise
        value = given.get(field)
        shown = " ".join(str(v) for v in value) if isinstance(value, tuple) else str(value)
        raise ExposimError(f"{flag} {shown}: {exc}") from None


def _check_args(args) -> None:
    """What only the command line can get wrong (the values are RunConfig's to check)."""
    from emulator.commands.argtypes import SEED_MAX

    for flag, seed in (("--seed", args.seed), ("--noise-seed", args.noise_seed)):
        if seed is not None and not 0 <= seed <= SEED_MAX:
            raise ExposimError(f"{flag} {seed}: must be in 0..{SEED_MAX}")
    for flag, count in (("--workers", args.workers), ("--group-size", args.group_size)):
        if isinstance(count, int) and count < 1:  # 0 would silently mean "default"
            raise ExposimError(f"{flag} {count}: must be >= 1")
    if args.noise_model is not None and args.noise != "consistent" and not args.resume:
        raise ExposimError("--noise-model is used only with --noise consistent")
    for dest in ("latency_frames", "warp", "native_blur_aware"):  # the native-only flags
        given = getattr(args, dest, None)
        if given not in (None, False) and args.rate != "native" and not args.resume:
            shown = f"--{dest.replace('_', '-')} {'' if given is True else given}".strip()
            raise ExposimError(f"{shown}: used only with --rate native")


def _progress_bar(desc: str, unit: str):
    """A tqdm bar on stderr and the one progress callback ``progress(done, total)`` that drives it."""
    from tqdm import tqdm

    bar = tqdm(total=None, unit=unit, desc=desc, file=sys.stderr, dynamic_ncols=True)

    def progress(done: int, total: int) -> None:
        if bar.total != total:
            bar.total = total
        bar.n = done
        bar.refresh()

    return bar, progress


def _run_json_safe(args) -> int:
    """Under ``--json`` stdout carries the JSON document alone: for the whole run ``sys.stdout`` is
    stderr, so nothing a method or a thread it started prints can reach the document."""
    if not args.json:
        return _run(args)
    stdout = sys.stdout
    args.json_stream = stdout
    sys.stdout = sys.stderr
    try:
        return _run(args)
    finally:
        sys.stdout = stdout


def _run(args) -> int:
    _check_args(args)
    if args.sequences is not None and args.frame_cache is not None:
        raise ExposimError("--frame-cache applies to one sequence; a dataset run reads each sequence's own "
                           "SEQUENCE/.exposim-frames")
    if args.sequences is not None:
        return _run_dataset(args)
    if args.scheduler not in (None, "serial") or args.scheduler_file is not None:
        raise ExposimError(f"--scheduler {args.scheduler or 'file'}: a single sequence runs serially; "
                           "pass --sequences all for a dataset run")
    _refuse_dataset_root(args.sequence)
    from emulator.io.runfolder import RUN_FILE, read_run_json
    from emulator.playback import RunConfig
    from emulator.runner import run_to_folder

    methods = args.methods
    base = None
    if args.resume:
        # The one resume rule (RunConfig.resumed): the recorded configuration wins, values given must equal it.
        if not (args.output / RUN_FILE).is_file():
            raise ExposimError(f"{args.output / RUN_FILE}: no run to resume (run.json missing)")
        recorded = read_run_json(args.output)
        base = RunConfig.from_json(recorded)
        if methods is None and recorded.get("method_specs"):
            methods = ",".join(recorded["method_specs"])  # import-path plugins by their path
    config = config_from_args(args, base)
    if config.start_ms != config.initial_ms:
        low, high = config.range_ms
        print(f"exposim run: warning: --initial-ms {config.initial_ms:g} is outside --range-ms {low:g} {high:g}; "
              f"clamped to {config.start_ms:g} ms (recorded in run.json)", file=sys.stderr)

    source = args.sequence
    if args.frame_cache is not None:  # a frame cache elsewhere (a read-only recording)
        from emulator.io.borealhdr import load_sequence

        source = load_sequence(args.sequence, frame_cache=args.frame_cache, imu_warning=config.blur != "none")
    _warn_broken_plugins()
    progress = None
    bar = None
    lines = log_lines("exposim run", args.quiet, heartbeat=True)  # closed in the finally below
    if lines is not None:  # a log (nohup, CI): a line at the start, every LOG_EVERY_S seconds and at the end
        progress = functools.partial(lines, "frames" if config.rate == "native" else "cycles")
    elif bars_enabled(args.quiet):
        from tqdm import tqdm

        def progress(done: int, total: int) -> None:
            nonlocal bar
            if bar is None:  # made at the first report, after the run's checks passed
                bar = tqdm(total=total, unit="cycle", desc="exposim run", file=sys.stderr, dynamic_ncols=True)
            if bar.total != total:
                bar.total = total
            bar.n = done
            bar.refresh()

    try:
        summary = run_to_folder(source, methods or "all", args.output, config, resume=args.resume,
                                progress=progress, command=_command(args))
    finally:
        if bar is not None:
            bar.close()
        if lines is not None:
            lines.close()
    return print_run_summary(args, summary)


def _refuse_dataset_root(path: Path) -> None:
    """A folder of recordings given as one recording: say which recordings and how to run them."""
    from emulator.datasetrun import discover_sequences
    from emulator.io.borealhdr import is_recording

    if not path.is_dir() or is_recording(path):
        return
    try:
        found = discover_sequences(path, "all")
    except Exception:  # noqa: BLE001 - not a dataset root either: the recording's own error follows
        return
    names = list(found)
    shown = ", ".join(names[:5]) + (f", ... ({len(names)} in all)" if len(names) > 5 else "")
    raise ExposimError(f"{path}: a folder of {len(names)} recording(s) ({shown}), not one recording; pass "
                       f"--sequences all (or --sequences NAME,...) to run them, or give the recording's own folder")


def _check_methods_once(methods: str, run_options: dict) -> None:
    """Build every method once with the run's options (no response: only the options are checked),
    so that a bad ``--option`` or a plugin that cannot be built is refused before a dataset run
    writes anything (it would otherwise fail in every unit and leave a dataset.json behind)."""
    import warnings

    from emulator.autoexposure.methodset import build_methods

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if run_options.get("workers") == "inline":
            build_methods(methods, mode=run_options.get("mode") or "paper", response=None,
                          options=run_options.get("options"))
            return
        from emulator.playback import RunConfig
        from emulator.playback.workers import start_methods, stop_methods

        config = RunConfig(mode=run_options.get("mode") or "paper", options=run_options.get("options") or {})
        stop_methods(start_methods(methods, config, None))  # built in worker processes, as the run builds them


def _run_dataset(args) -> int:
    """``exposim run ROOT --sequences ...``: every (sequence, method group) unit, then the dataset summary."""
    from emulator.datasetrun import DATASET_FILE, run_dataset
    from emulator.io.files import read_metadata
    from emulator.playback import RunConfig

    recorded = read_metadata(args.output / DATASET_FILE) if args.resume else {}
    base = RunConfig.from_json(recorded["config"]) if recorded.get("config") else None
    config = config_from_args(args, base)
    methods = args.methods or ",".join(recorded.get("methods", [])) or "all"
    group_size = args.group_size or recorded.get("group_size")
    scheduler, scheduler_file = (("threads", None) if args.scheduler == "threads" and args.scheduler_file is None
                                 else resolve_scheduler(args.scheduler, args.scheduler_file))
    _check_methods_once(methods, {"mode": config.mode, "options": config.options,  # before dataset.json exists
                                  "workers": config.workers})

    bar = None
    progress = None
    if bars_enabled(args.quiet):
        def progress(done: int, total: int) -> None:
            nonlocal bar, drive
            if bar is None:  # made at the first report, after the run's checks passed
                bar, drive = _progress_bar("exposim run (sequence, methods)", "unit")
            drive(done, total)

        drive = None

    try:
        summary = run_dataset(args.sequence, args.output, config, sequences=args.sequences, methods=methods,
                              group_size=group_size, scheduler=scheduler, scheduler_file=scheduler_file,
                              n_workers=args.workers if isinstance(args.workers, int) else None, retries=args.retries, resume=args.resume, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    if args.json:
        from emulator.io.files import strict_json

        print(strict_json(summary, indent=1), file=getattr(args, "json_stream", None) or sys.stdout)
    else:
        t = summary["throughput"]
        print(f"dataset run {args.output}  ({len(summary['sequences'])} sequences, {len(summary['units'])} units, "
              f"scheduler {summary['scheduler']})")
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
    failed = summary.get("failed_methods") or {}
    if failed:
        name, why = next(iter(failed.items()))
        raise ExposimError(f"{len(failed)} method(s) failed in every unit (see {args.output / 'report.md'}); "
                           f"first: {name}: {why}")
    failed_units = [f"{seq}/{m}" for seq, per in summary["per_sequence"].items() for m, fig in per.items()
                    if str(fig.get("status", "ok")).startswith("failed")]
    if failed_units and args.strict:
        print(f"FAILED      {', '.join(failed_units)} (--strict: exit code 1)")
        return 1
    return 0
