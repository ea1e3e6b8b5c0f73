"""``exposim bench features|vo|rpe|compare``: the paper's section V-D benchmarks, and methods side by side.

Only parses arguments and calls one library function of :mod:`emulator.metrics`;
OpenCV, evo, tqdm and matplotlib are imported inside the command functions.
"""

from __future__ import annotations

import argparse

from emulator.commands.argtypes import refine_mode
from emulator.commands.progress import add_quiet
from emulator.commands.body import CommandBody

__all__ = ["register"]


#: emulator.metrics.features.RATIO_TEST, repeated here so that --help does not import OpenCV (a test keeps them equal).
_RATIO_TEST = 0.8


def _floats(value: str) -> list[float]:
    try:
        return [float(v) for v in value.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {value!r}") from None


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
    f.set_defaults(func=CommandBody("emulator.commands.bench_body:features"))


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
    v.set_defaults(func=CommandBody("emulator.commands.bench_body:vo"))


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
    r.set_defaults(func=CommandBody("emulator.commands.bench_body:rpe"))


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
    c.set_defaults(func=CommandBody("emulator.commands.bench_body:compare"))


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
