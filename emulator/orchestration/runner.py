"""A closed-loop run written to a run folder: :func:`run_to_folder` (resume, lock).

The loop itself is :mod:`emulator.playback`, configured by one
:class:`~emulator.playback.RunConfig`; the folder's layout, writer and reader are
:mod:`emulator.io.runfolder`; its plot and summaries are :mod:`emulator.report.run`.
``exposim run``, the dataset runner, the demo and the studies all write through here.

The folder is written from memory: ``run.json`` at the start, every
:data:`RUN_JSON_EVERY` cycles and at the end; the summary and ``times.txt`` come from the
rows the run made (never read back); each emulated image is encoded once per (cycle,
camera, target) and shared by the methods with the same target (hard link, else a copy
of the bytes).
"""

from __future__ import annotations

import contextlib
import os
import threading
import warnings
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import numpy as np

from emulator.autoexposure.methodset import parse_methods
from emulator.errors import PlaybackError
from emulator.core.gray import bayer_to_gray8
from emulator.io.runfolder import (
    CSV_COLUMNS,
    CSV_FILE,
    RUN_FILE,
    RunWriter,
    format_row,
    tables_from_rows,
    EXTRA_COLUMNS,
)
import emulator.numpy_dispatch as numpy_dispatch
from emulator.playback import METHOD_CAMERA, MethodStep, RunConfig, RunStats, closed_loop, prepare_run, \
    resolve_sequence
from emulator.io.runwatch import watch_run
from emulator.playback.shmblock import SharedMemoryWarning, shortage_note
from emulator.playback.worker_child import plain  # inline methods' config() as JSON, as a worker sends it
from emulator.autoexposure.isolation import captured_output
from emulator.io.files import atomic_write_bytes
from emulator.io.runcsv import read_csv_rows
from emulator.report.run import summarise_run, write_run_report
from emulator.version import __version__

__all__ = ["run_to_folder", "write_run", "saved_image", "RUN_JSON_EVERY"]

#: ``run.json`` is rewritten every this many cycles (and at the start and the end).
RUN_JSON_EVERY = 10


def saved_image(image: np.ndarray, save: str, *, white_level: int, black_level: int) -> np.ndarray:
    """What ``--save`` writes of an emulated Bayer image: itself (png16), or 8-bit grey with the
    black level subtracted (png8, :func:`emulator.core.gray.bayer_to_gray8`). Shared by ``run`` and ``emulate``."""
    if save == "png16":
        return image
    if save == "png8":
        return bayer_to_gray8(image, white_level=white_level, black_level=black_level)
    raise PlaybackError(f"save must be png16 or png8 to save an image, got {save!r}")


class _ImageSaver:
    """Writes each step's images in the background, one encoding per (cycle, camera, target) (thread-safe).

    The first step of a (cycle, camera, target) submits its image to a small pool of encoder
    threads (PNG encoding releases the GIL, so it overlaps the loop); the other methods with
    that target get the same bytes (:meth:`RunWriter.share_image`) when it is written.  At
    most ``max_pending`` writes wait at a time (their images stay in memory); :meth:`close`
    waits for all of them and raises the first error.
    """

    def __init__(self, writer: RunWriter, save: str, white: int, black: int, *, threads: int = 2,
                 max_pending: int = 32, keep_cycles: int = 2) -> None:
        self.writer, self.save, self.white, self.black = writer, save, white, black
        self._keep_cycles = int(keep_cycles)  # cycles whose first writes are kept for other methods to share
        self._lock = threading.Lock()
        self._done: dict = {}
        self._pending: deque = deque()
        self._errors: list[BaseException] = []
        self._max_pending = int(max_pending)
        self._pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="exposim-save") \
            if save != "none" else None

    def __call__(self, st: MethodStep) -> None:
        if self._pool is None:
            return
        resumed = self.writer.recorded(st.method, st.cycle) is not None
        for cam, img in (("left", st.left), ("right", st.right)):
            if img is None:
                continue
            key = (st.cycle, cam, st.target_ms)
            with self._lock:
                first = self._done.get(key)
                if first is None:
                    self._done[key] = self._pool.submit(self._write, img, st.method, cam, st.timestamp_ns, resumed)
                    self._pending.append(self._done[key])
                    continue
            first.add_done_callback(lambda f, m=st.method, c=cam, t=st.timestamp_ns:
                                    self._share(f, m, c, t, resumed))
        self._forget(st.cycle)
        while True:
            with self._lock:
                oldest = self._pending.popleft() if len(self._pending) > self._max_pending else None
            if oldest is None:
                break
            oldest.result()

    def _write(self, img, method: str, cam: str, timestamp_ns: int, resumed: bool) -> Path:
        dest = self.writer.image_path(method, cam, timestamp_ns)
        if resumed and dest.exists():
            return dest  # a resumed run's image, already there
        data = saved_image(img, self.save, white_level=self.white, black_level=self.black)
        return self.writer.write_image(method, cam, timestamp_ns, data)

    def _share(self, first: Future, method: str, cam: str, timestamp_ns: int, resumed: bool) -> None:
        try:
            source = first.result()
            dest = self.writer.image_path(method, cam, timestamp_ns)
            if source != dest and not (resumed and dest.exists()):
                self.writer.share_image(source, method, cam, timestamp_ns)
        except BaseException as exc:  # raised again by close()
            with self._lock:
                self._errors.append(exc)

    def _forget(self, cycle: int) -> None:
        with self._lock:
            for key in [k for k in self._done if k[0] <= cycle - self._keep_cycles]:
                self._done.pop(key, None)

    def close(self) -> None:
        """Wait for every write; raise the first error."""
        if self._pool is None:
            return
        try:
            for fut in list(self._pending):
                fut.result()
        finally:
            self._pool.shutdown(wait=True)  # the sharing callbacks have run
        if self._errors:
            raise self._errors[0]


def _new_run_json(config: RunConfig, identity: dict, seq, built, method_specs, model, model_source, command,
                  created, blur_hook=None) -> dict:
    run_json = {
        **identity,
        **config.to_json(model, blur_hook),
        "white_level": int(seq.white_level),
        "black_level": int(seq.black_level),
        "cameras": list(seq.cameras),
        "brackets_ms": list(seq.brackets),
        "method_camera": METHOD_CAMERA,
        "selector_camera": METHOD_CAMERA,
        "method_options": {n: plain(m.config()) if hasattr(m, "config") else {} for n, m in built.items()},
        "method_specs": [s if isinstance(s, str) else n for s, n in zip(method_specs, built)],
        "command": command,
        "version": __version__,
        "created": created,
        "n_cycles": len(seq.cycles),
        "status": "running",
        "cycles_done": 0,
        "skipped_cycles": [],
    }
    if model_source is not None:
        run_json["noise_model_file"] = model_source
    if config.start_ms != config.initial_ms:
        run_json["initial_ms_clamped"] = config.start_ms
        run_json.setdefault("warnings", []).append(
            f"initial_ms {config.initial_ms:g} is outside range_ms {list(config.range_ms)}; "
            f"clamped to {config.start_ms:g} ms")
    return run_json


def run_to_folder(
    sequence,
    methods="all",
    out_dir=None,
    config: RunConfig | None = None,
    *,
    response=None,
    resume: bool = False,
    resume_given=None,
    progress: Callable[[int, int], None] | None = None,
    command: str | None = None,
    make_report: bool = True,
    run_json_extra: dict | None = None,
    **settings,
) -> dict:
    """Run AE methods on a recording and write a run folder (:mod:`emulator.io.runfolder`).

    ``config`` (a :class:`~emulator.playback.RunConfig`; keyword ``settings`` override its
    fields, e.g. ``save="png16"``, ``initial_ms=...``, ``method_timeout_s=...``) is checked
    before the folder is created.  Refuses an existing, non-empty ``out_dir``
    (:class:`OutputExistsError`) unless ``resume``: then the recorded configuration wins
    and what is given must equal it (:meth:`RunConfig.resumed`; ``resume_given`` names the
    fields given explicitly, default all), every method is re-run deterministically from
    cycle 0, rows already in the CSVs are checked against the replay (a mismatch raises)
    and not written again, missing images are written, and the run continues where it
    stopped.  The folder is locked while the run writes it
    (:class:`~emulator.errors.RunLockedError` for a second writer; the lock of a killed run
    is taken over).

    Returns the summary written to ``results.json`` (per-method figures, skipped cycles,
    timing with the steady-state rate apart from start-up).  ``progress(done, total)`` is
    called after every cycle.  A method that fails (its time limit, a plugin's error or bad
    result) keeps the rows before its failure; ``run.json`` and the summary record
    ``method_status`` (name -> ``"ok"`` or ``"failed: <reason> at cycle N"``).
    ``run_json_extra``: more keys for a new folder's ``run.json``.
    """
    run_json, tables = write_run(sequence, methods, out_dir, config, response=response, resume=resume,
                                 resume_given=resume_given, progress=progress, command=command,
                                 run_json_extra=run_json_extra, **settings)
    if make_report:
        return write_run_report(out_dir, run_json, tables)
    return summarise_run(out_dir, run_json, tables)


def write_run(sequence, methods, out_dir, config: RunConfig | None = None, *, response=None, resume: bool = False,
              resume_given=None, progress=None, command=None, run_json_extra=None, **settings):
    """The run of :func:`run_to_folder` without its report: returns ``(run_json, tables)`` from memory
    (the final ``run.json`` and each method's columns, :func:`emulator.io.runfolder.tables_from_rows`)."""
    if out_dir is None:
        raise PlaybackError("out_dir is required")
    out = Path(os.path.abspath(out_dir))  # absolute: a method's os.chdir cannot split the folder
    cfg = RunConfig.from_kwargs(config, **settings)
    seq = resolve_sequence(sequence, imu_warning=cfg.blur != "none")  # the IMU is read only for blur
    method_specs = parse_methods(methods) if isinstance(methods, str) else list(methods)
    stats = RunStats()
    prep = prepare_run(seq, method_specs, cfg, response, stats=stats)  # the provider of cfg.rate
    seq, response, built, provider, model, model_source, hook = prep
    names = list(built)
    identity = {"sequence": str(Path(seq.path).resolve()), "methods": names, "response": cfg.response_name(response)}
    shm_note = _reserve_image_blocks(seq, built)  # before the first cycle: a full /dev/shm is one line now

    with RunWriter(out, resume=resume, png_level=cfg.png_level) as writer, watch_run(out):  # a crash: run.json failed
        if resume:
            run_json = writer.run_json
            cfg.check_resume(run_json, resume_given, where=str(out / RUN_FILE), noise_model=model, blur_hook=hook,
                             identity=identity)
            run_json["resumed"] = run_json.get("resumed", 0) + 1
            run_json.setdefault("resume_commands", []).append(command)
            if writer.lock.stale_owner:
                run_json.setdefault("stale_locks", []).append(writer.lock.stale_owner)
        else:
            run_json = _new_run_json(cfg, identity, seq, built, method_specs, model, model_source, command,
                                     writer.lock.owner["started"], hook)
            run_json.update(run_json_extra or {})
            run_json.update(provider.run_json())  # native rate: window, warp, latency, benchmarked frames
        if shm_note is not None:
            run_json["shared_memory_pipes"], run_json["shared_memory"] = shm_note
        else:  # a resumed run whose /dev/shm has room now: no earlier shortage carried over
            run_json.pop("shared_memory_pipes", None)
            run_json.pop("shared_memory", None)
        run_json.update(cfg.per_run_json())  # how the methods ran (results do not depend on it): also on resume
        if cfg.workers == "process":  # the same bytes either way; recorded so that a reader knows
            run_json["worker_numpy"] = numpy_dispatch.describe()
        partial = [{"cycle": c.index, "missing": c.missing_by_camera(seq.cameras)} for c in seq.cycles
                   if c.missing_by_camera(seq.cameras)]
        if partial:  # flagged in the report (emulator.report.run); absent when every cycle is complete
            run_json["partial_cycles"] = partial
        ticks = provider.tick_indices  # cycles, or frames at native rate
        writer.start(run_json, names, seq.cameras, cfg.save, cycles=ticks, columns=provider.columns)  # resume: validated
        rows = _loop_into(writer, provider, built, cfg, stats, out, progress, len(ticks))
        if hook is not None:
            hook.write_table(out)  # blur.csv: each emulated image's blur
        if cfg.save != "none":
            writer.write_times(names, rows)
        _write_method_output(out, names)  # what methods printed (isolated from the run's stdout)
    return writer.run_json, tables_from_rows(rows)


def _loop_into(writer: RunWriter, provider, built: dict, cfg: RunConfig, stats: RunStats, out: Path,
               progress, n_cycles: int) -> dict[str, list[list[str]]]:
    """Run the loop, appending each step's row (checked against a resumed folder's); returns the rows."""
    names = list(built)
    run_json = writer.run_json
    # methods may be up to the provider's ticks_ahead cycles apart (emulator.playback.loop): a cycle's
    # first writes are kept until every method is past it, so each image is encoded once
    saver = _ImageSaver(writer, cfg.save, int(run_json["white_level"]), int(run_json["black_level"]),
                        keep_cycles=int(getattr(provider, "ticks_ahead", 0)) + 3)
    rows: dict[str, list[list[str]]] = {name: [] for name in names}
    skipped: list[dict] = []
    method_status = {name: "ok" for name in names}
    done = 0
    status = "failed"
    try:
        for cs in closed_loop(provider, built, cfg, want_right=cfg.save != "none", on_step=saver, stats=stats):
            method_status.update(cs.failed)
            if cs.skipped:
                skipped.append({"cycle": cs.cycle, "reason": cs.skipped, "missing": cs.missing})
            for name in names:
                st = cs.steps.get(name)
                if st is None:
                    continue
                row = format_row(st)
                rec = writer.recorded(name, st.cycle)
                if rec is None:
                    writer.append_row(name, row)
                elif rec != row:
                    raise PlaybackError(_resume_mismatch(out / name / CSV_FILE, st.cycle, rec, row))
                rows[name].append(row)
            done += 1
            short = {n: m.shm_shortage for n, m in built.items() if getattr(m, "shm_shortage", None)}
            if len(short) > len(run_json.get("shared_memory_pipes", ())):  # a larger image later: said at once
                run_json["shared_memory_pipes"] = list(short)
                run_json["shared_memory"] = shortage_note(short, len(names))
                if run_json["shared_memory"]:
                    warnings.warn(run_json["shared_memory"], SharedMemoryWarning, stacklevel=2)
                writer.update()
            if done % RUN_JSON_EVERY == 0:
                writer.update(cycles_done=done, skipped_cycles=skipped, method_status=method_status)
            if progress is not None:
                progress(done, n_cycles)
        saver.close()  # every image written before the run is complete
        status = "complete"
    except KeyboardInterrupt:
        status = "interrupted"
        raise
    except BaseException as exc:
        run_json["error"] = f"{type(exc).__name__}: {exc}"
        raise
    finally:
        if status != "complete":
            with contextlib.suppress(BaseException):  # the loop's own error is the one raised
                saver.close()
        if status == "complete":
            run_json.pop("error", None)
            changed = _tables_changed(out, rows)
            if changed:  # a process running as the user (a plugin's) wrote into the folder: said, not hidden
                run_json["tables_changed"] = changed
                warnings.warn(f"{out}: the table of {', '.join(changed)} differs from the rows this run wrote: a "
                              f"process besides the run (a plugin's?) wrote into the run folder; its results are "
                              f"not this run's", TablesChangedWarning, stacklevel=2)
        provider.finish_run_json(run_json)  # native rate: the frames the gyro did not cover
        writer.update(status=status, cycles_done=done, skipped_cycles=skipped, timing=stats.as_dict(),
                      method_status=method_status)
    return rows


class TablesChangedWarning(UserWarning):
    """A method's ``exposures.csv`` differs at the end of a run from the rows the run wrote into it."""


def _tables_changed(out: Path, rows: dict) -> list[str]:
    """The methods whose ``exposures.csv`` no longer holds exactly the rows of ``rows`` (what the run wrote)."""
    changed = []
    for name, written in rows.items():
        try:
            if read_csv_rows(out / name / CSV_FILE) != [list(r) for r in written]:
                changed.append(name)
        except (OSError, ValueError, PlaybackError):  # unreadable now: changed as well
            changed.append(name)
    return changed


def _reserve_image_blocks(seq, built: dict) -> tuple[list[str], str] | None:
    """Reserve every worker's image block for the recording's frame size (its first left frame, decoded)
    before the first cycle; where ``/dev/shm`` has no room for some, one :class:`SharedMemoryWarning`
    and ``(methods, note)`` for ``run.json``, else None."""
    workers = {n: m for n, m in built.items() if callable(getattr(m, "reserve", None))}
    frames = next((c.frames.get(METHOD_CAMERA) for c in seq.cycles if c.frames.get(METHOD_CAMERA)), None)
    if not workers or not frames:
        return None
    try:
        nbytes = next(iter(frames.values())).load().nbytes
    except Exception:  # noqa: BLE001 - a frame that cannot be read now: the loop names it where it reads it
        return None
    short = {}
    for name, worker in workers.items():
        if not worker.reserve(nbytes):
            short[name] = worker.shm_shortage
    if not short:
        return None
    note = shortage_note(short, len(built))
    warnings.warn(note, SharedMemoryWarning, stacklevel=3)
    return list(short), note


def _resume_mismatch(path: Path, cycle: int, recorded: list[str], replayed: list[str]) -> str:
    """One line naming the columns where a resumed folder's row and the replay differ."""
    names = list(CSV_COLUMNS) + list(EXTRA_COLUMNS)
    n = max(len(recorded), len(replayed))
    cell = lambda row, i: row[i] if i < len(row) else "(none)"  # noqa: E731
    diff = [i for i in range(n) if cell(recorded, i) != cell(replayed, i)]
    shown = "; ".join(f"{names[i] if i < len(names) else f'column {i + 1}'} {cell(recorded, i)} recorded, "
                      f"{cell(replayed, i)} replayed" for i in diff[:3])
    more = f" and {len(diff) - 3} more column(s)" if len(diff) > 3 else ""
    return (f"{path}: resume replay of cycle {cycle} differs from the recorded row ({shown}{more}); the table was "
            "edited, or the folder was written by another configuration or version of exposim")


#: File in a method's folder holding what the method printed (stdout and stderr, in order).
METHOD_OUTPUT_FILE = "output.txt"


def _write_method_output(out: Path, names) -> None:
    """Write each method's captured output (:mod:`emulator.autoexposure.isolation`) to its folder."""
    for name in names:
        text, total = captured_output(name, clear=True)
        if total:
            note = "" if total == len(text) else f"\n[... {total - len(text)} more characters not kept]\n"
            atomic_write_bytes(out / name / METHOD_OUTPUT_FILE, (text + note).encode(), overwrite=True)
