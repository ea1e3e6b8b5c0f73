"""What ``exposim run`` runs, imported when it runs (its arguments: :mod:`emulator.commands.run`)."""

from __future__ import annotations

import functools
import shlex
import sys
from pathlib import Path

from emulator.commands.progress import bars_enabled, log_lines
from emulator.commands.run_summary import print_run_summary
from emulator.orchestration.distributed import resolve_scheduler
from emulator.errors import ExposimError, PlaybackError
from emulator.core.native import NATIVE_RATE
from emulator.playback.config import WORKER_MODES, RunConfig, parse_options
from emulator.playback.settings import command_words, flag_of, given, settings_of, values_from_json
from emulator.autoexposure import installed_methods
from emulator.autoexposure.methodset import build_methods
from emulator.commands.argtypes import SEED_MAX
from emulator.io.borealhdr import load_sequence, is_recording
from emulator.io.files import read_metadata, strict_json
from emulator.io.runfolder import RUN_FILE, read_run_json
from emulator.orchestration.datasetrun import discover_sequences, DATASET_FILE, run_dataset
from emulator.orchestration.runner import run_to_folder
from emulator.playback.workers import start_methods, stop_methods

__all__ = ["run_json_safe", "config_from_args"]


def _warn_broken_plugins() -> None:
    """One stderr line per installed AE method plugin that cannot load (never swallowed)."""
    for name, plugin in installed_methods().items():
        if plugin.error is not None:
            print(f"exposim run: warning: AE method plugin '{name}' is broken ({plugin.error})", file=sys.stderr)


def _legacy_workers(args) -> None:
    """``--workers X``: ``--isolation X`` (process, inline) or ``--dataset-workers X`` (a count), with a notice."""
    value = getattr(args, "legacy_workers", None)
    if value is None:
        return
    new = "--isolation" if isinstance(value, str) else "--dataset-workers"
    if isinstance(value, int) and value < 1:
        raise ExposimError(f"--workers {value}: must be >= 1")
    print(f"exposim run: note: --workers {value} is now spelled {new} {value}", file=sys.stderr)
    dest = "workers" if isinstance(value, str) else "dataset_workers"
    if getattr(args, dest) not in (None, value):
        raise ExposimError(f"--workers {value} and {new} {getattr(args, dest)}: give one")
    setattr(args, dest, value)


#: Rank in the rebuilt command line of the flags that are not run settings (theirs: their Setting's).
_OWN_RANKS = {"--methods": 0, "--seed": 6, "--option": 14, "--resume": 22}


def _command(args) -> str:
    """The command line that reproduces this run (rebuilt from the parsed arguments)."""
    words = [(_OWN_RANKS["--methods"], ["--methods", str(args.methods)] if args.methods is not None else []),
             (_OWN_RANKS["--seed"], ["--seed", str(args.seed)] if args.seed is not None else []),
             (_OWN_RANKS["--option"], [w for text in args.option for w in ("--option", text)]),
             (_OWN_RANKS["--resume"], ["--resume"] if args.resume else [])]
    parts = ["exposim", "run", str(args.sequence), "-o", str(args.output)]
    for _, more in sorted(words + command_words(args, RunConfig), key=lambda w: w[0]):
        parts += more
    return shlex.join(parts)


def _given(args) -> dict:
    """The run settings given on the command line (None: not given)."""
    options = parse_options(args.option)
    if args.seed is not None:
        options.setdefault("kim", {})["seed"] = args.seed
    return {**given(args, RunConfig), "options": options or None}


def config_from_args(args, recorded=None):
    """The :class:`~emulator.playback.RunConfig` of the command line over ``recorded`` (a recorded
    ``run.json`` or dataset configuration, on ``--resume``), built once; a bad value is refused by
    RunConfig, named here by its flag."""
    values = _given(args)
    base = values_from_json(RunConfig, recorded) if recorded else {}
    try:
        return RunConfig(**{**base, **{k: v for k, v in values.items() if v is not None}})
    except PlaybackError as exc:
        field = str(exc).split(" ", 1)[0]
        flag = flag_of(RunConfig, field)
        if flag is None or values.get(field) is None:  # not given here (a recorded value): no flag to name
            raise
        value = values.get(field)
        shown = " ".join(str(v) for v in value) if isinstance(value, tuple) else str(value)
        raise ExposimError(f"{flag} {shown}: {exc}") from None


def _check_args(args) -> None:
    """What only the command line can get wrong (the values are RunConfig's to check)."""
    for flag, seed in (("--seed", args.seed), ("--noise-seed", args.noise_seed)):
        if seed is not None and not 0 <= seed <= SEED_MAX:
            raise ExposimError(f"{flag} {seed}: must be in 0..{SEED_MAX}")
    for flag, count in (("--dataset-workers", args.dataset_workers), ("--group-size", args.group_size)):
        if count is not None and count < 1:  # 0 would silently mean "default"
            raise ExposimError(f"{flag} {count}: must be >= 1")
    if args.noise_model is not None and args.noise != "consistent" and not args.resume:
        raise ExposimError("--noise-model is used only with --noise consistent")
    for f, s in settings_of(RunConfig):  # the native-only flags
        value = getattr(args, f.name, None)
        if s.native_only and value is not None and args.rate != NATIVE_RATE and not args.resume:
            raise ExposimError(f"{s.flag} {'' if value is True else value}".strip() + ": used only with --rate native")


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


def run_json_safe(args) -> int:
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
    _legacy_workers(args)
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

    methods = args.methods
    recorded = None
    if args.resume:
        # The one resume rule (RunConfig.check_resume): the recorded configuration wins, values given must equal it.
        if not (args.output / RUN_FILE).is_file():
            raise ExposimError(f"{args.output / RUN_FILE}: no run to resume (run.json missing)")
        recorded = read_run_json(args.output)
        if methods is None and recorded.get("method_specs"):
            methods = ",".join(recorded["method_specs"])  # import-path plugins by their path
    config = config_from_args(args, recorded)
    if config.start_ms != config.initial_ms:
        low, high = config.range_ms
        print(f"exposim run: warning: --initial-ms {config.initial_ms:g} is outside --range-ms {low:g} {high:g}; "
              f"clamped to {config.start_ms:g} ms (recorded in run.json)", file=sys.stderr)

    source = args.sequence
    if args.frame_cache is not None:  # a frame cache elsewhere (a read-only recording)
        source = load_sequence(args.sequence, frame_cache=args.frame_cache, imu_warning=config.blur != "none")
    _warn_broken_plugins()
    progress = None
    bar = None
    lines = log_lines("exposim run", args.quiet, heartbeat=True)  # closed in the finally below
    if lines is not None:  # a log (nohup, CI): a line at the start, every LOG_EVERY_S seconds and at the end
        progress = functools.partial(lines, config.provider_class.unit)
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


def _check_methods_once(methods: str, config: RunConfig) -> None:
    """Build every method once with the run's options (no response: only the options are checked),
    so that a bad ``--option`` or a plugin that cannot be built is refused before a dataset run
    writes anything (it would otherwise fail in every unit and leave a dataset.json behind)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if config.workers == WORKER_MODES[1]:
            build_methods(methods, mode=config.mode, response=None, options=config.options)
            return

        stop_methods(start_methods(methods, config, None))  # built in worker processes, as the run builds them


def _run_dataset(args) -> int:
    """``exposim run ROOT --sequences ...``: every (sequence, method group) unit, then the dataset summary."""
    recorded = read_metadata(args.output / DATASET_FILE) if args.resume else {}
    config = config_from_args(args, recorded.get("config"))
    methods = args.methods or ",".join(recorded.get("methods", [])) or "all"
    group_size = args.group_size or recorded.get("group_size")
    scheduler, scheduler_file = (("threads", None) if args.scheduler == "threads" and args.scheduler_file is None
                                 else resolve_scheduler(args.scheduler, args.scheduler_file))
    _check_methods_once(methods, config)  # before dataset.json exists

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
                              n_workers=args.dataset_workers, retries=args.retries, resume=args.resume,
                              progress=progress)
    finally:
        if bar is not None:
            bar.close()
    if args.json:
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
