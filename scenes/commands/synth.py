"""``exposim synth``: render a scene along a trajectory into a BorealHDR-layout dataset."""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
from pathlib import Path

from emulator.commands.progress import add_quiet, bars_enabled

__all__ = ["register", "stop_between_images"]


def register(subparsers) -> None:
    from scenes.base import SCENES
    from scenes.commands.render import add_scheduler_option, add_denoise_option
    from scenes.camera import DEFAULT_SATURATE_MS

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
    p.add_argument("--size", default="480x300",
                   help="WIDTHxHEIGHT (default 480x300, the size the stereo VO and the AE study were measured at; "
                   "it renders about 4x slower than 160x100, which is too small for VO; docs/real-data.md)")
    p.add_argument("--spp", type=int, default=16, help="render samples per pixel (default 16)")
    p.add_argument("--camera", default="borealhdr", choices=("borealhdr", "linear", "gamma22", "s_curve"),
                   help="camera response of the synthetic camera: the BorealHDR camera's measured inverse response "
                        "(pcalib_inside1), or a linear, gamma 2.2 or S-shaped curve (default %(default)s)")
    p.add_argument("--saturate-ms", type=float, default=DEFAULT_SATURATE_MS,
                   help="exposure at which a white surface facing the sun saturates (default %(default)s)")
    p.add_argument("--speed", type=float, default=None, help="walking speed, m/s (default 2 km/h)")
    p.add_argument("--walk", default=None, metavar="WALK",
                   help="borealhdr (default: turns like the BorealHDR backpack, median 10.7 deg/s), gentle "
                        "(0.5 deg sway, ~4 deg/s) or replay:PATH (a BorealHDR imu.csv's gyro)")
    p.add_argument("--seed", type=int, default=0, help="scene seed (placement, textures) (default %(default)s)")
    p.add_argument("--noise-seed", type=int, default=0, help="sensor noise seed (default %(default)s)")
    p.add_argument("--param", action="append", metavar="KEY=VALUE", help="scene parameter (repeatable)")
    p.add_argument("--no-blur", action="store_true",
                   help="sample the scene at each trigger instant instead of integrating over the exposure window")
    p.add_argument("--render-per", choices=("shot", "cycle"), default="shot",
                   help="one render per shot, or per bracket sweep warped to every shot (default shot)")
    p.add_argument("--mono", action="store_true", help="left camera only")
    p.add_argument("--noiseless", action="store_true", help="exact noiseless captures")
    p.add_argument("--gt-exposures", default="", help="comma-separated target exposures (ms) to capture as ground truth")
    p.add_argument("--save-radiance", action="store_true", help="also write the radiance of every shot (OpenEXR)")
    add_denoise_option(p)
    add_scheduler_option(p)
    p.add_argument("--cache-dir", dest="cache", metavar="DIR", type=Path, default=None,
                   help="render cache folder (default $EXPOSIM_CACHE or ~/.cache/exposim/renders)")
    p.add_argument("--cache", dest="cache", type=Path, default=None, help=argparse.SUPPRESS)  # old spelling
    p.add_argument("--force", action="store_true",
                   help="replace an existing exposim dataset (refused, naming them, if it holds files synth did not write)")
    add_quiet(p)
    p.set_defaults(func=_run, extras=("synth",))


register.order = 70  # place in `exposim --help`


def _run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from scenes.base import get_scene
    from emulator.errors import ExposimError
    from scenes.commands.render import parse_params, parse_size
    from scenes.parallel import check_scheduler
    from scenes.synthesize import synthesize

    width, height = parse_size(args.size)
    try:
        gt = tuple(float(x) for x in args.gt_exposures.split(",") if x.strip())
    except ValueError:
        raise ExposimError(f"--gt-exposures must be comma-separated numbers, got {args.gt_exposures!r}") from None
    scene = get_scene(args.scene, seed=args.seed, **parse_params(args.param))
    scheduler = check_scheduler(args.scheduler)
    render_bar = None
    if scheduler is not None:
        render_bar = tqdm(total=args.cycles * 6 * (1 if args.mono else 2), desc=f"render {scene.name} (dask)",
                          unit="img", disable=not bars_enabled(args.quiet), file=sys.stderr)
    with (render_bar if render_bar is not None else contextlib.nullcontext()), tqdm(total=args.cycles * 6 * (1 if args.mono else 2), desc=f"synth {scene.name}", unit="img",
              disable=not bars_enabled(args.quiet), file=sys.stderr) as bar, \
            stop_between_images("exposim synth") as check:

        def progress(done, total):
            check()
            bar.total = total * (1 if args.mono else 2)
            bar.n = done * (1 if args.mono else 2)
            bar.refresh()

        path = synthesize(
            scene, args.output, n_cycles=args.cycles, width=width, height=height, spp=args.spp,
            camera=args.camera, saturate_ms=args.saturate_ms, speed_mps=args.speed, walk=args.walk, blur=not args.no_blur, render_per=args.render_per,
            seed=args.noise_seed,
            stereo=not args.mono, noise=not args.noiseless, gt_exposures_ms=gt, save_radiance=args.save_radiance,
            cache_dir=args.cache, denoise=args.denoise, overwrite=args.force, progress=progress,
            scheduler=scheduler, render_progress=None if render_bar is None else render_bar.update,
        )
    print(f"wrote {path} ({args.cycles} cycles, {width}x{height}, {scene.name}); inspect with: exposim info {path}")
    return 0


@contextlib.contextmanager
def stop_between_images(command: str):
    """Turn Ctrl-C during rendering into a clean stop after the current image.

    Mitsuba renders inside Dr.Jit, which turns a KeyboardInterrupt raised during a render
    into a RuntimeError (a traceback and exit code 1).  Inside this block the first SIGINT
    only sets a flag; calling the yielded ``check()`` (from a progress callback, between
    images) then raises KeyboardInterrupt in Python code, where the writer removes its
    staging folder and the CLI exits with 130.  A second SIGINT raises at once, and a
    Dr.Jit error caused by it is turned back into KeyboardInterrupt.  Outside the main
    thread, or when SIGINT is ignored, nothing is changed.
    """
    hits = []
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or previous is signal.SIG_IGN:
        yield lambda: None
        return

    def handler(signum, frame):
        hits.append(signum)
        if len(hits) > 1:
            raise KeyboardInterrupt
        with contextlib.suppress(RuntimeError, OSError):  # stderr busy in the interrupted code (a progress bar)
            sys.stderr.write(f"\n{command}: interrupted; stopping after the current image (Ctrl-C again: at once)\n")

    def check():
        if hits:
            raise KeyboardInterrupt

    signal.signal(signal.SIGINT, handler)
    try:
        yield check  # a SIGINT after the last image changes nothing: the dataset is complete
    except RuntimeError as exc:
        if hits or isinstance(exc.__cause__, KeyboardInterrupt):
            raise KeyboardInterrupt from None
        raise
    finally:
        signal.signal(signal.SIGINT, previous)
