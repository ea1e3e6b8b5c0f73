"""A closed-loop run written to a run folder: :func:`run_to_folder` (resume, lock).

The loop itself is :mod:`emulator.playback`; the folder's layout, writer and reader are
:mod:`emulator.io.runfolder`; its plot and summaries are :mod:`emulator.report.run`.
``exposim run``, the dataset runner, the demo and the studies all write through here.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from emulator.autoexposure import DEFAULT_RANGE_MS
from emulator.autoexposure.methodset import build_methods, parse_methods
from emulator.dataset import Sequence
from emulator.errors import PlaybackError
from emulator.emulate import check_exposure
from emulator.gray import bayer_to_gray8
from emulator.io.borealhdr import sequence_response
from emulator.io.runfolder import CSV_COLUMNS, CSV_FILE, RUN_FILE, SAVE_MODES, RunWriter, format_row
from emulator.playback import (
    DEFAULT_INITIAL_MS,
    DEFAULT_SELECTOR,
    METHOD_CAMERA,
    MethodStep,
    RunStats,
    _check_range,
    _check_timeout,
    _clamp,
    _noise_spec,
    _resolve_sequence,
    iter_run,
)
from emulator.select import SELECTORS

__all__ = ["run_to_folder", "saved_image", "resolve_noise_model"]


def _canon(value) -> str:
    return json.dumps(value, sort_keys=True, default=str)


def _config_of(run_json: dict) -> dict:
    out = {k: run_json.get(k) for k in ("sequence", "methods", "selector", "initial_ms", "range_ms", "save", "mode",
                                        "options", "response", "method_timeout")}
    out["noise"] = run_json.get("noise") or {"mode": "none"}  # run folders from before --noise: none
    out["blur"] = run_json.get("blur") or {"mode": "none"}  # run folders from before --blur: none
    return out


def _same_file(a, b) -> bool:
    """Two recorded paths (relative ones to the working directory) name one existing file."""
    try:
        return bool(a) and bool(b) and Path(a).is_file() and Path(a).resolve() == Path(b).resolve()
    except OSError:
        return False


def saved_image(image: np.ndarray, save: str, *, white_level: int, black_level: int) -> np.ndarray:
    """What ``--save`` writes of an emulated Bayer image: itself (png16), or 8-bit grey with the
    black level subtracted (png8, :func:`emulator.gray.bayer_to_gray8`). Shared by ``run`` and ``emulate``."""
    if save == "png16":
        return image
    if save == "png8":
        return bayer_to_gray8(image, white_level=white_level, black_level=black_level)
    raise PlaybackError(f"save must be png16 or png8 to save an image, got {save!r}")


def resolve_noise_model(noise: str, noise_model, seq: Sequence, response):
    """The noise model of a run: None for ``noise="none"``; a NoiseModel; a path to a noise-model
    JSON (:func:`emulator.io.noisemodel.read_noise_model`); or, when None, the model the
    recording's ``exposim.json`` carries (synthetic recordings). Returns (model, source)."""
    from emulator.io.noisemodel import noise_model_from_metadata, read_noise_model
    from emulator.noise import NoiseModel

    if noise == "none":
        return None, None
    if isinstance(noise_model, NoiseModel):
        return noise_model, str(noise_model.name)
    if noise_model is not None:
        return read_noise_model(noise_model, response), str(Path(noise_model).resolve())
    meta_path = Path(seq.path) / "exposim.json"
    model = noise_model_from_metadata(seq.metadata, response, source=str(meta_path))
    if model is None:
        raise PlaybackError(
            f'{seq.path}: noise "{noise}" needs a noise model and the recording carries none (no camera in '
            f"{meta_path.name}); pass --noise-model FILE.json (written by `exposim calibrate --noise`)"
        )
    return model, str(meta_path.resolve())


def run_to_folder(
    sequence,
    methods="all",
    out_dir=None,
    *,
    save: str = "none",
    response=None,
    response_path=None,
    initial_ms: float = DEFAULT_INITIAL_MS,
    range_ms=DEFAULT_RANGE_MS,
    selector: str = DEFAULT_SELECTOR,
    mode: str = "paper",
    options: Mapping | None = None,
    jobs: int = 1,
    resume: bool = False,
    progress: Callable[[int, int], None] | None = None,
    command: str | None = None,
    make_report: bool = True,
    noise: str = "none",
    noise_model=None,
    noise_seed: int = 0,
    method_timeout: float | None = None,
    blur: str = "none",
    blur_aware: bool = False,
) -> dict:
    """Run AE methods on a recording and write a run folder (:mod:`emulator.io.runfolder`).

    Refuses an existing, non-empty ``out_dir`` (:class:`OutputExistsError`) unless ``resume``:
    then the configuration comes from ``out_dir/run.json`` (arguments that differ raise
    :class:`PlaybackError`), every method is re-run deterministically from cycle 0, rows
    already in the CSVs are checked against the replay (a mismatch raises) and not written
    again, missing images are written, and the run continues where it stopped.  The folder
    is locked while the run writes it: a second run on it (``resume`` while the first is
    alive) raises :class:`~emulator.errors.RunLockedError`; the lock of a killed run is
    taken over.

    Returns the summary written to ``results.json`` (per-method figures, skipped cycles,
    timing; :func:`emulator.report.run.write_run_report`).  ``progress(done, total)`` is
    called after every cycle.  Every argument is checked before the folder is created.
    ``initial_ms`` outside ``range_ms`` is clamped (``run.json``: ``initial_ms_clamped``).
    ``noise``, ``noise_model`` (a NoiseModel, a noise-model JSON path, or None for the one
    the recording's ``exposim.json`` carries), ``noise_seed``: see :func:`iter_run`; the
    choice is recorded in ``run.json`` (``"noise"``) and a resume must repeat it.
    called after every cycle.  A method that fails (``method_timeout``, a plugin's error or
    bad result; see :func:`iter_run`) keeps the rows before its failure; ``run.json`` and the
    summary record ``method_status`` (name -> ``"ok"`` or ``"failed: <reason> at cycle N"``).
    """
    if out_dir is None:
        raise PlaybackError("out_dir is required")
    out = Path(os.path.abspath(out_dir))  # absolute: a method's os.chdir cannot split the folder
    if save not in SAVE_MODES:
        raise PlaybackError(f"save must be one of {', '.join(SAVE_MODES)}, got {save!r}")
    seq = _resolve_sequence(sequence)
    if response is None:
        response = sequence_response(seq, response_path)
    response_name = str(response_path) if response_path is not None else str(getattr(response, "name", "custom"))
    if Path(response_name).is_file():  # absolute: a resume from another working directory finds it
        response_name = str(Path(response_name).resolve())
    method_specs = parse_methods(methods) if isinstance(methods, str) else list(methods)
    built = build_methods(method_specs, mode=mode, response=response, options=options)
    names = list(built)
    timeout_s = _check_timeout(method_timeout)
    user_options = {k: {kk: vv for kk, vv in v.items()} for k, v in dict(options or {}).items()}
    config = {
        "sequence": str(Path(seq.path).resolve()),
        "methods": names,
        "selector": selector,
        "initial_ms": float(check_exposure(initial_ms, "initial_ms")),
        "range_ms": [float(v) for v in _check_range(range_ms)],
        "save": save,
        "mode": mode,
        "options": user_options,
        "response": response_name,
        "method_timeout": timeout_s,
    }
    if selector not in SELECTORS:
        raise PlaybackError(f"unknown selector {selector!r}; choose one of {', '.join(SELECTORS)}")
    if isinstance(jobs, bool) or not isinstance(jobs, (int, np.integer)) or int(jobs) < 1:
        raise PlaybackError(f"jobs must be an integer >= 1, got {jobs!r}")
    white, black = int(seq.white_level), int(seq.black_level)
    if response.white_level != white or response.black_level != black:
        response = response.with_levels(white_level=white, black_level=black)
    model, model_source = resolve_noise_model(noise, noise_model, seq, response)
    noise_spec = _noise_spec(noise, model, noise_seed, response)
    config["noise"] = ({"mode": "none"} if noise_spec is None else
                       {"mode": noise, "seed": int(noise_seed),
                        "model": {k: v for k, v in model.to_dict().items() if k != "response"}})
    clamped_initial = _clamp(config["initial_ms"], config["range_ms"])
    from emulator.motion import blur_hook

    hook = blur_hook(blur, seq, response, blur_aware=blur_aware)  # None for "none"; blur.csv, run.json "blur"
    config["blur"] = {"mode": "none"} if hook is None else hook.describe()
    if blur_aware and selector != "higher-no-sat":
        raise PlaybackError(f"the blur-aware selection refines selector higher-no-sat, not {selector!r}")

    with RunWriter(out, resume=resume) as writer:
        if resume:
            run_json = writer.run_json
            old = _config_of(run_json)
            diff = [k for k in config if _canon(old.get(k)) != _canon(config[k])
                    and not (k == "response" and _same_file(old.get(k), config[k]))]
            if diff:
                raise PlaybackError(
                    f"{out / RUN_FILE}: --resume with a different configuration ({', '.join(diff)}): recorded "
                    + "; ".join(f"{k}={old.get(k)!r}" for k in diff)
                )
            run_json["resumed"] = run_json.get("resumed", 0) + 1
            run_json.setdefault("resume_commands", []).append(command)
            if writer.lock.stale_owner:
                run_json.setdefault("stale_locks", []).append(writer.lock.stale_owner)
        else:
            from emulator import __version__

            run_json = {
                **config,
                "white_level": white,
                "black_level": black,
                "cameras": list(seq.cameras),
                "brackets_ms": list(seq.brackets),
                "method_camera": METHOD_CAMERA,
                "selector_camera": METHOD_CAMERA,
                "method_options": {n: m.config() if hasattr(m, "config") else {} for n, m in built.items()},
                "method_specs": [s if isinstance(s, str) else n for s, n in zip(method_specs, names)],
                "command": command,
                "version": __version__,
                "jobs": int(jobs),
                "created": writer.lock.owner["started"],
                "n_cycles": len(seq.cycles),
                "status": "running",
                "cycles_done": 0,
                "skipped_cycles": [],
            }
            if model_source is not None:
                run_json["noise_model_file"] = model_source
            if clamped_initial != config["initial_ms"]:
                run_json["initial_ms_clamped"] = clamped_initial
                run_json.setdefault("warnings", []).append(
                    f"initial_ms {config['initial_ms']:g} is outside range_ms {config['range_ms']}; "
                    f"clamped to {clamped_initial:g} ms")
        run_json["jobs"] = int(jobs)
        writer.start(run_json, names, seq.cameras, save, cycles=[c.index for c in seq.cycles])  # resume: validated

        def write_images(st: MethodStep) -> None:
            if save == "none":
                return
            rec = writer.recorded(st.method, st.cycle)
            for cam, img in (("left", st.left), ("right", st.right)):
                if img is None:
                    continue
                if rec is not None and writer.image_path(st.method, cam, st.timestamp_ns).exists():
                    continue
                data = saved_image(img, save, white_level=white, black_level=black)
                writer.write_image(st.method, cam, st.timestamp_ns, data)

        stats = RunStats()
        skipped: list[dict] = []
        method_status = {name: "ok" for name in names}
        done = 0
        status = "failed"
        try:
            gen = iter_run(seq, list(built.values()), initial_ms=initial_ms, range_ms=range_ms, selector=selector,
                           response=response, jobs=jobs, emulate_right=save != "none", on_step=write_images,
                           stats=stats, noise=noise, noise_model=model, noise_seed=noise_seed,
                           method_timeout=timeout_s, blur=hook)
            for cs in gen:
                method_status.update(cs.failed)
                if cs.skipped:
                    skipped.append({"cycle": cs.cycle, "reason": cs.skipped, "missing": cs.missing})
                for name in names:
                    st = cs.steps.get(name)
                    if st is None:
                        continue
                    row = format_row(st)
                    rec = writer.recorded(name, st.cycle)
                    if rec is not None:
                        if rec != row:
                            raise PlaybackError(
                                f"{out / name / CSV_FILE}: resume replay of cycle {st.cycle} differs from the recorded "
                                f"row ({','.join(rec[:len(CSV_COLUMNS)])} recorded, "
                                f"{','.join(row[:len(CSV_COLUMNS)])} replayed); the folder was written by another "
                                "configuration or version"
                            )
                    else:
                        writer.append_row(name, row)
                done += 1
                writer.update(cycles_done=done, skipped_cycles=skipped, method_status=method_status)
                if progress is not None:
                    progress(done, len(seq.cycles))
            status = "complete"
        except KeyboardInterrupt:
            status = "interrupted"
            raise
        except BaseException as exc:
            run_json["error"] = f"{type(exc).__name__}: {exc}"
            raise
        finally:
            if status == "complete":
                run_json.pop("error", None)
            writer.update(status=status, cycles_done=done, skipped_cycles=skipped, timing=stats.as_dict(),
                          method_status=method_status)
        if hook is not None:
            hook.write_table(out)
        if save != "none":
            writer.write_times(names)
        _write_method_output(out, names)  # what methods printed (isolated from the run's stdout)
    if make_report:
        from emulator.report.run import write_run_report

        return write_run_report(out)
    from emulator.report.run import summarise_run

    return summarise_run(out)


#: File in a method's folder holding what the method printed (stdout and stderr, in order).
METHOD_OUTPUT_FILE = "output.txt"


def _write_method_output(out: Path, names) -> None:
    """Write each method's captured output (:mod:`emulator.autoexposure.isolation`) to its folder."""
    from emulator.autoexposure.isolation import captured_output
    from emulator.io.files import atomic_write_bytes

    for name in names:
        text, total = captured_output(name, clear=True)
        if total:
            note = "" if total == len(text) else f"\n[... {total - len(text)} more characters not kept]\n"
            atomic_write_bytes(out / name / METHOD_OUTPUT_FILE, (text + note).encode(), overwrite=True)
