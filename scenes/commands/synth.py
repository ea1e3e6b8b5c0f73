"""``exposim synth``: render a scene along a trajectory into a BorealHDR-layout dataset."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["register"]


def register(subparsers) -> None:
    from scenes.base import SCENES
    from scenes.synthesize import DEFAULT_SATURATE_MS

    p = subparsers.add_parser(
        "synth",
        help="render a scene along a walk and write a bracketed BorealHDR-layout dataset with ground truth",
        description=(
            "Render a procedural scene at every bracket shot's own timestamp and pose (22 frames/s, "
            "brackets 1..32 ms), capture it with a synthetic camera (shot and read noise, vignetting, "
            "12-bit Bayer) and write camera_left|camera_right/<ms>/<ns>.png plus ground truth "
            "(poses in TUM format, camera parameters, calibration, optional radiance and captures)."
        ),
    )
    p.add_argument("scene", choices=sorted(SCENES), metavar="SCENE", help=f"one of: {', '.join(sorted(SCENES))}")
    p.add_argument("-o", "--output", required=True, type=Path, help="dataset folder to create")
    p.add_argument("--cycles", type=int, default=4, help="bracket sweeps to capture (default 4)")
    p.add_argument("--size", default="160x100", help="WIDTHxHEIGHT (default 160x100)")
    p.add_argument("--spp", type=int, default=16, help="render samples per pixel (default 16)")
    p.add_argument("--camera", default="borealhdr", choices=("borealhdr", "linear", "gamma22", "s_curve"))
    p.add_argument("--saturate-ms", type=float, default=DEFAULT_SATURATE_MS,
                   help="exposure at which a white surface facing the sun saturates (default %(default)s)")
    p.add_argument("--speed", type=float, default=None, help="walking speed, m/s (default 2 km/h)")
    p.add_argument("--seed", type=int, default=0, help="scene seed (placement, textures)")
    p.add_argument("--noise-seed", type=int, default=0, help="sensor noise seed")
    p.add_argument("--param", action="append", metavar="KEY=VALUE", help="scene parameter (repeatable)")
    p.add_argument("--mono", action="store_true", help="left camera only")
    p.add_argument("--noiseless", action="store_true", help="exact noiseless captures")
    p.add_argument("--gt-exposures", default="", help="comma-separated target exposures (ms) to capture as ground truth")
    p.add_argument("--save-radiance", action="store_true", help="also write the radiance of every shot (OpenEXR)")
    p.add_argument("--cache-dir", dest="cache", metavar="DIR", type=Path, default=None,
                   help="render cache folder (default $EXPOSIM_CACHE or ~/.cache/exposim/renders)")
    p.add_argument("--cache", dest="cache", type=Path, default=None, help=argparse.SUPPRESS)  # old spelling
    p.add_argument("--force", action="store_true", help="replace an existing exposim dataset")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_run)


register.order = 70  # place in `exposim --help`


def _run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    import scenes
    from emulator.errors import ExposimError
    from scenes.commands.render import parse_params, parse_size
    from scenes.synthesize import synthesize

    width, height = parse_size(args.size)
    try:
        gt = tuple(float(x) for x in args.gt_exposures.split(",") if x.strip())
    except ValueError:
        raise ExposimError(f"--gt-exposures must be comma-separated numbers, got {args.gt_exposures!r}") from None
    scene = scenes.get_scene(args.scene, seed=args.seed, **parse_params(args.param))
    with tqdm(total=args.cycles * 6 * (1 if args.mono else 2), desc=f"synth {scene.name}", unit="img",
              disable=args.quiet, file=sys.stderr) as bar:

        def progress(done, total):
            bar.total = total * (1 if args.mono else 2)
            bar.n = done * (1 if args.mono else 2)
            bar.refresh()

        path = synthesize(
            scene, args.output, n_cycles=args.cycles, width=width, height=height, spp=args.spp,
            camera=args.camera, saturate_ms=args.saturate_ms, speed_mps=args.speed, seed=args.noise_seed,
            stereo=not args.mono, noise=not args.noiseless, gt_exposures_ms=gt, save_radiance=args.save_radiance,
            cache_dir=args.cache, overwrite=args.force, progress=progress,
        )
    print(f"wrote {path} ({args.cycles} cycles, {width}x{height}, {scene.name}); inspect with: exposim info {path}")
    return 0
