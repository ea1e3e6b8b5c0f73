"""Command line of the render study: ``python -m validation.render_study OUT`` and ``exposim validate render -o OUT``."""

from __future__ import annotations

import argparse
import shlex
import sys
from dataclasses import replace
from pathlib import Path

from tqdm import tqdm

from emulator.commands.progress import add_json, add_quiet, bars_enabled, print_json
from emulator.commands import argtypes
from emulator.errors import ExposimError
from validation.common import ValidationError
from validation.render_study.config import CONFIGS, DEFAULT_REAL_SEQUENCE, RenderStudyConfig
from validation.render_study.study import run_render_study, total_steps
from validation.render_study.report import render_study_table
from validation.protocol import Study

__all__ = ["STUDY", "add_arguments", "config_from_args", "run_from_args", "print_summary", "run_validate", "main"]


# ------------------------------------------------------------------------------------------ command line




def _sizes_text(sizes) -> str:
    return ",".join(f"{w}x{h}" for w, h in sizes)


def add_arguments(p: argparse.ArgumentParser, *, output_option: bool = False) -> None:
    """The study's options on ``p`` (``python -m validation.render_study`` and ``exposim validate render``).

    Every help text names the full study's default and the ``--quick`` value; ``output_option``:
    ``-o/--output DIR`` instead of a positional folder.
    """
    full, quick = CONFIGS["full"], CONFIGS["quick"]

    def both(fmt, attr):
        a, b = getattr(full, attr), getattr(quick, attr)
        return f"(default {fmt(a)}; --quick {fmt(b)})"

    csv = lambda v: ",".join(str(x) for x in v)  # noqa: E731
    out_help = "output folder (results.json, report.md, time_vs_error.png)"
    if output_option:
        p.add_argument("-o", "--output", type=Path, required=True, help=out_help)
    else:
        p.add_argument("output", type=Path, help=out_help)
    p.add_argument("--quick", action="store_true",
                   help=f"pipeline check: {csv(quick.scenes)} at {quick.width}x{quick.height}, spp "
                        f"{csv(quick.spp_levels)}, {quick.reference_spp}-spp reference (a few minutes)")
    p.add_argument("--scenes", help="comma-separated study scenes " + both(csv, "scenes"))
    p.add_argument("--size", type=argtypes.size, help=f"study size WxH (default {full.width}x{full.height}; "
                                              f"--quick {quick.width}x{quick.height})")
    p.add_argument("--spp", type=argtypes.ints, help="comma-separated spp levels " + both(csv, "spp_levels"))
    p.add_argument("--reference-spp", type=int, help="spp of the raw reference " + both(str, "reference_spp"))
    p.add_argument("--texture-scenes", help="comma-separated scenes for the texture targets, '' for none " +
                                            both(csv, "texture_scenes"))
    p.add_argument("--texture-sizes", help="comma-separated WxH sizes for the texture targets " +
                                           both(_sizes_text, "texture_sizes"))
    p.add_argument("--texture-spp", type=int, help="spp of the denoised texture renders " +
                                                   both(str, "texture_spp"))
    p.add_argument("--texture-poses", type=int, help="walk poses per texture size " + both(str, "texture_poses"))
    p.add_argument("--real", type=Path, help=f"real BorealHDR sequence (default {DEFAULT_REAL_SEQUENCE})")
    p.add_argument("--cache-dir", dest="cache", metavar="DIR",
                   help="render cache for the reference ('off': none; default $EXPOSIM_CACHE "
                        "or ~/.cache/exposim/renders)")
    p.add_argument("--cache", dest="cache", help=argparse.SUPPRESS)  # old spelling
    p.add_argument("--force", action="store_true", help="overwrite an existing results.json")
    add_quiet(p)


def config_from_args(args: argparse.Namespace) -> RenderStudyConfig:
    """The :class:`RenderStudyConfig` of parsed :func:`add_arguments` options (raises ValidationError)."""
    changes: dict = {}
    if args.scenes:
        changes["scenes"] = tuple(s.strip() for s in args.scenes.split(",") if s.strip())
    if args.size:
        changes["width"], changes["height"] = args.size
    if args.spp:
        changes["spp_levels"] = args.spp
    if args.reference_spp is not None:
        changes["reference_spp"] = args.reference_spp
    if args.texture_scenes is not None:
        changes["texture_scenes"] = tuple(s.strip() for s in args.texture_scenes.split(",") if s.strip())
    if args.texture_sizes:
        try:
            changes["texture_sizes"] = tuple(argtypes.size(s) for s in args.texture_sizes.split(",") if s.strip())
        except argparse.ArgumentTypeError as exc:
            raise ValidationError(f"--texture-sizes: {exc}") from None
    if args.texture_spp is not None:
        changes["texture_spp"] = args.texture_spp
    if args.texture_poses is not None:
        changes["texture_poses"] = args.texture_poses
    if args.real is not None:
        changes["real_sequence"] = str(args.real)
    if args.cache is not None:
        changes["cache_dir"] = args.cache
    return replace(CONFIGS["quick" if args.quick else "full"], **changes)


def run_from_args(args: argparse.Namespace, command: str) -> dict:
    """Run the study of parsed :func:`add_arguments` options with a progress bar; return the results."""
    config = config_from_args(args)
    with tqdm(total=total_steps(config), desc="render study", unit="step", disable=not bars_enabled(args.quiet),
              file=sys.stderr) as bar:
        return run_render_study(args.output, config, force=args.force, progress=bar.update, command=command)


def print_summary(results: dict, output: Path) -> None:
    """The table and the written files, on stdout (command lines only)."""
    print(render_study_table(results))
    print(f"wrote {output / 'results.json'}, {output / 'report.md'}, {output / 'report.html'}, {output / 'time_vs_error.png'}")


def main(argv=None) -> int:
    """``python -m validation.render_study`` (also ``exposim validate render -o OUT``)."""
    p = argparse.ArgumentParser(prog="python -m validation.render_study",
                                description="Render study: speed against error of raw and denoised renders, and realism vs real frames.")
    add_arguments(p)
    args = p.parse_args(argv)
    argv_list = sys.argv[1:] if argv is None else list(argv)
    command = "python -m validation.render_study " + " ".join(shlex.quote(a) for a in argv_list)
    try:
        results = run_from_args(args, command)
    except (ExposimError, FileNotFoundError, NotADirectoryError) as exc:
        print(f"render_study: {exc}", file=sys.stderr)
        return 1
    print_summary(results, args.output)
    return 0


def _validate_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``exposim validate render``: the study's, with ``-o/--output`` and ``--json``."""
    add_arguments(p, output_option=True)
    add_json(p)


def run_validate(args: argparse.Namespace) -> int:
    """``exposim validate render``: run the study, print its table (or ``--json``)."""
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


_HELP = ("render study: time and error of raw vs OIDN-denoised renders per spp against a high-spp "
         "reference, keypoint repeatability, static-camera flicker, texture statistics vs real frames")

#: ``exposim validate render``.
STUDY = Study("render", _HELP, _validate_arguments, run_validate)
