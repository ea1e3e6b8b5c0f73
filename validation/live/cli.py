"""The command line of the experiment: ``exposim validate live`` and ``python -m validation.live``.

Both parse the same options (:func:`add_arguments`); a non-empty output folder is never
overwritten (the next free ``OUT-2``, ``OUT-3`` ... is used and named), ``--redraw``
rewrites the verdicts of a finished folder from its ``raw.json``.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from dataclasses import replace
from pathlib import Path

from emulator.commands.progress import add_json, add_quiet, bars_enabled, print_json
from emulator.commands import argtypes
from emulator.orchestration.distributed import check_scheduler
from emulator.errors import ExposimError
from scenes.denoise import DENOISERS, resolve_denoise
from scenes.errors import RenderError
from scenes.presets import parse_setting
from validation.live.config import CONFIG_CHANGES, CONFIGS, DEFAULTS, STUDY_DENOISE, STUDY_PRESET, LiveConfig, LiveError
from validation.live.experiment import numbered_output, redraw, run_live_experiment, run_replicated, stop_study
from validation.live.report import headline
from validation.protocol import Study

__all__ = ["HELP", "DESCRIPTION", "STUDY", "add_arguments", "build_parser", "config_from_args", "command_line",
           "run", "run_validate", "main"]

HELP = "live versus emulated closed loop: does the emulated benchmark rank the AE methods as a live camera would?"
DESCRIPTION = (
    "On synthetic stereo walks, every AE method runs twice: emulated (the normal closed loop on the "
    "bracketed recording, plain and noise-consistent emulation) and live (each cycle the camera captures at the "
    "method's own exposure from the rendered radiance, at the emulator's bracket instant or at the cycle's first "
    "shot; and natively: the AE on every frame at the recorder's 22 fps with an exposure latency, see --latency-frames). Compares exposure trajectories, images, features/VO metrics and the methods' rankings (Kendall tau), "
    "and measures the noise variance ratio. Writes results.json, report.md, exposure_<scene>.png, metrics.png.")






def add_arguments(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The experiment's options, their defaults (the ``full`` configuration) in the help."""
    full = argparse.Namespace(**{**DEFAULTS, **CONFIG_CHANGES["full"]})  # no LiveConfig built: registering stays light
    quick = argparse.Namespace(**{**DEFAULTS, **CONFIG_CHANGES["quick"]})
    p.add_argument("-o", "--output", type=Path, required=True,
                   help="output folder (a non-empty one is never overwritten: OUT-2, OUT-3 ... is used)")
    p.add_argument("--quick", action="store_true",
                   help=f"reduced configuration: {quick.n_cycles} cycles per scene, {quick.noise_repeats} noise "
                        f"repeats, the renders of the preset study-oidn8 ({quick.spp} spp, {quick.denoise}) (a "
                        "pipeline check in minutes); other options still apply")
    p.add_argument("--scenes", type=argtypes.names, help=f"comma-separated scenes (default {','.join(full.scenes)})")
    p.add_argument("--cycles", type=int,
                   help=f"bracket cycles per scene (default {full.n_cycles}; --quick {quick.n_cycles})")
    p.add_argument("--size", type=argtypes.size, help=f"image size WxH (default {full.width}x{full.height})")
    p.add_argument("--spp", type=int, help=f"render samples per pixel (default {full.spp}; --quick {quick.spp}; the "
                        "other render settings stay the default's: --render sets them all)")
    p.add_argument("--seed", type=int, help=f"scene, render, camera and live-capture seed (default {full.seed})")
    p.add_argument("--methods", type=argtypes.names,
                   help=f"comma-separated AE methods (default all {len(full.methods)}: {', '.join(full.methods)})")
    p.add_argument("--noise-repeats", type=int,
                   help=f"captures per exposure for the noise variance ratio (default {full.noise_repeats}; "
                        f"--quick {quick.noise_repeats})")
    p.add_argument("--replicates", type=int, default=1,
                   help="run the experiment on this many seeds (--seed, +1, ...): each scene of each is an "
                        "independent walk of the replicated verdicts (default 1; the verdicts need >= 10 walks, "
                        "docs/verdicts.md sizes a decision)")
    p.add_argument("--no-control", action="store_true",
                   help="skip the re-seeded live runs (each live condition again with other capture-noise seeds: "
                        "the live-against-live controls)")
    p.add_argument("--latency-frames", type=int,
                   help="exposure latency of the native-rate live camera, frames: a proposal made after frame k is "
                        f"used from frame k + 1 + latency (default {full.latency_frames})")
    p.add_argument("--frame-rate-hz", type=float,
                   help="frame rate of the native-rate live camera (default the recorder's "
                        f"{full.frame_rate_hz:g}; its frames must start on the recorder's shots, e.g. 11)")
    p.add_argument("--no-native", action="store_true",
                   help="skip the native-rate live condition (reported as not run)")
    p.add_argument("--render-per", choices=("shot", "cycle"),
                   help="one render per shot and camera, or one per bracket sweep and camera warped with depth "
                        f"to every shot (a sixth of the renders) (default {full.render_per})")
    p.add_argument("--denoise", choices=DENOISERS,
                   help="denoiser of the renders (default $EXPOSIM_DENOISE when set, else "
                        f"{STUDY_DENOISE}, the preset {STUDY_PRESET}'s); on an NVIDIA GPU ('cuda_ad_rgb'), 'off' with "
                        "--spp 2048 keeps render noise below the sensor's on forest_winter (3.2 s a sweep and camera "
                        "on an H200; docs/results/render.md)")
    p.add_argument("--render", metavar="PRESET",
                   help=f"a render preset ({STUDY_PRESET}: the default, render noise within 3 points of the "
                        "sensor's for SIFT on all four study scenes, about 25-33x the render time of study-oidn8; "
                        "study-oidn8: the renders of studies before 2026-12; study-adaptive; study-sun64; study-hq) "
                        "or a setting "
                        "DENOISER@SPP[+LIGHT=WEIGHT,...][~xFACTOR:PERCENT%%[@MSms]]: sets --spp, --denoise, the "
                        "renders' choice of lights and an adaptive sample count together (docs/results/render.md "
                        "measures them); not with --spp or --denoise")
    p.add_argument("--stochastic-seeds", type=int, metavar="K",
                   help="seeds per walk and condition of each AE method that draws random numbers (kim): the same K "
                        "seeds in every condition, the verdicts on their mean per walk, the per-seed rows in "
                        "walks_seeds.csv (default 1: its default seed alone)")
    p.add_argument("--keep-radiance", action="store_true", help="keep the datasets' radiance EXRs (large)")
    p.add_argument("--no-run-images", action="store_true",
                   help="delete each walk's run images (runs/<scene>/<run>/<method>/images/left and right) once its "
                        "features and VO are measured: about 180 MB less per walk at the default settings and a "
                        "faster walk (the images are written uncompressed); the results are the same, the report "
                        "then has no contact sheets")
    p.add_argument("--cache-dir", help="render cache (default $EXPOSIM_CACHE or ~/.cache/exposim/renders)")
    p.add_argument("--scheduler", default=None, metavar="serial|local|tcp://HOST:PORT",
                   help="where the walks run, each walk (scene x seed, all its conditions) one task: 'serial' (this "
                        "process, the default), 'local' (a Dask LocalCluster, --workers processes) or the address "
                        "of a running Dask scheduler (tcp://HOST:PORT or tls://HOST:PORT; its workers must see OUT "
                        "and the render cache under the same paths); the same results on every path")
    p.add_argument("--workers", type=int, help="worker processes of --scheduler local (default: the CPUs)")
    p.add_argument("--resume", action="store_true",
                   help="finish the study already in OUT (same options): walks whose record exists "
                        "(walks/<scene>.json) are not run again, failed ones are")
    p.add_argument("--calibration-studies", type=int, metavar="N",
                   help="plasmode studies per emulator and size in the calibration of the verdicts on the study's "
                        "own walks (default 100; 0 skips it; with --redraw, default: as many as the folder used)")
    add_quiet(p, "no progress bars")
    add_json(p)
    p.add_argument("--stop", metavar="REASON",
                   help="stop the pre-registered study in OUT before its planned walks, for REASON (a rule that does "
                        "not read the data, e.g. its budget), and draw its verdicts once, on the seeds whose every "
                        "walk is finished: writes stop.json first (when, why, the seeds judged, the walks left out); "
                        "a stopped study is not resumed, --redraw recomputes it")
    p.add_argument("--redraw", action="store_true",
                   help="only recompute the verdicts and rewrite results.json, report.md and the figures of the "
                        "existing folder OUT from its raw.json (or from its per-walk table walks.csv where only that "
                        "and results.json are left)")
    return p


def build_parser(prog: str = "python -m validation.live") -> argparse.ArgumentParser:
    return add_arguments(argparse.ArgumentParser(prog=prog, description=DESCRIPTION))


def _render_changes(args) -> dict:
    """``--render PRESET`` as the configuration's spp, denoiser, emitter weights and adaptive sample count."""
    if args.spp is not None or args.denoise is not None:
        raise LiveError("--render sets spp and the denoiser: give --render, or --spp and --denoise, not both")
    try:
        preset = parse_setting(args.render)
    except RenderError as exc:
        raise LiveError(f"--render: {exc}") from None
    if preset.denoise.enabled and preset.denoise != resolve_denoise(preset.denoise.name):
        raise LiveError(f"--render {args.render}: a study's denoiser is a named one ({preset.denoise.name} with its own "
                        f"albedo/normal spp); use a preset or DENOISER@SPP without /AUX_SPP")
    return {"spp": preset.spp, "denoise": preset.denoise.name, "emitter_weights": preset.emitter_weights,
            "adaptive": None if preset.adaptive is None else preset.adaptive.text}


def config_from_args(args) -> LiveConfig:
    """The configuration the options ask for (:class:`~validation.live.config.LiveError` if invalid)."""
    changes = {}
    if args.cycles is not None:
        changes["n_cycles"] = args.cycles
    if args.size is not None:
        changes["width"], changes["height"] = args.size
    for key in ("spp", "seed", "scenes", "methods", "noise_repeats", "latency_frames", "frame_rate_hz",
                "render_per", "denoise", "stochastic_seeds"):
        if getattr(args, key, None) is not None:
            changes[key] = getattr(args, key)
    if getattr(args, "render", None) is not None:
        changes.update(_render_changes(args))
    if args.no_control:
        changes["control"] = False
    if args.keep_radiance:
        changes["keep_radiance"] = True
    if getattr(args, "no_native", False):
        changes["native"] = False
    return replace(CONFIGS["quick" if args.quick else "full"], **changes)


def command_line(args, prog: str) -> str:
    """The command line that reproduces this run (output-only options left out)."""
    words = shlex.split(prog) + ["-o", str(args.output)]
    if args.quick:
        words.append("--quick")
    for key in ("scenes", "cycles", "size", "spp", "seed", "methods", "noise_repeats", "latency_frames",
                "frame_rate_hz", "render_per", "denoise", "render", "stochastic_seeds"):
        value = getattr(args, key, None)
        if value is None:
            continue
        if key == "size":
            value = f"{value[0]}x{value[1]}"
        elif isinstance(value, tuple):
            value = ",".join(value)
        words += ["--" + key.replace("_", "-"), str(value)]
    if getattr(args, "replicates", 1) != 1:
        words += ["--replicates", str(args.replicates)]
    if getattr(args, "calibration_studies", None) is not None:
        words += ["--calibration-studies", str(args.calibration_studies)]
    words += [flag for flag, on in (("--no-control", args.no_control), ("--keep-radiance", args.keep_radiance),
                                    ("--no-native", getattr(args, "no_native", False))) if on]
    return shlex.join(words)


def run(args, prog: str = "exposim validate live") -> int:
    """Run (or ``--redraw``) the experiment the options ask for; print the headline.

    Raises :class:`~emulator.errors.ExposimError` for bad options or input (the caller
    prints it as one line).
    """
    def log(msg: str) -> None:
        print(msg, file=sys.stderr)

    if args.calibration_studies is not None and args.calibration_studies < 0:
        raise ExposimError(f"--calibration-studies must be >= 0, got {args.calibration_studies}")
    if args.stop is not None and (args.redraw or args.resume):
        raise ExposimError("--stop draws a stopped study's verdicts itself: not with --redraw or --resume")
    if args.redraw or args.stop is not None:
        results = (redraw(args.output, calibration_studies=args.calibration_studies) if args.redraw else
                   stop_study(args.output, args.stop, command=f"{prog} -o {shlex.quote(str(args.output))} --stop "
                              f"{shlex.quote(args.stop)}" + ("" if args.calibration_studies is None else
                                                              f" --calibration-studies {args.calibration_studies}"),
                              calibration_studies=args.calibration_studies))
        if args.json:
            print_json(results)
            return 0
        print(headline(results))
        return 0
    cfg = config_from_args(args)
    if args.replicates < 1:
        raise ExposimError(f"--replicates must be >= 1, got {args.replicates}")
    scheduler = None if args.scheduler is None else check_scheduler(args.scheduler)
    if args.workers is not None and args.workers < 1:
        raise ExposimError(f"--workers must be >= 1, got {args.workers}")
    out = args.output if args.resume else numbered_output(args.output)
    if out != args.output:
        log(f"live: {args.output} exists and is not empty; writing to {out}")
    t0 = time.perf_counter()
    kw = dict(progress=bars_enabled(args.quiet), command=command_line(args, prog), cache_dir=args.cache_dir,
              log=None if args.quiet else log, scheduler=scheduler, n_workers=args.workers, resume=args.resume,
              keep_run_images=not args.no_run_images)
    if args.replicates > 1:
        results = run_replicated(out, cfg, args.replicates, calibration_studies=args.calibration_studies, **kw)
    else:
        results = run_live_experiment(out, cfg, **kw)
    failed = results.get("failed_walks") or []
    if args.json:
        print_json(results)
    else:
        print(headline(results))
        print(f"wrote {out / 'results.json'}, {out / 'report.md'}, {out / 'report.html'} in "
              f"{(time.perf_counter() - t0) / 60:.1f} min")
    if failed:
        log(f"live: {len(failed)} walk(s) failed ({'; '.join(f['walk'] + ': ' + f['error'] for f in failed)}); the "
            f"verdicts are over the others; rerun with --resume to retry them")
        return 1
    return 0


def main(argv=None) -> int:
    """``python -m validation.live``: errors (bad input, unreadable or unwritable paths) as one line, exit code 1."""
    args = build_parser().parse_args(argv)
    try:
        return run(args, "python -m validation.live")
    except (ExposimError, OSError) as exc:  # bad input, or a path that cannot be read or written: one line
        print(f"live: {exc}", file=sys.stderr)
        return 1


def run_validate(args) -> int:
    """``exposim validate live``: :func:`run` under that name."""
    return run(args, "exposim validate live")


#: ``exposim validate live``: renders walks, so the synth extra is checked before any output.
STUDY = Study("live", HELP, add_arguments, run_validate, description=DESCRIPTION)
