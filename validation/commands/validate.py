"""``exposim validate emulation|selectors|motion|speed``: thin argument parsing around
:func:`validation.report.run_experiment`; ``exposim validate ae-study`` around
:func:`validation.ae_study.run_study`; ``exposim validate render``: the render study
(:mod:`validation.render_study`); ``exposim validate live``: :mod:`validation.live`;
``exposim validate blur``: exposure-time blur (:mod:`validation.blur`); ``exposim validate native``:
native emulation on a real recording, leaving each frame out (:mod:`validation.native_loo`).

Default sizes are the full study; ``--quick`` is the reduced configuration of the tests.
A folder that already holds a results.json is refused unless ``--force``.
``exposim validate live`` (live versus emulated closed loop) is :mod:`validation.live.cli`.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from emulator.commands.progress import add_json, add_quiet, bars_enabled, print_json
from emulator.commands import argtypes

__all__ = ["register"]

_HELP = {
    "emulation": "emulation accuracy on exact ground truth (paper Fig. 3): per bracket and selector, noise subtracted",
    "selectors": "HigherNoSat, closest, reference rule and a predicted-error selector against an oracle",
    "motion": "error of emulating from a bracket shot up to ~230 ms earlier or later, against walking speed",
    "speed": "time per image against RMSE: lookup table, float path, reference interpolation, render spp",
}






class _DefaultsFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Every option's default in ``--help``: the argparse default, or, for an option left at
    None, the experiment configuration's value (full and ``--quick``), looked up only when
    the help is shown (``action.config_default``)."""

    def _get_help_string(self, action):
        text = action.help or ""
        if "%(default)" in text or "(default" in text:
            return text
        lazy = getattr(action, "config_default", None)
        if lazy is not None:
            full, quick = (_show(v) for v in lazy())
            shown = full if full == quick else f"{full}; with --quick: {quick}"
            return f"{text} (default: {shown.replace('%', '%%')})"
        if action.default is None or action.default is False or action.default is argparse.SUPPRESS:
            return text
        return text + " (default: %(default)s)"


def _show(value) -> str:
    if isinstance(value, (tuple, list)):
        return ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in value)
    return "none" if value is None else str(value)


def _config_size(name: str):
    def lookup():
        from validation.report import make_config

        full, quick = make_config(name), make_config(name, quick=True)
        return f"{full.width}x{full.height}", f"{quick.width}x{quick.height}"

    return lookup


def _config_default(name: str, field: str):
    def lookup():
        from validation.report import make_config

        return getattr(make_config(name), field), getattr(make_config(name, quick=True), field)

    return lookup


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "validate",
        help="render-and-validate experiments on synthetic ground truth (writes results.json, PNGs, report.md)",
        description="Validate the emulator, the bracket selectors, motion between brackets and speed on "
                    "synthetic scenes with exact ground truth.",
        formatter_class=_DefaultsFormatter,
    )
    vsub = p.add_subparsers(dest="experiment", metavar="EXPERIMENT", required=True)
    for name, help_ in _HELP.items():
        q = vsub.add_parser(name, help=help_, description=help_, formatter_class=_DefaultsFormatter)
        q.add_argument("-o", "--output", type=Path, required=True, help="output folder")
        q.add_argument("--quick", action="store_true", help="reduced configuration (seconds, for tests)")
        q.add_argument("--force", action="store_true", help="overwrite an existing results.json")
        add_quiet(q)
        add_json(q)
        q.add_argument("--cache-dir", help="render cache folder (default $EXPOSIM_CACHE or ~/.cache/exposim/renders)")
        q.add_argument("--size", type=argtypes.size, metavar="WxH", help="render size in pixels, WIDTHxHEIGHT")
        q.add_argument("--spp", type=int, help="render samples per pixel")
        if name in ("emulation", "selectors", "speed"):
            q.add_argument("--exposures", type=int, dest="n_exposures", help="number of ground-truth exposures")
        if name in ("emulation", "selectors"):
            q.add_argument("--repeats", type=int, help="captures per ground-truth exposure (noise estimate)")
            q.add_argument("--responses", type=argtypes.names, help="comma-separated camera responses")
        if name in ("emulation", "motion", "speed"):
            q.add_argument("--scenes", type=argtypes.names, help="comma-separated study scenes")
        if name == "emulation":
            q.add_argument("--vignetting", type=argtypes.floats, help="comma-separated extra vignetting strengths")
        if name == "selectors":
            q.add_argument("--train-scenes", type=argtypes.names, help="scenes that tune the proposed selector")
            q.add_argument("--test-scenes", type=argtypes.names, help="held-out scenes")
        if name == "motion":
            q.add_argument("--speeds", type=argtypes.floats, dest="speeds_mps", help="walking speeds, m/s")
        q.set_defaults(func=_run, experiment=name, extras=("synth",))
        for action in q._actions:
            if action.dest == "size":
                action.config_default = _config_size(name)
            elif action.dest in _OPTION_FIELDS and action.dest != "cache_dir":
                action.config_default = _config_default(name, action.dest)
    _register_ae_study(vsub)
    from validation.live.cli import register as register_live  # its own options and runner

    register_live(vsub)
    _register_render(vsub)
    from validation.blur.cli import register as register_blur  # issue 21: exposure-time blur

    register_blur(vsub)
    from validation.native_loo.cli import register as register_native  # leave one frame out

    register_native(vsub)


register.order = 80  # place in `exposim --help`

_RENDER_HELP = ("render study: time and error of raw vs OIDN-denoised renders per spp against a high-spp "
                "reference, keypoint repeatability, static-camera flicker, texture statistics vs real frames")


def _register_render(vsub) -> None:
    """``exposim validate render``: :mod:`validation.render_study` (its own options, defaults in --help)."""
    from validation.render_study import add_arguments

    q = vsub.add_parser("render", help=_RENDER_HELP, description=_RENDER_HELP)
    add_arguments(q, output_option=True)
    add_json(q)
    q.set_defaults(func=_run_render, experiment="render", extras=("synth",))


def _run_render(args) -> int:
    from validation.render_study import print_summary, run_from_args

    words = ["exposim", "validate", "render", "-o", str(args.output)]
    for flag in ("quick", "force"):
        if getattr(args, flag):
            words.append("--" + flag)
    for key in ("scenes", "size", "spp", "reference_spp", "texture_scenes", "texture_sizes", "texture_spp",
                "texture_poses", "real"):
        value = getattr(args, key)
        if value is not None:
            if isinstance(value, tuple):
                value = "x".join(map(str, value)) if key == "size" else ",".join(map(str, value))
            words += ["--" + key.replace("_", "-"), str(value)]
    results = run_from_args(args, shlex.join(words))
    if args.json:
        print_json(results)
        return 0
    print_summary(results, args.output)
    return 0


_OPTION_FIELDS = ("cache_dir", "width", "height", "spp", "n_exposures", "repeats", "responses", "scenes",
                  "vignetting", "train_scenes", "test_scenes", "speeds_mps")


def _register_ae_study(vsub) -> None:
    """``exposim validate ae-study``: the synthetic AE study (paper section V-D)."""
    from validation.ae_study.cli import add_arguments

    help_ = ("the paper's section V-D benchmarks (features, stereo VO, RPE) for the seven AE methods on synthetic "
             "stereo walks, with a verdict on each of the paper's findings")
    q = vsub.add_parser("ae-study", help=help_, description=help_, formatter_class=_DefaultsFormatter)
    add_arguments(q, output_option=True)
    add_json(q)
    q.set_defaults(func=_run_ae_study, experiment="ae-study", extras=("synth",))


def _run_ae_study(args) -> int:
    from validation.ae_study.cli import run_from_args, summary_lines

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


def _run(args) -> int:
    from validation.report import make_config, run_experiment

    overrides = {k: getattr(args, k, None) for k in _OPTION_FIELDS if k not in ("width", "height")}
    size = getattr(args, "size", None)
    overrides["width"], overrides["height"] = size if size is not None else (None, None)
    config = make_config(args.experiment, quick=args.quick, **overrides)
    bar = None
    progress = None
    if bars_enabled(args.quiet):
        from tqdm import tqdm

        bar = tqdm(total=config.n_steps(), desc=f"validate {args.experiment}", unit="step", file=sys.stderr)
        progress = bar.update
    try:
        results = run_experiment(args.experiment, args.output, config=config, force=args.force,
                                 command=_command(args, overrides), progress=progress)
    finally:
        if bar is not None:
            bar.close()
    if args.json:  # the file as written (the studies round floats to 12 digits)
        from emulator.io.files import read_results

        print_json(read_results(args.output))
        return 0
    print(_headline(args.experiment, results))
    print(f"wrote {args.output / 'results.json'}, {args.output / 'report.md'}, {args.output / 'report.html'} and {len(results['figures'])} figure(s)")
    return 0


def _command(args, overrides: dict) -> str:
    """The command line that reproduces this run (output-only options left out)."""
    words = ["exposim", "validate", args.experiment, "-o", str(args.output)]
    if args.quick:
        words.append("--quick")
    if overrides.get("width") is not None:
        words += ["--size", f"{overrides['width']}x{overrides['height']}"]
    for key, value in overrides.items():
        if value is None or key in ("cache_dir", "width", "height"):
            continue
        flag = {"n_exposures": "--exposures", "speeds_mps": "--speeds"}.get(key, "--" + key.replace("_", "-"))
        if isinstance(value, tuple):
            value = ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in value)
        words += [flag, str(value)]
    return shlex.join(words)


def _headline(name: str, r: dict) -> str:
    f = lambda v: "n/a" if v is None else f"{v:.3f}"  # noqa: E731
    if name == "emulation":
        return (f"{r['selector']} ({r['main_camera']}), noise subtracted, valid pixels: median {f(r['median_rmse_percent'])} %"
                f", max {f(r['max_rmse_percent'])} % (paper 0.21 % / 1.78 %); all pixels: median "
                f"{f(r['median_rmse_percent_all_pixels'])} %, max {f(r['max_rmse_percent_all_pixels'])} %; noiseless max "
                f"{f(r['noiseless_max_rmse_percent'])} %; within analytic bound: {r['noiseless_within_analytic_bound']}")
    if name == "selectors":
        t = r["summary"]["test"]["exact_all"]
        parts = [f"{n}: +{f(d['excess_over_oracle']['mean'])}" for n, d in t.items() if n != "oracle"]
        return ("held-out mean excess over oracle (% of DN range): " + ", ".join(parts)
                + f"; predicted-error beats HigherNoSat: {r['predicted_error']['beats_higher_no_sat_on_held_out']}")
    if name == "motion":
        return "; ".join(
            f"{src}: static median {f(d['static_baseline_clean_all']['median'])} %, one shot away "
            f"{f(d['one_shot_offset_clean_all']['median'])} %, largest offset {f(d['largest_offset_clean_all']['median'])}"
            f" % (max {f(d['largest_offset_clean_all']['max'])} %)" for src, d in r["sources"].items()
        ) + f"; {r['renders']} renders"
    rows = ", ".join(f"{row['config']}: {f(row.get('ms_per_full_frame', row['ms_per_study_image']))} ms / "
                     f"{f(row['rmse_all']['median'])} %" for row in r["table"])
    return "time per image / median RMSE: " + rows
