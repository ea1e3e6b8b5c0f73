"""``exposim render``: render a scene along a trajectory to OpenEXR files.

Thin: parses arguments and calls :mod:`scenes`.  Heavy imports (Mitsuba, tqdm)
happen inside the command.  ``parse_size`` and ``parse_params`` are shared with
``exposim synth`` (:mod:`scenes.commands.synth`).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from emulator.commands.progress import add_quiet, bars_enabled
from scenes.errors import RenderError, SceneError

__all__ = ["register", "parse_size", "parse_params", "frame_seed", "add_denoise_option", "add_scheduler_option"]

#: Files the render command writes in its output folder (besides frames/).
OUTPUT_FILES = ("scene.json", "poses_left.txt", "poses_right.txt")


def parse_size(text: str) -> tuple[int, int]:
    """``"480x300"`` -> (480, 300) (:func:`emulator.commands.argtypes.size`); a bad size is a :class:`SceneError`."""
    from emulator.commands.argtypes import size

    try:
        return size(text)
    except argparse.ArgumentTypeError as exc:
        raise SceneError(f"--size: {exc}") from None


def parse_params(items: list[str] | None) -> dict:
    """``["sun_elevation_deg=20", "texture_px=512"]`` -> dict (numbers parsed, bools true/false)."""
    out: dict = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise SceneError(f"--param must be KEY=VALUE, got {item!r}")
        v: object
        low = value.strip().lower()
        if low in ("true", "false"):
            v = low == "true"
        else:
            try:
                v = int(value)
            except ValueError:
                try:
                    v = float(value)
                except ValueError:
                    raise SceneError(f"--param {key}: value must be a number or true/false, got {value!r}") from None
        out[key.strip()] = v
    return out


def add_denoise_option(parser) -> None:
    """``--denoise oidn|oidn-fast|oidn-hq|off`` (shared by ``exposim render`` and ``exposim synth``)."""
    from scenes.denoise import DEFAULT_DENOISER, DENOISERS, ENV_DENOISE

    parser.add_argument("--denoise", choices=DENOISERS, default=None,
                        help=f"'oidn': denoise each render with Intel Open Image Denoise fed Mitsuba's "
                             f"albedo and normal; 'oidn-fast': OIDN's balanced filter and a 16-spp albedo/normal "
                             f"pass (about half the time, a little more error); 'oidn-hq': a 1024-spp "
                             f"albedo/normal pass (with --spp 256: render noise no worse than the sensor's for "
                             f"SIFT, about 15x the time of 8 spp); 'off': the raw path-traced "
                             f"estimate (default {DEFAULT_DENOISER}, "
                             f"or ${ENV_DENOISE} when set). Without a usable OIDN "
                             "(pyoidn missing, unsupported CPU) a warning says why and renders are raw")


def add_scheduler_option(parser) -> None:
    """``--scheduler local|tcp://HOST:PORT`` (shared by ``exposim render`` and ``exposim synth``)."""
    from scenes.parallel import SCHEDULER_HELP

    parser.add_argument("--scheduler", default=None, metavar="local|tcp://HOST:PORT",
                        help=SCHEDULER_HELP + " (default: serial, in this process)")


def frame_seed(base_seed: int, index: int, camera: int) -> int:
    """Sampler seed of frame ``index`` of camera 0 (left) or 1 (right): independent noise per image."""
    return (int(base_seed) * 1_000_003 + 2 * int(index) + int(camera)) % (1 << 32)


def register(subparsers) -> None:
    """Add the ``render`` sub-command to the ``exposim`` parser."""
    from scenes.base import SCENES

    p = subparsers.add_parser(
        "render",
        help="render a procedural scene along a trajectory to OpenEXR radiance",
        description=(
            "Render a procedural Mitsuba scene along a camera trajectory. Writes one float32 OpenEXR "
            "per frame (frames/left/<timestamp_ns>.exr, and frames/right/ with --stereo), the poses in "
            "TUM format (poses_left.txt, poses_right.txt) and scene.json with the scene parameters, "
            "intrinsics, spp, the denoiser and the dynamic range of every frame. Each frame is a low-spp "
            "render denoised by Open Image Denoise unless --denoise off. Renders are cached on disk."
        ),
    )
    p.add_argument("scene", choices=sorted(SCENES), metavar="SCENE", help=f"one of: {', '.join(sorted(SCENES))}")
    p.add_argument("-o", "--output", required=True, type=Path, help="output folder")
    p.add_argument("--seed", type=int, default=0, help="scene seed (placement, textures); default 0")
    p.add_argument("--param", action="append", metavar="KEY=VALUE", help="scene parameter (repeatable)")
    p.add_argument("--trajectory", default="auto",
                   help="'walk', 'static', 'auto' (static for static scenes, else walk; default) or a TUM "
                        "pose file (renders at its timestamps)")
    p.add_argument("--duration", type=float, default=2.0, help="trajectory duration, s (default 2)")
    p.add_argument("--rate", type=float, default=2.0, help="frames per second (default 2)")
    p.add_argument("--size", default="480x300", help="WIDTHxHEIGHT in pixels (default 480x300)")
    p.add_argument("--fov", type=float, default=None, help="horizontal field of view, degrees (default 78.26)")
    p.add_argument("--spp", default="64",
                   help="samples per pixel (default 64), or 'auto': the smallest of 4..256 whose render noise is "
                        "below the sensor noise at the 32 ms bracket, measured on the first pose at <= 160 px wide "
                        "(256 when none is; the curve goes to scene.json)")
    p.add_argument("--render-seed", type=int, default=0, help="base sampler seed (default 0)")
    p.add_argument("--stereo", action="store_true", help="also render the right camera (baseline 0.18 m)")
    p.add_argument("--baseline", type=float, default=None, help="stereo baseline, m (default 0.18)")
    p.add_argument("--variant", default=None, help="Mitsuba variant (default: probed llvm_ad_rgb, else scalar_rgb)")
    add_denoise_option(p)
    add_scheduler_option(p)
    cache = p.add_mutually_exclusive_group()
    cache.add_argument("--cache-dir", dest="cache", metavar="DIR", type=Path, default=None, help="render cache folder (default "
                       "$EXPOSIM_CACHE or ~/.cache/exposim/renders)")
    cache.add_argument("--cache", dest="cache", type=Path, default=None, help=argparse.SUPPRESS)  # old spelling
    cache.add_argument("--no-cache", action="store_true", help="do not read or write the render cache")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    add_quiet(p)
    p.set_defaults(func=run_render, extras=("synth",))


def _timestamps_and_poses(scene, args):
    import numpy as np

    from emulator.io.tum import read_tum
    from scenes import trajectory as tr

    mode = args.trajectory
    if mode not in ("auto", "walk", "static"):
        path = Path(mode)
        if not path.is_file():
            raise FileNotFoundError(f"--trajectory: no such TUM pose file: {path}")
        poses_file = read_tum(path, allow_empty=True)
        if len(poses_file) == 0:
            raise SceneError(f"--trajectory: {path} holds no pose")
        return poses_file.timestamps_s, poses_file.poses
    if not (math.isfinite(args.duration) and args.duration >= 0):
        raise SceneError(f"--duration must be >= 0, got {args.duration}")
    if not (math.isfinite(args.rate) and args.rate > 0):
        raise SceneError(f"--rate must be > 0, got {args.rate}")
    duration = max(float(args.duration), 1e-3)
    if mode == "static" or (mode == "auto" and scene.is_static):
        traj = tr.static(scene.default_pose(), duration_s=duration)
    else:
        from scenes.walks import DEFAULT_WALK, make_walk

        traj = make_walk(DEFAULT_WALK, duration, seed=scene.seed, start=scene.start, heading_deg=scene.heading_deg,
                         stream=scene.name)
    ts = traj.timestamps(args.rate) if args.duration > 0 else np.zeros(1)
    return ts, traj.poses(ts)


def _checked_output(out: Path, cameras: list[str], stamps_ns: list[int], *, stereo: bool, force: bool) -> Path:
    """``out``, refused when it is a file, or when it holds an output file of this render and not ``force``."""
    from emulator.errors import OutputExistsError

    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"-o: {out} exists and is not a folder")
    targets = [out / "scene.json", out / "poses_left.txt"] + ([out / "poses_right.txt"] if stereo else [])
    targets += [out / "frames" / cam / f"{ns}.exr" for cam in cameras for ns in stamps_ns]
    existing = [t for t in targets if t.exists()]
    if existing and not force:
        raise OutputExistsError(f"{existing[0]} exists ({len(existing)} output file(s) in {out}); "
                                f"use --force to overwrite")
    return out


def _spp(value, scene, pose, width: int, height: int, fov: float, variant: str, cache_dir):
    """``--spp``: an integer, or ``auto`` (:func:`scenes.select_spp` on ``pose``): ``(spp, selection record or
    None)``."""
    from scenes.spp import select_spp

    if str(value).lower() == "auto":
        # measured on the first pose, at no more than 160 px wide to keep it affordable
        sel_w = min(width, 160)
        sel_h = max(1, round(height * sel_w / width))
        selection = select_spp(scene, pose, width=sel_w, height=sel_h, fov_deg=fov, variant=variant,
                                      candidates=(4, 9, 16, 36, 64, 144, 256), cache_dir=cache_dir)
        return selection.spp, selection.to_dict()
    try:
        return int(value), None
    except ValueError:
        raise RenderError(f"--spp must be an integer or 'auto', got {value!r}") from None


def run_render(args: argparse.Namespace) -> int:
    """Body of ``exposim render``."""
    import numpy as np

    from scenes.base import get_scene
    from scenes.camera import DEFAULT_FOV_DEG, intrinsics
    from scenes.dynamic_range import dynamic_range_db
    from emulator.io.exr import write_exr
    from emulator.io.files import write_metadata
    from emulator.io.tum import write_tum
    from scenes import trajectory as tr
    from scenes.cache import library_versions, resolve_cache_dir
    from scenes.denoise import effective_denoise
    from scenes.variant import check_variant_name, choose_variant

    width, height = parse_size(args.size)
    fov = DEFAULT_FOV_DEG if args.fov is None else args.fov
    scene = get_scene(args.scene, seed=args.seed, **parse_params(args.param))
    ts, poses = _timestamps_and_poses(scene, args)
    baseline = tr.BASELINE_M if args.baseline is None else float(args.baseline)
    cameras = ["left", "right"] if args.stereo else ["left"]
    stamps_ns = [int(round(t * 1e9)) for t in ts]
    if len(set(stamps_ns)) != len(stamps_ns):
        raise SceneError("--trajectory: timestamps must be distinct (after rounding to ns)")

    out = _checked_output(Path(args.output), cameras, stamps_ns, stereo=args.stereo, force=args.force)

    from scenes.parallel import check_scheduler, render_many

    scheduler = check_scheduler(getattr(args, "scheduler", None))
    cache_dir = False if args.no_cache else args.cache
    denoise, denoise_fallback = effective_denoise(args.denoise)
    variant = check_variant_name(args.variant) if args.variant else choose_variant()
    spp, spp_info = _spp(args.spp, scene, poses[0], width, height, fov, variant, cache_dir)

    for cam in cameras:
        (out / "frames" / cam).mkdir(parents=True, exist_ok=True)
    frames = []
    jobs = [(i, cam) for i in range(len(ts)) for cam in cameras]
    from tqdm import tqdm

    # every job complete (explicit cache folder, variant, denoiser): a Dask worker decides nothing
    folder = resolve_cache_dir(cache_dir)
    seeds = [frame_seed(args.render_seed, i, 0 if cam == "left" else 1) for i, cam in jobs]
    tasks = [dict(scene=scene, pose=poses[i] if cam == "left" else tr.stereo_right(poses[i], baseline),
                  width=width, height=height, spp=spp, seed=seed, fov_deg=fov,
                  cache_dir=False if folder is None else folder, variant=variant, denoise=denoise)
             for (i, cam), seed in zip(jobs, seeds)]
    with tqdm(total=len(jobs), desc=f"render {scene.name}", unit="img", disable=not bars_enabled(args.quiet),
              file=sys.stderr) as bar:
        for (i, cam), seed, img in zip(jobs, seeds, render_many(tasks, scheduler=scheduler, progress=bar.update)):
            write_exr(out / "frames" / cam / f"{stamps_ns[i]}.exr", img, overwrite=True)
            frames.append({"camera": cam, "timestamp_ns": stamps_ns[i], "seed": seed,
                           "dynamic_range_db": round(dynamic_range_db(img), 3)})

    write_tum(out / "poses_left.txt", stamps_ns, poses)
    if args.stereo:
        write_tum(out / "poses_right.txt", stamps_ns, np.stack([tr.stereo_right(p, baseline) for p in poses]))
    fx, fy, cx, cy = intrinsics(width, height, fov)
    drs = [f["dynamic_range_db"] for f in frames]
    info = {
        "scene": scene.name,
        "description": scene.description,
        "seed": scene.seed,
        "params": dict(scene.params),
        "reference_radiance": scene.reference_radiance,
        "width": width,
        "height": height,
        "fov_deg": fov,
        "intrinsics": {"fx": fx, "fy": fy, "cx": cx, "cy": cy},
        "spp": spp,
        "spp_selection": spp_info,
        "denoise": denoise.key_material(),
        "denoise_fallback": denoise_fallback,
        "variant": variant,
        "versions": library_versions(),
        "baseline_m": baseline if args.stereo else None,
        "radiance_units": "W m^-2 sr^-1, linear Rec.709 RGB",
        "pose_convention": "camera-to-world, OpenCV camera frame (x right, y down, z forward), world z up",
        "dynamic_range_db": {"min": min(drs), "median": float(np.median(drs)), "max": max(drs)},
        "frames": frames,
    }
    write_metadata(out / "scene.json", info, overwrite=True)
    return 0


register.order = 60  # place in `exposim --help`
