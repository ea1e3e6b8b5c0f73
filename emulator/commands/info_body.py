"""What ``exposim info`` runs, imported when it runs (its arguments: :mod:`emulator.commands.info`)."""

from __future__ import annotations

from pathlib import Path

from emulator.cells import DASH, format_number
from emulator.errors import CalibrationError
from emulator.io.borealhdr import load_sequence, find_response
from emulator.io.files import strict_json
from emulator.io.imu import ImuMissingWarning
from emulator.metrics.stereo_calibration import choose_calibration
from emulator.playback.motion import blur_table, recording_motion

__all__ = ["info"]


def info(args) -> int:
    import warnings

    with warnings.catch_warnings():  # info reports the IMU itself ("imu": null / "imu  none")
        warnings.simplefilter("ignore", ImuMissingWarning)
        seq = load_sequence(args.sequence, frame_cache=args.frame_cache)
    desc = seq.describe()
    desc["imu"], desc["blur"] = _motion(seq, args)
    desc["response"], desc["calibration"] = _found_files(seq, args.calibration)
    if args.json:
        print(strict_json(desc, indent=1))
        return 0
    print(f"sequence   {seq.path}")
    print(f"cameras    {', '.join(seq.cameras)}")
    print(f"brackets   {', '.join(f'{b:g}' for b in seq.brackets)} ms")
    print(f"levels     black {seq.black_level}, white {seq.white_level}")
    print(f"response   {desc['response'] or 'none found (exposim run needs --response FILE)'}")
    cal = desc["calibration"]
    print(f"calibration {cal['folder']} ({cal['reason']})" if cal["folder"] else f"calibration none: {cal['reason']}")
    print(f"cycles     {len(seq)} ({len(seq) - len(seq.partial_cycles)} complete, partial: {seq.partial_cycles or 'none'})")
    for c in desc["cycles"]:
        cams = "  ".join(f"{cam}: {len(c.get(cam, {}))}/{len(seq.brackets)}" for cam in seq.cameras)
        print(f"  cycle {c['index']:4d}  t0 {c['timestamp_ns']}  {cams}{'  partial' if c['partial'] else ''}")
    if seq.gaps:
        print("gaps")
        for g in seq.gaps:
            print(f"  {g}")
    _print_blur(seq, desc["imu"], desc["blur"])
    return 0


def _found_files(seq, calibration) -> tuple[str | None, dict]:
    """(the response file a run would use, the stereo calibration bench vo and export would use, and why)."""
    response = find_response(seq.path)
    try:
        choice = choose_calibration(seq.path, calibration, seq.cycles[0].timestamp_ns if seq.cycles else None)
        cal = {"folder": str(Path(choice.folder).resolve()), "reason": choice.reason}
    except CalibrationError as exc:
        if calibration is not None:
            raise
        cal = {"folder": None, "reason": str(exc)}
    return (str(Path(response).resolve()) if response is not None else None), cal


def _motion(seq, args) -> tuple[dict | None, dict | None]:
    """(IMU summary, predicted blur per left frame) for ``info``; (None, None) without an IMU."""
    if seq.imu is None:
        return None, None
    try:
        motion = recording_motion(seq, args.calibration, stamp=args.stamp)
    except CalibrationError as exc:
        if args.calibration is not None:
            raise
        return seq.imu.describe(), {"error": str(exc)}
    cam = "left" if "left" in seq.cameras else seq.cameras[0]
    return seq.imu.describe(), {
        "camera": cam,
        "stamp": motion.stamp,
        "R_cam_imu": motion.R_cam_imu.tolist(),
        "focal_px": float(motion.K(cam)[0][0, 0]),
        "frames": blur_table(seq, motion, cam),
    }


def _cell(row: dict | None) -> str:
    text = DASH if row is None else f"{format_number(row['max_px'], '.2f')}/{format_number(row['centre_px'], '.2f')}"
    return f"{text:>14s}"


def _print_blur(seq, imu: dict | None, blur: dict | None) -> None:
    if imu is None:
        print("imu        none (no imu/imu.csv): blur is not predicted")
        return
    rate = imu["angular_speed_deg_s"]
    print(f"imu        {imu['n_samples']} samples at {imu['rate_hz']:.1f} Hz; angular speed p50 {rate['p50']:.2f}, "
          f"p90 {rate['p90']:.2f}, p99 {rate['p99']:.2f} deg/s over the whole file")
    if "error" in blur:
        print(f"blur       not predicted: {blur['error']}")
        return
    print(f"blur       px on the {blur['camera']} camera (largest over the image / centre), stamp at exposure "
          f"{blur['stamp']}, f = {blur['focal_px']:.1f} px")
    by_cycle: dict[int, dict[float, dict]] = {}
    for r in blur["frames"]:
        by_cycle.setdefault(r["cycle"], {})[r["exposure_ms"]] = r
    print("  cycle " + "".join(f"{f'{b:g} ms':>14s}" for b in seq.brackets) + "   deg/s")
    for c, rows in sorted(by_cycle.items()):
        cells = "".join(_cell(rows.get(b)) for b in seq.brackets)
        rates = [r["mean_rate_deg_s"] for r in rows.values()]
        print(f"  {c:5d} {cells}   {max(rates):.2f}")
    return None
