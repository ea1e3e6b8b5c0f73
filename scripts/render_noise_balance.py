"""Render noise against sensor noise for features, per render setting (validation/render_study/balance.py).

Usage:
    python scripts/render_noise_balance.py -o OUT.json oidn-fast@2 oidn@64/1024+sun=16 study-hq
        [--scenes forest_winter,forest_edge | --scenes study] [--baseline study-oidn8 | --baseline none]
        [--sweeps 0,11,22,33,44] [--render-per cycle|shot|still] [--size 480x300] [--exposures 8,32]
        [--cache-dir DIR]

For each scene and each setting (a preset of scenes.presets, or DENOISER@SPP[/AUX_SPP][+LIGHT=WEIGHT,...]
[~xFACTOR:PERCENT%[/TILE][@MSms]], the last an adaptive sample count, scenes.adaptive):
keypoint repeatability between two render seeds (same sensor noise) and between two sensor-noise draws (same
render), at each exposure, mean and 95 % interval over the walk's sweeps, and the renders' seconds per sweep and
camera. The baseline setting (default study-oidn8, the live study's former renders) is measured first on each
scene in the same run, and every setting's seconds are also given as a ratio to it. A setting whose renders all
came from the render cache (--cache-dir) is not timed: its seconds and ratio are left empty ("cached"). A setting
meets the goal at an exposure when the difference's whole 95 % interval is at or above -3 points. Writes OUT.json
(refuses an existing file) and OUT.md (the table), and prints one line per setting and exposure.
"""

import argparse
import os
import platform
import sys
from pathlib import Path

import numpy as np

import scenes
from emulator.errors import ExposimError
from emulator.io.files import strict_json, write_text
from scenes.cache import library_versions
from scenes.variant import ENV_VARIANT, gpu_description
from scenes.presets import LEGACY_STUDY_PRESET
from validation.render_study.balance import noise_balance, pareto_table, parse_setting, radiance_bias


def _floats(text):
    try:
        return tuple(float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None


def _size(text):
    w, sep, h = text.partition("x")
    if not (sep and w.isdigit() and h.isdigit()):
        raise argparse.ArgumentTypeError(f"expected WxH, e.g. 480x300, got {text!r}")
    return int(w), int(h)


def _machine() -> dict:
    """Where the figures are made: the render variant, the GPU it renders on, the cores and the versions that
    shape the figures (Mitsuba's and Dr.Jit's as the render cache keys them: "missing" where not installed)."""
    import cv2  # the features' library (the measure imports it anyway)

    variant = scenes.choose_variant()
    return {"render_variant": variant, "gpu": gpu_description() if variant.startswith("cuda_") else None,
            "cpu_count": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__,
            "opencv": cv2.__version__, **library_versions()}


def _command(argv) -> str:
    """The command line as a reader reruns it: the forced variant, if any, and the output file's name alone."""
    args = list(argv)
    for i, a in enumerate(args[:-1]):
        if a in ("-o", "--output"):
            args[i + 1] = Path(args[i + 1]).name
        elif a == "--cache-dir":  # a folder of this machine: a placeholder
            args[i + 1] = "CACHE"
    forced = os.environ.get(ENV_VARIANT, "").strip()
    return " ".join(([f"{ENV_VARIANT}={forced}"] if forced else []) + ["python scripts/render_noise_balance.py"] + args)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("settings", nargs="+", help="render settings, e.g. oidn-fast@2 oidn@8 oidn@8/32 off@64")
    p.add_argument("-o", "--output", type=Path, required=True, help="JSON file to write (never overwritten)")
    p.add_argument("--scene", default=None, help="one scene (default forest_winter); see --scenes")
    p.add_argument("--scenes", default=None,
                   help="comma-separated study scenes, or 'study' for the live study's four (default forest_winter)")
    p.add_argument("--baseline", default=LEGACY_STUDY_PRESET,
                   help=f"setting timed first on each scene for the ratios (default {LEGACY_STUDY_PRESET}; 'none': no "
                        f"baseline)")
    p.add_argument("--size", type=_size, default=(480, 300))
    p.add_argument("--exposures", type=_floats, default=(8.0, 32.0), help="ms (default 8,32)")
    p.add_argument("--sweeps", type=_floats, default=(0, 11, 22, 33, 44),
                   help="bracket sweeps of the walk, 273 ms each (default 0,11,22,33,44: every 3 s)")
    p.add_argument("--render-per", choices=("cycle", "shot", "still"), default="cycle",
                   help="the study's shots from one render per sweep (default), from one render per shot, or "
                        "still renders without warp and blur")
    p.add_argument("--bias-reference", default=None, metavar="SETTING",
                   help="also measure each setting's mean radiance against this deep reference (e.g. off@256) at "
                        "sweeps 0, 22, 44 of the walk (still renders): the radiance bias the setting introduces")
    p.add_argument("--cache-dir", default=None,
                   help="render cache: each setting and scene in a folder of its own below it, the bias reference's "
                        "renders in reference/ (default none, so that the seconds are the renders')")
    args = p.parse_args(argv)
    if args.output.exists():
        print(f"{args.output}: exists; choose another output file", file=sys.stderr)
        return 2
    table_path = args.output.with_suffix(".md")
    if table_path.exists():
        print(f"{table_path}: exists; choose another output file", file=sys.stderr)
        return 2
    try:
        scene_keys = _scenes(args.scene, args.scenes)
        baseline = None if args.baseline == "none" else args.baseline
        settings = ([baseline] if baseline else []) + [s for s in args.settings if s != baseline]
        for s in settings:
            parse_setting(s)
        machine = _machine()
        results = []
        for key in scene_keys:
            for s in settings:
                # each setting its own cache folder: two settings of one spp share their raw renders there,
                # and the second would be timed without its path tracing
                own = Path(args.cache_dir) / f"{key}-{settings.index(s)}" if args.cache_dir else False
                r = noise_balance(s, scene_key=key, width=args.size[0], height=args.size[1],
                                  exposures_ms=args.exposures, sweeps=tuple(int(x) for x in args.sweeps),
                                  render_per=args.render_per, cache_dir=own)
                if baseline:
                    base = next(x for x in results + [r] if x["scene"] == key and x["setting"] == baseline)
                    r["baseline"] = baseline
                    # None when either was read from the render cache: its seconds are not a render's
                    r["ratio_to_baseline"] = (r["seconds_per_sweep"] / base["seconds_per_sweep"]
                                              if r["seconds_per_sweep"] and base["seconds_per_sweep"] else None)
                if args.bias_reference:
                    r["radiance"] = radiance_bias(s, scene_key=key, reference=args.bias_reference,
                                                  width=args.size[0], height=args.size[1], cache_dir=own,
                                                  reference_cache_dir=Path(args.cache_dir) / "reference"
                                                  if args.cache_dir else False)
                results.append(r)
                _print(key, s, r)
    except ExposimError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    args.output.parent.mkdir(parents=True, exist_ok=True)
    # strict JSON: one sweep has no interval, written as null with the reason
    doc = {"command": _command(sys.argv[1:] if argv is None else argv), "machine": machine, "results": results}
    write_text(args.output, strict_json(doc, indent=1) + "\n", overwrite=False)
    write_text(table_path, pareto_table(results) + "\n", overwrite=False)
    return 0


def _scenes(one, many) -> list[str]:
    from validation.live.config import SCENES as STUDY_SCENES

    if one and many:
        raise ExposimError("give --scene or --scenes, not both")
    if many == "study":
        return list(STUDY_SCENES)
    keys = [k.strip() for k in (many or one or "forest_winter").split(",") if k.strip()]
    if not keys or len(set(keys)) != len(keys):
        raise ExposimError(f"--scenes: each scene once, got {many!r}")
    return keys


def _print(scene: str, setting: str, r: dict) -> None:
    for e, v in r["exposures"].items():
        ro, so, d = v["render_only"], v["sensor_only"], v["difference"]
        ratio = r.get("ratio_to_baseline")
        print(f"{scene:>13} {setting:>22} {e:>3} ms  render-only {ro[0]:5.1f} [{ro[1]:5.1f}, {ro[2]:5.1f}]  sensor-only "
              f"{so[0]:5.1f} [{so[1]:5.1f}, {so[2]:5.1f}]  difference {d[0]:+5.1f} [{d[1]:+5.1f}, {d[2]:+5.1f}]"
              f"  {'met' if v['met'] else 'NOT met'} (whole interval)  "
              + ("cached, not timed" if r["seconds_per_sweep"] is None else f"{r['seconds_per_sweep']:.2f} s/sweep")
              + (f" ({ratio:.2f}x)" if ratio is not None else ""), flush=True)
    if "radiance" in r:
        b, d = r["radiance"]["difference_percent"], r["radiance"]["difference_percent_sun_excluded"]
        print(f"{scene:>13} {setting:>22} mean radiance against {r['radiance']['reference']}: {b[0]:+.2f} % "
              f"[{b[1]:+.2f}, {b[2]:+.2f}]; without the sun disk {d[0]:+.2f} % [{d[1]:+.2f}, {d[2]:+.2f}]", flush=True)


if __name__ == "__main__":
    sys.exit(main())
