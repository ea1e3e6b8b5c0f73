"""``exposim bench features|vo|rpe|compare``: the paper's section V-D benchmarks, and methods side by side.

Only parses arguments and calls one library function of :mod:`emulator.metrics`;
OpenCV, evo, tqdm and matplotlib are imported inside the command functions.
"""

from __future__ import annotations

import argparse
import contextlib
import shlex
import shutil
import sys
from pathlib import Path

from emulator.commands.argtypes import refine_mode
from emulator.commands.progress import add_quiet, progress_arg
from emulator.io.files import to_jsonable, strict_json
from emulator.metrics.bench import bench_features, bench_vo
from emulator.metrics.compare import bench_compare
from emulator.metrics.features import RATIO_TEST
from emulator.metrics.rpe import looks_like_estimate, rpe_files
from emulator.metrics.vo import VOParameters
from emulator.report.bench import features_verdicts, vo_verdicts

__all__ = ["register"]


def _command_line(args: argparse.Namespace, positional: tuple[str, ...]) -> str:
    """The command, rebuilt from the parsed arguments (also right when ``main(argv)`` is
    called in-process, where ``sys.argv`` is someone else's)."""
    parts = ["exposim", "bench", args.bench_command]
    for name in positional:
        value = getattr(args, name)
        parts += [str(v) for v in value] if isinstance(value, list) else [str(value)]
    for name, value in vars(args).items():
        if name in positional or name in ("func", "command", "bench_command") or value is None or value is False:
            continue
        flag = "--" + name.replace("_", "-")
        if value is True:
            parts.append(flag)
        elif isinstance(value, list):
            parts += [flag, ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in value)]
        else:
            parts += [flag, str(value)]
    return shlex.join(parts)


#: emulator.metrics.features.RATIO_TEST, repeated here so that --help does not import OpenCV (a test keeps them equal).
_RATIO_TEST = 0.8


def _ratio(args) -> float:
    return RATIO_TEST if args.ratio is None else args.ratio


def _methods(value: str | None) -> list[str] | None:
    return [m.strip() for m in value.split(",") if m.strip()] if value else None


def _floats(value: str) -> list[float]:
    try:
        return [float(v) for v in value.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {value!r}") from None




@contextlib.contextmanager
def _removed_on_failure(output):
    """Remove ``output`` again if this command created it and then failed (no empty -o folder left)."""
    path = Path(output)
    existed = path.exists()
    try:
        yield
    except BaseException:
        if not existed and path.is_dir():
            shutil.rmtree(path, ignore_errors=True)
        raise


def _print_json(results: dict) -> None:
    print(strict_json(to_jsonable(results), indent=1))


def _features(args: argparse.Namespace) -> int:
    with _removed_on_failure(args.output), progress_arg("exposim bench features", args.quiet) as progress:
        results = _bench_features(args, bench_features, progress)
    if args.json:
        _print_json(results)
    return _features_summary(args, results)


def _bench_features(args, bench_features, progress):
    return bench_features(
        args.run_dirs,
        args.output,
        methods=_methods(args.methods),
        grid=(args.grid, args.grid),
        ratio=_ratio(args),
        n_features=args.n_features,
        matcher=args.matcher,
        scale=args.scale,
        max_frames=args.max_frames,
        every_frame=args.every_frame,
        force=args.force,
        progress=progress,
        command=_command_line(args, ("run_dirs",)),
    )


def _features_summary(args, results) -> int:
    if not args.quiet:
        for name, m in results["methods"].items():
            u = m["median_uniformity"]
            print(
                f"{name}: median uniformity {'-' if u is None else f'{100 * u:.1f} %'}, "
                f"median matches {m['median_matches']}, min matches {m['min_matches']}",
                file=sys.stderr,
            )

        for verdict in features_verdicts(results):
            print(f"verdict: {verdict}", file=sys.stderr)
        print(f"wrote {args.output}/results.json, fig4_features.png, report.md, report.html", file=sys.stderr)
    return 0


def _vo(args: argparse.Namespace) -> int:
    params = VOParameters(
        ratio=_ratio(args),
        n_features=args.n_features,
        matcher=args.matcher,
        min_matches=args.min_matches,
        min_inliers=args.min_inliers,
        max_step_m=args.max_step_m,
        seed=args.seed,
    )
    with _removed_on_failure(args.output), progress_arg("exposim bench vo", args.quiet) as progress:
        results = _bench_vo(args, bench_vo, params, progress)
    if args.json:
        _print_json(results)
    return _vo_summary(args, results)


def _bench_vo(args, bench_vo, params, progress):
    return bench_vo(
        args.run_dir,
        args.output,
        reference=args.reference,
        calibration=args.calibration,
        methods=_methods(args.methods),
        parameters=params,
        scale=args.scale,
        baseline_m=args.baseline_m,
        refine_extrinsics=args.refine_extrinsics,
        deltas_m=args.deltas,
        align_scale=not args.no_align_scale,
        max_diff_s=args.max_diff,
        rpe_on_failure=args.rpe_on_failure,
        max_frames=args.max_frames,
        every_frame=args.every_frame,
        force=args.force,
        progress=progress,
        command=_command_line(args, ("run_dir",)),
    )


def _vo_summary(args, results) -> int:
    if not args.quiet:
        choice = results["calibration"]["choice"]
        ext = results["calibration"]["extrinsics"]
        print(f"calibration: {choice['folder']} ({choice['reason']})", file=sys.stderr)
        if ext.get("epipolar_residual_px") is not None:
            print(f"extrinsics: {ext['mode']}, epipolar residual {ext['epipolar_residual_px']:.2f} px"
                  + (f" -> {ext['estimate']['epipolar_residual_after_px']:.2f} px after refinement"
                     if ext.get("refined") else "") + f": {ext['reason']}", file=sys.stderr)
        for note in results["limitations"]:
            print(f"not computed / limited: {note}", file=sys.stderr)
        for name, m in results["methods"].items():
            line = f"{name}: {m['status']}, {m['n_tracked']}/{m['n_frames']} frames tracked"
            t = m.get("summary")
            if t:  # the VO table (emulator.metrics.vo_table): what tells methods apart without a reference
                fmt = lambda v, spec: "-" if v is None else format(v, spec)  # noqa: E731
                line += (f", median {fmt(t['median_stereo_points'], '.0f')} stereo points, "
                         f"{fmt(t['median_inliers'], '.0f')} PnP inliers, path {t['path_length_m']:.3f} m")
            if m["rpe"]:
                first = next((e for e in m["rpe"]["deltas"] if e.get("trans_percent") or e.get("trans_pct")), None)
                if first:
                    trans = first.get("trans_percent") or first["trans_pct"]  # trans_pct: results before the rename
                    line += (
                        f", RPE at {first['delta_m']:.2f} m: {trans['median']:.2f} % "
                        f"{first['rot_deg_per_m']['median']:.3f} deg/m"
                    )
            print(line, file=sys.stderr)

        for verdict in vo_verdicts(results):
            print(f"verdict: {verdict}", file=sys.stderr)
        print(f"wrote {args.output}/results.json, <method>.txt (TUM; evo_traj tum {args.output}/*.txt), "
              + ("fig6_rpe.png, " if results["reference"] is not None else "")
              + "trajectories.png, report.md, report.html"
              + (", evo/rpe_*/<method>.zip (evo_res)" if any(m["evo_results"] for m in results["methods"].values())
                 else ""), file=sys.stderr)
    return 0


def _compare(args: argparse.Namespace) -> int:
    with _removed_on_failure(args.output):
        results = bench_compare(args.folders, args.output, force=args.force,
                                command=_command_line(args, ("folders",)))
    if args.json:
        _print_json(results)
    if not args.quiet:
        cmp = results["comparisons"]
        primary = cmp[cmp["primary"]]["methods"]
        scale, unit = (100.0, " %") if cmp["primary"] == "mean_saturated_fraction" else (1.0, "")
        for k, label in enumerate(results["ranking"], 1):
            r = primary[label]
            iv = "" if not r["ci95"] else f" [{scale * r['ci95'][0]:.3g}, {scale * r['ci95'][1]:.3g}]"
            print(f"{k}. {label}: {cmp['primary'].replace('_', ' ')} {scale * r['estimate']:.3g}{unit}{iv}",
                  file=sys.stderr)
        for name, t in (cmp.get("still_trending") or {}).items():
            print(f"too short to settle: {name} still {t['direction']} at the end", file=sys.stderr)
        print(f"wrote {args.output}/results.json, report.md, report.html", file=sys.stderr)
    return 0


def _rpe(args: argparse.Namespace) -> int:
    # The order is evo's (REF EST); swapping the two changes the numbers, so say which
    # file is which and flag a likely swap.
    ref_why = looks_like_estimate(args.ref)
    swapped = ref_why is not None and looks_like_estimate(args.est) is None
    # evo may print notices on stdout (e.g. when it creates its settings file); keep
    # stdout for the result only.
    with contextlib.redirect_stdout(sys.stderr):
        stats = rpe_files(
            args.ref,
            args.est,
            delta=args.delta,
            delta_unit=args.delta_unit,
            align_scale=args.align_scale,
            max_diff_s=args.max_diff,
        )
    print(f"reference: {args.ref} ({stats['n_ref_poses']} poses); estimate: {args.est} "
          f"({stats['n_est_poses']} poses) (order REF EST, as evo_rpe)", file=sys.stderr)
    if swapped:
        print(f"warning: the reference {args.ref} looks like an estimate ({ref_why}) and the estimate {args.est} "
              "does not; the order is REF EST as in evo_rpe: swap the files if they are the wrong way round",
              file=sys.stderr)
    if args.json:
        print(strict_json({"rmse": stats["rmse"], "mean": stats["mean"], "median": stats["median"]}))
    else:
        unit = "frames" if args.delta_unit == "f" else "m"
        scaled = f", scale corrected x{stats['scale']:.6f}" if args.align_scale else ""
        print(
            f"RPE translation (m), delta {args.delta:g} {unit}, {stats['n_pairs']} pairs{scaled}: "
            f"rmse {stats['rmse']:.6f}  mean {stats['mean']:.6f}  median {stats['median']:.6f}  "
            f"std {stats['std']:.6f}  min {stats['min']:.6f}  max {stats['max']:.6f}"
        )
    return 0


def _help(parser: argparse.ArgumentParser):
    def show(args: argparse.Namespace) -> int:
        parser.print_help()
        return 2

    return show


def _common_sift(p: argparse.ArgumentParser) -> None:
    p.add_argument("--ratio", type=float, default=None,
                   help=f"Lowe ratio test threshold (default {_RATIO_TEST}, the same for features and VO)")
    p.add_argument("--n-features", type=int, default=0, help="SIFT keypoints kept per image, 0 = all (default)")
    p.add_argument("--matcher", choices=("flann", "bf"), default="flann",
                   help="nearest neighbours: kd-trees (default) or exact brute force")
    p.add_argument("--methods", help="comma-separated subset of the run's methods")
    p.add_argument("--max-frames", type=int, help="use only the first N images of each method (a reduced run)")
    p.add_argument("--every-frame", action="store_true",
                   help="a run made with --rate native: use every frame (default: one per recorder cycle, the frame at "
                        "the cycle's first shot, so that native and cycle-rate runs are compared on the same images)")
    p.add_argument("-o", "--output", required=True, help="output folder (results.json, figures, report.md)")
    p.add_argument("--force", action="store_true", help="overwrite an existing results.json")
    add_quiet(p, "no progress bars or summary")
    p.add_argument("--json", action="store_true", help="print results.json to stdout")


def _add_features(sub) -> None:
    """``exposim bench features``."""
    f = sub.add_parser(
        "features",
        help="SIFT uniformity, matches and success rate (Fig. 4)",
        description="SIFT on the emulated left images of each method: uniformity on a grid, ratio-test matches "
        "between consecutive images, success rate against tau_matches. Several run folders (one per sequence) "
        "give the success rate over sequences.",
    )
    f.add_argument("run_dirs", nargs="+", metavar="RUN_DIR", help="output folder(s) of `exposim run`")
    f.add_argument("--grid", type=int, default=20, help="grid cells per side for uniformity (default 20)")
    f.add_argument("--scale", type=float, default=1.0, help="image scale before SIFT, (0, 1] (default 1)")
    _common_sift(f)
    f.set_defaults(func=_features)


def _add_vo(sub) -> None:
    """``exposim bench vo``."""
    v = sub.add_parser(
        "vo",
        help="stereo VO per method and RPE against a reference (Fig. 6)",
        description="Minimal OpenCV stereo VO (rectification, SIFT stereo depth, PnP RANSAC) on each method's "
        "images; RPE through evo against the reference as a function of trajectory length.",
    )
    v.add_argument("run_dir", metavar="RUN_DIR", help="output folder of `exposim run` (left and right images saved)")
    v.add_argument("--reference", help="reference trajectory, TUM format, left camera-to-world (default: the "
                   "sequence's ground_truth/poses_left.txt if it exists)")
    v.add_argument("--calibration", help="folder with left.yaml, right.yaml (default: chosen from the layout and "
                   "the recording's date: <sequence>/calibration, calibration/<month>_<year>/ beside the recording, "
                   "or calibration_files/calibration_vo/<month>_<year>/ of a BorealHDR clone)")
    v.add_argument("--baseline-m", type=float, help="override the calibration's stereo baseline (m)")
    v.add_argument("--refine-extrinsics", type=refine_mode, default="auto", metavar="auto|N",
                   help="re-estimate the rig's relative rotation from left-right matches: 'auto' (default) when "
                   "the median epipolar residual of 2 stereo pairs under the calibration exceeds half the row "
                   "tolerance (the BorealHDR Sept. 2023 files: 17 px); N > 0: always, from N pairs; 0: never")
    v.add_argument("--scale", type=float, default=1.0, help="rectified image scale, (0, 1] (default 1)")
    v.add_argument("--deltas", type=_floats, help="RPE pair lengths in m, comma-separated (default: 10..50 %% "
                   "of the reference path length)")
    v.add_argument("--no-align-scale", action="store_true", help="do not correct the estimate's scale before RPE")
    v.add_argument("--max-diff", type=float, default=0.06,
                   help="max time difference image-reference in s (default 0.06)")
    v.add_argument("--rpe-on-failure", action="store_true", help="also compute the RPE of runs where VO failed")
    v.add_argument("--min-matches", type=int, default=20, help="fewest temporal matches for PnP (default 20)")
    v.add_argument("--min-inliers", type=int, default=15, help="fewest PnP inliers (default 15)")
    v.add_argument("--max-step-m", type=float, default=1.0,
                   help="largest plausible motion between frames in m (default 1)")
    v.add_argument("--seed", type=int, default=0, help="OpenCV RNG seed for RANSAC and kd-trees (default 0)")
    _common_sift(v)
    v.set_defaults(func=_vo)


def _add_rpe(sub) -> None:
    """``exposim bench rpe``."""
    r = sub.add_parser(
        "rpe",
        help="translation RPE of two TUM files, REF then EST, as evo_rpe computes it",
        description="Translation RPE of EST against REF through evo's library, arguments in evo's order; equals "
        "`evo_rpe tum REF EST --pose_relation trans_part --delta D --delta_unit U [--correct_scale]`. "
        "Which file is the reference is printed on stderr, with a warning when REF is a trajectory written by "
        "`exposim bench vo` and EST is not.",
    )
    r.add_argument("ref", metavar="REF.txt", help="reference trajectory (TUM), first as in evo_rpe")
    r.add_argument("est", metavar="EST.txt", help="estimated trajectory (TUM)")
    r.add_argument("--delta", type=float, default=1.0, help="pair spacing (default 1)")
    r.add_argument("--delta-unit", choices=("m", "f"), default="f", help="metres or frames (default f)")
    r.add_argument("--align-scale", action="store_true", help="correct the estimate's scale (evo --correct_scale)")
    r.add_argument("--max-diff", type=float, default=0.01,
                   help="max timestamp difference for association in s (default 0.01, as evo_rpe)")
    r.add_argument("--json", action="store_true", help='print {"rmse": ..., "mean": ..., "median": ...} only')
    r.set_defaults(func=_rpe)


def _add_compare(sub) -> None:
    """``exposim bench compare``."""
    c = sub.add_parser(
        "compare",
        help="methods of several run (or bench features) folders side by side, in one ranking",
        description="Put the methods of several folders of one recording in one table with 95 % intervals: run "
        "folders of `exposim run` (mean saturated fraction, mean exposure) or output folders of `exposim bench "
        "features` (median matches, median uniformity). A plugin-only run and an earlier run of the built-ins "
        "make one ranking; a cycle-rate and a native-rate run of the same methods stand side by side, judged "
        "on the same recorder cycles. A method in several folders is named by its rate, else by its folder.",
    )
    c.add_argument("folders", nargs="+", metavar="FOLDER", help="run folders, or bench features folders (one kind)")
    c.add_argument("-o", "--output", required=True, help="output folder (results.json, report.md, report.html)")
    c.add_argument("--force", action="store_true", help="overwrite an existing results.json")
    add_quiet(c, "no summary")
    c.add_argument("--json", action="store_true", help="print results.json to stdout")
    c.set_defaults(func=_compare)


def register(subparsers) -> None:
    """Add ``bench`` with ``features``, ``vo`` and ``rpe`` to the ``exposim`` parser."""
    bench = subparsers.add_parser(
        "bench",
        help="benchmarks of paper section V-D: SIFT features, stereo VO, RPE",
        description="Measure what each AE method does to a VSLAM pipeline (paper section V-D).",
    )
    bench.set_defaults(func=_help(bench))
    sub = bench.add_subparsers(dest="bench_command", metavar="BENCHMARK")

    _add_features(sub)
    _add_vo(sub)
    _add_rpe(sub)
    _add_compare(sub)


register.order = 40  # place in `exposim --help`
