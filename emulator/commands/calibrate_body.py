"""What ``exposim calibrate`` runs, imported when it runs (its arguments: :mod:`emulator.commands.calibrate`)."""

from __future__ import annotations

from emulator.commands.progress import bars_enabled
from emulator.calibration import calibrate_from_recording, calibrate_stack, cross_bracket_error
from emulator.errors import ExposimError, OutputExistsError
from emulator.io.borealhdr import find_response, load_sequence, sequence_response
from emulator.io.files import strict_json
from emulator.io.noisemodel import write_noise_model
from emulator.io.pcalib import write_response
from emulator.io.stack import read_stack
from emulator.noise import bracket_groups, estimate_noise_model, json_safe
from emulator.report.calibration import plot_calibration

__all__ = ["calibrate"]


def _progress_bar(enabled: bool):
    """A progress(done, total, label) callable drawing a tqdm bar (per phase), and a closer."""
    if not enabled:
        return None, lambda: None
    from tqdm import tqdm

    state: dict = {}

    def progress(done: int, total: int, label: str) -> None:
        phase = label.split(":")[0].split(" ")[0]
        bar = state.get("bar")
        if bar is None or state.get("phase") != phase or state.get("total") != total:
            if bar is not None:
                bar.close()
            bar = tqdm(total=total, desc=phase, unit="step", leave=False, dynamic_ncols=True)
            state.update(bar=bar, phase=phase, total=total)
        bar.n = done
        bar.set_postfix_str(label, refresh=False)
        bar.refresh()

    def close() -> None:
        if state.get("bar") is not None:
            state["bar"].close()

    return progress, close


def _check_levels(args) -> None:
    """--white-level / --black-level only where they are used: a STACK folder (whose reader
    checks 0 <= black < white <= 4095); a recording has its own levels in exposim.json."""
    white = getattr(args, "white_level", None)
    black = getattr(args, "black_level", None)
    given = [f for f, v in (("--white-level", white), ("--black-level", black)) if v is not None]
    if given and args.stack is None:
        raise ExposimError(f"{' and '.join(given)} apply to a STACK folder only; a recording "
                           "(--from-recording, --noise) gives its levels in its exposim.json")


def _fit_response(args, progress):
    """The response fitted from ``args.stack`` or ``args.from_recording``, with the recording's cross-bracket
    scores (recovered and existing response; None with --no-score or a stack) and the existing response:
    ``(result, score, reference)``."""
    score = None
    reference = None
    if args.stack is not None:
        kw = {"margin_dn": args.margin}
        if args.knots is not None:
            kw["n_knots"] = args.knots
        if args.smoothness is not None:
            kw["smoothness"] = args.smoothness

        stack = read_stack(args.stack, white_level=args.white_level, black_level=args.black_level)
        result = calibrate_stack(
            stack, max_pixels=args.pixels, check_static=not args.no_static_check, rng=args.seed,
            progress=progress, **kw,
        )
    else:
        seq = load_sequence(args.from_recording)
        cams = None if args.camera == "both" else (args.camera,)
        kw = {"margin_dn": args.margin, "stride": args.stride}
        if args.knots is not None:
            kw["n_knots"] = args.knots
        if args.smoothness is not None:
            kw["smoothness"] = args.smoothness
        result = calibrate_from_recording(seq, cameras=cams, rng=args.seed, progress=progress, **kw)
        if not args.no_score:
            score = {"recovered": cross_bracket_error(seq, result.response, cameras=cams, stride=args.stride,
                                                      progress=progress)}
            found = find_response(seq.path)
            if found is not None:
                reference = sequence_response(seq, found)
                score["existing"] = cross_bracket_error(seq, reference, cameras=cams, stride=args.stride,
                                                        progress=progress)
    return result, score, reference


def _print_result(args, result, score) -> None:
    """What ``exposim calibrate`` prints without --json: the fit, its samples, residual, warnings and scores."""
    info = result.info
    print(f"method      {result.method}")
    if args.stack is not None:
        print(f"stack       {info['stack']}: {info['n_images']} images, {info['n_exposures']} exposures "
              f"{min(info['exposures_ms']):g}..{max(info['exposures_ms']):g} ms, "
              f"{info['image_size'][0]}x{info['image_size'][1]}")
        print(f"samples     {info['n_pixels']} pixels, {info['n_samples']} unclipped samples "
              f"({100 * info['clipped_fraction']:.1f} % clipped), solver {info['solver']}, "
              f"{info['iterations']} iteration(s){'' if info['converged'] else ' (not converged)'}")
    else:
        print(f"recording   {info['sequence']}: {info['n_pairs']} bracket pairs in {info['n_cycles']} sweeps, "
              f"cameras {', '.join(info['cameras'])}, {info['n_matched_quantiles']} matched quantiles")
    print(f"DN range    observed {result.observed_dn[0]}..{result.observed_dn[1]} "
          f"(extrapolated outside), levels {result.black_level}..{result.white_level}")
    noise = "" if result.noise_dn != result.noise_dn else f", noise ~{result.noise_dn:.2f} DN"
    print(f"residual    {result.residual_rms_dn:.2f} DN RMS ({result.residual_rms_percent:.3f} % of range), "
          f"robust {result.residual_robust_dn:.2f} DN{noise}")
    for w in info.get("warnings", []):
        print(f"warning     {w}")
    print(f"vignetting  {info['vignetting']}")
    if score:
        for k, v in score.items():
            print(f"cross-bracket error ({k}: {v.response_name}): median {v.median_pct:.3f} %, "
                  f"mean {v.mean_pct:.3f} % over {len(v.pairs)} emulations")


def calibrate(args) -> int:
    if sum(x is not None for x in (args.stack, args.from_recording, args.noise)) != 1:
        raise ExposimError("give one of a STACK folder, --from-recording SEQ or --noise SEQ")
    _check_levels(args)
    if args.noise is not None:
        return _calibrate_noise(args)
    out = args.output
    plot_path = out.with_name(out.stem + ".png")
    if not args.force:
        for p in (out, plot_path):
            if p.exists():
                raise OutputExistsError(f"{p}: exists; refusing to overwrite (use --force)")

    progress, close = _progress_bar(bars_enabled(args.quiet or args.json))
    try:
        result, score, reference = _fit_response(args, progress)
    finally:
        close()

    write_response(out, result.response, overwrite=args.force)
    plot_calibration(result, plot_path, reference=reference,
                     reference_label=f"existing {reference.name}" if reference is not None else "reference",
                     overwrite=args.force)

    if args.json:
        d = result.to_dict()
        d["output"] = str(out)
        d["plot"] = str(plot_path)
        if score:
            d["cross_bracket"] = {k: {"response": v.response_name, "median_pct": v.median_pct,
                                      "mean_pct": v.mean_pct, "n_pairs": len(v.pairs)} for k, v in score.items()}

        print(strict_json(d))
        return 0
    _print_result(args, result, score)
    print(f"wrote       {out} and {plot_path}")
    return 0


def _calibrate_noise(args) -> int:
    """``--noise SEQ``: in-situ noise model of a recording, written as JSON."""
    out = args.output
    if out.exists() and not args.force:
        raise OutputExistsError(f"{out}: exists; refusing to overwrite (use --force)")
    if args.max_groups is not None and args.max_groups < 1:
        raise ExposimError(f"--max-groups must be >= 1, got {args.max_groups}")
    seq = load_sequence(args.noise)
    response = sequence_response(seq)
    cams = None if args.camera == "both" else (args.camera,)
    progress, close = _progress_bar(bars_enabled(args.quiet or args.json))
    try:
        groups = bracket_groups(seq, cameras=cams, max_groups=args.max_groups, progress=progress)
        estimate = estimate_noise_model(groups, response, name=f"in-situ:{seq.path}", progress=progress)
    finally:
        close()
    write_noise_model(out, estimate, overwrite=args.force)

    top = float(response.g[response.white_level])
    full_well_std = estimate.gain_std * top
    if args.json:
        d = json_safe(estimate.to_dict())
        d.update(output=str(out), sequence=str(seq.path), response=response.name,
                 full_well_std=json_safe(full_well_std))

        print(strict_json(d))
        return 0

    def pm(value: float, std: float, fmt: str, unit: str) -> str:
        if std == std:
            return f"{value:{fmt}} +- {std:{fmt}} {unit}"
        return f"{value:{fmt}} {unit} (standard error undetermined)"

    spread = estimate.spread.get("gain_e_per_h", {})
    print(f"method      in-situ photon transfer: {len(groups)} bracket group(s) of {seq.path}")
    print(f"response    {response.name} (g({response.white_level}) = {top:.6g}; electrons = gain x g(DN))")
    print(f"gain        {pm(estimate.gain_e_per_h, estimate.gain_std, '.4g', 'e- per unit of g')}")
    print(f"read noise  {pm(estimate.read_noise_e, estimate.read_noise_std, '.3g', 'e- rms')}")
    print(f"full well   {pm(estimate.full_well_e, full_well_std, '.4g', 'e-')} at DN {response.white_level}")
    if spread.get("n"):
        print(f"spread      per-group gain {spread['p16']:.4g}..{spread['p84']:.4g} (16th..84th percentile of "
              f"{spread['n']} groups)")
    for w in estimate.warnings:
        print(f"warning     {w}")
    print(f"wrote       {out}")
    return 0
