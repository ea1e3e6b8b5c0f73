"""What ``exposim bench`` runs, imported when it runs (its arguments: :mod:`emulator.commands.bench`)."""

from __future__ import annotations

import argparse
import contextlib
import shlex
import shutil
import sys
from pathlib import Path

from emulator.commands.progress import progress_arg
from emulator.io.files import to_jsonable, strict_json
from emulator.metrics.bench import bench_features, bench_vo
from emulator.metrics.compare import bench_compare
from emulator.metrics.features import RATIO_TEST
from emulator.metrics.rpe import looks_like_estimate, rpe_files
from emulator.metrics.vo import VOParameters
from emulator.report.bench import features_verdicts, vo_verdicts

__all__ = ["features", "vo", "rpe", "compare"]


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


def _ratio(args) -> float:
    return RATIO_TEST if args.ratio is None else args.ratio


def _methods(value: str | None) -> list[str] | None:
    return [m.strip() for m in value.split(",") if m.strip()] if value else None


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


def features(args: argparse.Namespace) -> int:
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


def vo(args: argparse.Namespace) -> int:
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


def compare(args: argparse.Namespace) -> int:
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


def rpe(args: argparse.Namespace) -> int:
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
