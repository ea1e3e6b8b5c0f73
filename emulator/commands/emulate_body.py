"""What ``exposim emulate`` runs, imported when it runs (its arguments: :mod:`emulator.commands.emulate`)."""

from __future__ import annotations

import math

from emulator.errors import ExposimError, DatasetError
from emulator.core.blur import emulate_blur_consistent
from emulator.core.emulate import check_exposure, emulate
from emulator.core.select import saturated_fraction, blur_aware, select
from emulator.io.borealhdr import sequence_response, load_sequence
from emulator.io.files import strict_json
from emulator.io.png import write_png8, write_png16
from emulator.orchestration.runner import saved_image
from emulator.playback.motion import blur_hook, recording_motion, find_camera_calibration

__all__ = ["emulate_command", "emulate_cycle"]


def emulate_cycle(
    sequence,
    cycle_index: int,
    exposure_ms: float,
    *,
    cameras: tuple[str, ...] = ("left", "right"),
    selector: str = "higher-no-sat",
    response=None,
    from_ms: float | None = None,
    blur: str = "none",
    calibration=None,
    stamp: str = "end",
):
    """Emulate one cycle; returns (info dict, {camera: image}).

    The selector sees the brackets present for every requested camera and decides on the
    first camera's saturation (the left one for a stereo pair), once for all cameras.
    ``from_ms`` forces the source bracket instead (it must be present for every camera).
    ``selector="blur-aware"``: :func:`emulator.core.select.blur_aware` with the recording's gyro.
    ``blur="consistent"`` adds the blur of the extra exposure time from the recording's
    gyro (:mod:`emulator.playback.motion`); with an IMU, each camera's entry records the predicted
    blur of the source and of a capture at the target (px, largest over the image) and
    ``blur_mismatch_px`` (source minus target: > 0 is blur the emulated image keeps; with
    ``consistent`` the added blur makes it 0 where the target is longer).
    """
    exposure_ms = check_exposure(exposure_ms, "--exposure-ms")
    cycle, available = _cycle_brackets(sequence, cycle_index, cameras)
    response = response or sequence_response(sequence)
    lead = cameras[0]
    levels = dict(white_level=sequence.white_level, black_level=sequence.black_level)
    images = {}

    def frac(b):
        return lambda: saturated_fraction(_load(lead, b), **levels)

    def _load(cam, b):
        key = (cam, b)
        if key not in images:
            images[key] = cycle.frames[cam][b].load()
        return images[key]

    if from_ms is not None:
        from_ms = check_exposure(from_ms, "--from-ms")
        if from_ms not in available:
            raise ExposimError(f"--from-ms {from_ms:g}: cycle {cycle_index} of {sequence.path} has no {from_ms:g} ms "
                               f"bracket for {' and '.join(cameras)} (present: {', '.join(f'{b:g}' for b in available)})")
        chosen = from_ms

    hook = blur_hook(blur, sequence, response, calibration=calibration, stamp=stamp)
    motion = hook.motion if hook is not None else (
        recording_motion(sequence, calibration, stamp=stamp) if sequence.imu is not None and (
            selector == "blur-aware" or _has_calibration(sequence, calibration)) else None)
    if from_ms is None:
        chosen = _select_bracket(selector, exposure_ms, {b: frac(b) for b in available}, levels, motion, sequence,
                                 cycle, lead)
    info = {
        "sequence": str(sequence.path),
        "cycle": cycle_index,
        "target_ms": exposure_ms,
        "selector": selector if from_ms is None else "forced (--from-ms)",
        "bracket_ms": chosen,
        "blur": blur,
        "ratio": exposure_ms / chosen,
        "response": response.name,
        "cameras": {},
    }
    out = {}
    stamps = {cam: cycle.frames[cam][chosen].timestamp_ns for cam in cameras}
    if len(set(stamps.values())) > 1:  # a stereo pair comes from one capture instant
        other = cameras[-1]
        raise DatasetError(f"{cycle.frames[other][chosen].path}: stereo pair mismatch, {other} timestamp "
                           f"{stamps[other]} != {lead} timestamp {stamps[lead]} for bracket {chosen:g} ms")
    for cam in cameras:
        out[cam], info["cameras"][cam] = _emulate_camera(cam, cycle.frames[cam][chosen], _load(cam, chosen), chosen,
                                                         exposure_ms, response, levels, hook, motion)
    info["valid_fraction"] = min(c["valid_fraction"] for c in info["cameras"].values())
    return info, out


def _cycle_brackets(sequence, cycle_index: int, cameras: tuple[str, ...]):
    """The cycle and the brackets present for every camera of ``cameras``, checked: ``(cycle, brackets)``."""
    if not 0 <= cycle_index < len(sequence):
        raise ExposimError(f"cycle {cycle_index} out of range: {sequence.path} has cycles 0..{len(sequence) - 1}")
    missing = [c for c in cameras if c not in sequence.cameras]
    if missing:
        raise ExposimError(f"{sequence.path}: no {', '.join(missing)} camera in this recording")
    cycle = sequence[cycle_index]
    available = cycle.available(cameras)
    if not available:
        raise ExposimError(
            f"{sequence.path}: cycle {cycle_index} has no bracket present for {' and '.join(cameras)}"
        )
    return cycle, available


def _select_bracket(selector: str, exposure_ms: float, fractions: dict, levels: dict, motion, sequence, cycle,
                    lead: str) -> float:
    """The bracket ``selector`` picks from the lead camera's saturated ``fractions`` (bracket -> callable);
    ``blur-aware`` weighs each bracket's excess blur from the recording's gyro (``motion``)."""
    if selector == "blur-aware":
        if motion is None:
            raise ExposimError(f"--selector blur-aware needs the recording's gyro (imu/imu.csv); {sequence.path} has none")
        return blur_aware(exposure_ms, fractions, **levels, excess_blur_px=lambda b: (
            motion.mismatch_px(lead, cycle.frames[lead][b].timestamp_ns, b, exposure_ms)))
    return select(selector, exposure_ms, fractions, **levels)


def _emulate_camera(cam: str, frame, raw, chosen: float, exposure_ms: float, response, levels: dict, hook, motion):
    """One camera's emulated image (blur-consistent with a blur ``hook``) and its entry of ``info["cameras"]``."""
    if hook is not None:
        Hs, ws = motion.homographies(cam, frame.timestamp_ns, chosen, exposure_ms, (raw.shape[1], raw.shape[0]))
        img, valid = emulate_blur_consistent(raw, chosen, exposure_ms, response, Hs, ws)
    else:
        img, valid = emulate(raw, chosen, exposure_ms, response, return_mask=True)
    entry = {
        "source": str(frame.path),
        "timestamp_ns": frame.timestamp_ns,
        "valid_fraction": float(valid.mean()),
        "saturated_fraction_source": saturated_fraction(raw, **levels),
    }
    if motion is not None:
        entry.update(_blur_info(motion, cam, frame.timestamp_ns, chosen, exposure_ms, raw.shape,
                                consistent=hook is not None))
    return img, entry


def _blur_info(motion, cam: str, timestamp_ns: int, source_ms: float, target_ms: float, shape, *,
               consistent: bool) -> dict:
    """Predicted blur of the source and of a capture at the target (px, largest over the image), and
    their difference (0 where blur-consistent emulation added the missing blur)."""
    size = (shape[1], shape[0])
    src = motion.frame_blur(cam, timestamp_ns, source_ms, size).max_px
    tgt = motion.frame_blur(cam, timestamp_ns, target_ms, size).max_px
    mismatch = src - tgt
    if consistent and mismatch < 0:
        mismatch = 0.0
    out = {"source_blur_px": src, "target_blur_px": tgt, "blur_mismatch_px": mismatch}
    for key, ms in (("source_blur_px", source_ms), ("target_blur_px", target_ms)):
        if not math.isfinite(out[key]):  # strict JSON: null, and why
            out[key] = None
            out["blur_mismatch_px"] = None
            out["blur_note"] = (f"no blur predicted for the {ms:g} ms exposure window: the IMU record does not "
                                "cover it")
    return out


def _has_calibration(sequence, calibration) -> bool:
    return find_camera_calibration(sequence, calibration) is not None


def emulate_command(args) -> int:
    seq = load_sequence(args.sequence, frame_cache=args.frame_cache)
    cams = ("left", "right") if args.camera == "both" else (args.camera,)
    if args.camera == "both":
        cams = tuple(c for c in cams if c in seq.cameras) or cams
    response = None
    if args.response is not None:
        response = sequence_response(seq, args.response)
    if args.blur_aware and args.selector != "higher-no-sat":
        raise ExposimError(f"--blur-aware applies to --selector higher-no-sat, not {args.selector}")
    selector = "blur-aware" if args.blur_aware else args.selector
    info, images = emulate_cycle(seq, args.cycle, args.exposure_ms, cameras=cams, selector=selector, response=response,
                               from_ms=args.from_ms, blur=args.blur, calibration=args.calibration, stamp=args.stamp)
    targets = {
        cam: args.output / f"{cam}_cycle{args.cycle:04d}_{args.exposure_ms:g}ms.png" for cam in images
    }
    if not args.force:
        for path in targets.values():
            if path.exists():
                raise ExposimError(f"{path}: exists; refusing to overwrite (use --force)")
    writer = write_png16 if args.save == "png16" else write_png8
    for cam, path in targets.items():
        data = saved_image(images[cam], args.save, white_level=seq.white_level, black_level=seq.black_level)
        writer(path, data, overwrite=args.force)
        info["cameras"][cam]["output"] = str(path)
    info["save"] = args.save
    if args.json:
        print(strict_json(info, indent=1))
    else:
        print(
            f"cycle {info['cycle']}: target {info['target_ms']:g} ms from bracket {info['bracket_ms']:g} ms "
            f"(ratio {info['ratio']:.4g}, {info['selector']}), valid pixels {100 * info['valid_fraction']:.2f} %, "
            f"blur {info['blur']}"
        )
        for cam, c in info["cameras"].items():
            blur = (f"; blur source {c['source_blur_px']:.2f} px, target {c['target_blur_px']:.2f} px, excess "
                    f"{c['blur_mismatch_px']:+.2f} px" if c.get("blur_mismatch_px") is not None else "")
            if c.get("blur_note"):
                blur = f"; {c['blur_note']}"
            print(f"  {cam:5s} {c['source']} (t = {c['timestamp_ns']} ns) -> {c['output']}{blur}")
    return 0
