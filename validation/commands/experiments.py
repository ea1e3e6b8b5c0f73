"""``exposim validate emulation|selectors|motion|speed``: the four experiments of
:func:`validation.report.run_experiment`, as studies of the protocol (:class:`~validation.protocol.Study`).

Default sizes are the full study; ``--quick`` is the reduced configuration of the tests.
A folder that already holds a results.json is refused unless ``--force``.
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

from tqdm import tqdm

from emulator.commands import argtypes
from emulator.commands.progress import add_json, add_quiet, bars_enabled, print_json
from emulator.io.files import read_results
from validation.protocol import DefaultsFormatter, Study
from validation.report import make_config, run_experiment

__all__ = ["EMULATION", "SELECTORS", "MOTION", "SPEED"]

_HELP = {
    "emulation": "emulation accuracy on exact ground truth (paper Fig. 3): per bracket and selector, noise subtracted",
    "selectors": "HigherNoSat, closest, reference rule and a predicted-error selector against an oracle",
    "motion": "error of emulating from a bracket shot up to ~230 ms earlier or later, against walking speed",
    "speed": "time per image against RMSE: lookup table, float path, reference interpolation, render spp",
}

_OPTION_FIELDS = ("cache_dir", "width", "height", "spp", "n_exposures", "repeats", "responses", "scenes",
                  "vignetting", "train_scenes", "test_scenes", "speeds_mps")


def _config_size(name: str):
    def lookup():
        full, quick = make_config(name), make_config(name, quick=True)
        return f"{full.width}x{full.height}", f"{quick.width}x{quick.height}"

    return lookup


def _config_default(name: str, field: str):
    def lookup():
        return getattr(make_config(name), field), getattr(make_config(name, quick=True), field)

    return lookup


def _options_of(name: str):
    """The ``add_arguments`` of experiment ``name``: its options, their defaults looked up in its configuration."""

    def add_arguments(q) -> None:
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
        for action in q._actions:  # noqa: SLF001 - argparse keeps its actions there
            if action.dest == "size":
                action.config_default = _config_size(name)
            elif action.dest in _OPTION_FIELDS and action.dest != "cache_dir":
                action.config_default = _config_default(name, action.dest)

    return add_arguments


def run(args) -> int:
    """Run the experiment ``args.experiment`` from its parsed options; print its headline (or ``--json``)."""
    overrides = {k: getattr(args, k, None) for k in _OPTION_FIELDS if k not in ("width", "height")}
    size = getattr(args, "size", None)
    overrides["width"], overrides["height"] = size if size is not None else (None, None)
    config = make_config(args.experiment, quick=args.quick, **overrides)
    bar = None
    progress = None
    if bars_enabled(args.quiet):
        bar = tqdm(total=config.n_steps(), desc=f"validate {args.experiment}", unit="step", file=sys.stderr)
        progress = bar.update
    try:
        results = run_experiment(args.experiment, args.output, config=config, force=args.force,
                                 command=_command(args, overrides), progress=progress)
    finally:
        if bar is not None:
            bar.close()
    if args.json:  # the file as written (the studies round floats to 12 digits)
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


def _study(name: str) -> Study:
    return Study(name, _HELP[name], _options_of(name), run, formatter_class=DefaultsFormatter)


EMULATION, SELECTORS, MOTION, SPEED = (_study(name) for name in _HELP)
