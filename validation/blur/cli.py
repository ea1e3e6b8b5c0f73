"""``exposim validate blur`` and ``python -m validation.blur``."""

from __future__ import annotations

import argparse
import shlex
import sys
from dataclasses import replace
from pathlib import Path

from emulator.commands import argtypes
from emulator.errors import ExposimError
from validation.blur.config import BlurConfig
from validation.blur.report import headline
from validation.blur.study import run_study
from validation.protocol import Study

__all__ = ["HELP", "STUDY", "add_arguments", "config_from_args", "run_from_args", "main"]

HELP = ("exposure-time blur: warped sub-instants against a brute-force reference, render cost, the walk's "
        "angular rate against the real gyro, emulated against live sharpness")


def add_arguments(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    full, quick = BlurConfig(), BlurConfig.quick()
    p.add_argument("-o", "--output", type=Path, required=True, help="output folder")
    p.add_argument("--quick", action="store_true",
                   help=f"reduced configuration ({quick.width}x{quick.height}, {quick.spp} spp; well under a minute)")
    p.add_argument("--force", action="store_true", help="overwrite an existing results.json")
    p.add_argument("--scene", help=f"walkable scene (default {full.scene})")
    p.add_argument("--walk", help=f"walk preset (default {full.walk})")
    p.add_argument("--size", type=argtypes.size,
                   help=f"WxH of the reference comparison and the render cost (default {full.width}x{full.height}; "
                        "the sharpness comparison has its own --sharpness-size)")
    p.add_argument("--sharpness-size", type=argtypes.size,
                   help=f"WxH of the sharpness comparison (default {full.sharpness_width}x{full.sharpness_height}, "
                        "the BorealHDR camera's)")
    p.add_argument("--spp", type=int, help=f"samples per pixel of the blurred shots (default {full.spp})")
    p.add_argument("--instants", type=int, help=f"shot instants compared (default {full.n_instants})")
    p.add_argument("--versus-walks", type=int,
                   help=f"walks of the live-against-emulated table (default {full.versus_walks}, quick "
                        f"{quick.versus_walks}; 0: not measured)")
    p.add_argument("--versus-cycles", type=int,
                   help=f"bracket sweeps per walk of that table (default {full.versus_cycles})")
    p.add_argument("--real-imu", help="the real gyro, a BorealHDR imu.csv (default: the shared sample's)")
    p.add_argument("--cache-dir", help="render cache (default $EXPOSIM_CACHE or ~/.cache/exposim/renders)")
    return p


def config_from_args(args) -> BlurConfig:
    """The configuration the parsed options ask for."""
    cfg = BlurConfig.quick() if args.quick else BlurConfig()
    changes = {k: v for k, v in (("scene", args.scene), ("walk", args.walk), ("spp", args.spp),
                                 ("n_instants", args.instants), ("real_imu", args.real_imu),
                                 ("versus_walks", args.versus_walks), ("versus_cycles", args.versus_cycles),
                                 ("cache_dir", args.cache_dir)) if v is not None}
    if args.size is not None:
        changes.update(width=args.size[0], height=args.size[1])
    if getattr(args, "sharpness_size", None) is not None:
        changes.update(sharpness_width=args.sharpness_size[0], sharpness_height=args.sharpness_size[1])
    return replace(cfg, **changes)


def run_from_args(args) -> int:
    """Run the study from parsed :func:`add_arguments` options; print its headline."""
    words = ["exposim", "validate", "blur", "-o", str(args.output)] + (["--quick"] if args.quick else [])
    for flag, v in (("--scene", args.scene), ("--walk", args.walk), ("--spp", args.spp),
                    ("--instants", args.instants), ("--versus-walks", args.versus_walks),
                    ("--versus-cycles", args.versus_cycles)):
        if v is not None:
            words += [flag, str(v)]
    if args.size is not None:
        words += ["--size", f"{args.size[0]}x{args.size[1]}"]
    if getattr(args, "sharpness_size", None) is not None:
        words += ["--sharpness-size", f"{args.sharpness_size[0]}x{args.sharpness_size[1]}"]
    results = run_study(config_from_args(args), args.output, command=shlex.join(words), force=args.force)
    print(headline(results))
    print(f"wrote {args.output / 'results.json'} and {args.output / 'report.md'}")
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m validation.blur", description=HELP)
    add_arguments(p)
    args = p.parse_args(argv)
    try:
        return run_from_args(args)
    except Exception as exc:  # noqa: BLE001 - one clear line, as the exposim CLI does
        if isinstance(exc, (ExposimError, FileNotFoundError)):
            print(f"error: {exc}", file=sys.stderr)
            return 1
        raise


#: ``exposim validate blur``: renders walks, so the synth extra is checked up front.
STUDY = Study("blur", HELP, add_arguments, run_from_args)
