"""Whole-dataset runs: every sequence under a BorealHDR root, in units of (sequence, method group).

Layout of a dataset run folder ``OUT``::

    OUT/dataset.json                 the configuration (sequences, methods, groups, run options)
    OUT/<sequence>/<group>/          one run folder per (sequence, method group), exactly the
                                     folder ``exposim run SEQ --methods <group's methods>`` writes
    OUT/results.json, report.md,     the dataset summary: per-sequence and per-method tables,
    OUT/methods.png                  throughput and its projection to the full BorealHDR dataset

A sequence is a folder holding ``camera_left/`` or ``camera_right/``, or a trajectory
``.zip`` (:class:`emulator.io.borealhdr.ZipSource`); its name is the folder name or the
zip's stem.  Methods are split into groups of ``group_size`` (default: all methods in one
group, one unit per sequence: the methods of a group share decoded images, which on the
shared sample makes a cycle 2.6x cheaper than seven one-method units; ``group_size=1`` gives
the finest parallelism).  The methods of a group finish together, so a finished
(sequence, method) is never recomputed.  A method's closed loop does not depend on the other methods of its group,
so the CSVs are the same bytes for any grouping and any scheduler.

Each unit runs :func:`run_unit`: it writes its run folder under a staging name
(``.<group>.staging-<token>``) and renames it into place only when complete, so a unit that
is killed mid-way (a worker that dies) leaves no partial folder under the final name, and a
retry starts from scratch; a unit whose folder already exists is not recomputed (resume,
or a duplicate attempt).  :func:`run_dataset` plans the units, runs them serially or on
Dask (:mod:`emulator.orchestration.distributed`) and writes the summary, with the run's throughput
(:mod:`emulator.orchestration.throughput`).  Nothing here prints.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import time
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

from emulator.autoexposure.methodset import parse_methods
from emulator.autoexposure.registry import is_import_path, plugin_from_path
from emulator.errors import ExposimError, OutputExistsError
from emulator.io.borealhdr import is_recording, load_sequence
from emulator.io.files import RESULTS_FILE, read_metadata, read_results, write_metadata
from emulator.io.runfolder import RUN_FILE, RunLock, read_run_json
from emulator.orchestration.distributed import check_scheduler, is_client, open_client, run_tasks
from emulator.orchestration.runner import write_run
from emulator.orchestration.throughput import BOREALHDR_FULL, project_throughput, throughput
from emulator.playback import RunConfig
from emulator.report.dataset import write_dataset_report
from emulator.report.run import write_run_report

__all__ = [
    "DATASET_FILE",
    "BOREALHDR_FULL",
    "Unit",
    "discover_sequences",
    "plan_groups",
    "plan_units",
    "run_unit",
    "run_dataset",
    "count_images",
    "project_throughput",
    "DatasetRunError",
    "remove_stale_staging",
    "throughput",
    "to_plain",
]

#: The configuration file of a dataset run folder.
DATASET_FILE = "dataset.json"
_STAGING = ".staging-"


class DatasetRunError(ExposimError):
    """A dataset run that cannot start or resume (bad selection, different configuration)."""


@dataclass(frozen=True)
class Unit:
    """One unit of work: a method group on one sequence, written to ``out/sequence/group``."""

    sequence: str
    path: str
    methods: tuple[str, ...]
    group: str

    @property
    def key(self) -> str:
        return f"{self.sequence}/{self.group}"


# ---------------------------------------------------------------------------- planning
def discover_sequences(root: str | os.PathLike, selection: str = "all") -> dict[str, Path]:
    """Sequences under ``root`` (name -> folder or zip), sorted by name; ``root`` itself if it is one.

    ``selection`` is ``all`` or comma-separated names (a zip's name is its stem); an
    unknown name raises :class:`DatasetRunError` listing the names found.
    """
    root = Path(root)
    if not root.exists():
        raise FileNotFoundError(f"{root}: dataset folder not found")
    found: dict[str, Path] = {}
    if is_recording(root):
        found[root.stem if root.is_file() else root.name] = root
    else:
        for child in sorted(root.iterdir()):
            if child.name.startswith(".") or not is_recording(child):
                continue
            name = child.stem if child.is_file() else child.name
            if name in found:
                raise DatasetRunError(f"{root}: sequence {name!r} is there twice ({found[name].name} and {child.name})")
            found[name] = child
    if not found:
        raise DatasetRunError(f"{root}: no sequence (a folder with camera_left/ or camera_right/, or a .zip)")
    if selection is None or selection.strip() == "all":
        return found
    wanted = [s.strip() for s in selection.split(",") if s.strip()]
    unknown = [s for s in wanted if s not in found]
    if unknown or not wanted:
        raise DatasetRunError(f"{root}: no sequence named {', '.join(unknown) or repr(selection)}; "
                              f"found: {', '.join(found)}")
    return {name: found[name] for name in dict.fromkeys(wanted)}


def plan_groups(methods: list[str], group_size: int = 1) -> list[tuple[str, ...]]:
    """Methods in order, cut into groups of ``group_size`` (the last may be smaller)."""
    if int(group_size) < 1:
        raise DatasetRunError(f"group size must be >= 1, got {group_size!r}")
    n = int(group_size)
    return [tuple(methods[i:i + n]) for i in range(0, len(methods), n)]


#: Longest group folder name, bytes: file names stop at 255 bytes, and a unit's staging
#: folder adds a dot, a marker and a random suffix to it.
MAX_GROUP_NAME_BYTES = 200


def _group_name(methods: tuple[str, ...]) -> str:
    """``"m1+m2+..."``; a name over :data:`MAX_GROUP_NAME_BYTES` is cut and made unique by a hash
    of the whole (the unit's record keeps the full method list)."""
    name = "+".join(methods)
    raw = name.encode()
    if len(raw) <= MAX_GROUP_NAME_BYTES:
        return name
    digest = hashlib.sha256(raw).hexdigest()[:16]
    head = raw[: MAX_GROUP_NAME_BYTES - len(digest) - 1].decode(errors="ignore")
    return f"{head}~{digest}"


def plan_units(sequences: Mapping[str, Path], methods: list[str], group_size: int = 1) -> list[Unit]:
    """Every (sequence, method group), sequence-major."""
    groups = plan_groups(methods, group_size)
    return [Unit(name, str(Path(path).resolve()), g, _group_name(g)) for name, path in sequences.items() for g in groups]


# ---------------------------------------------------------------------------- one unit
def count_images(sequence) -> int:
    """Images of a recording as BorealHDR counts them: one per shot (a stereo pair once)."""
    return sum(max((len(f) for f in c.frames.values()), default=0) for c in sequence.cycles)


def _unit_record(unit: Unit, folder: Path, reused: bool) -> dict:
    """The record of a unit whose folder exists (a resumed or duplicate unit): read from it."""
    info = read_run_json(folder)
    if not (folder / RESULTS_FILE).is_file():  # killed between the rename and the report
        write_run_report(folder)
    return _record(unit, folder, reused, info, read_results(folder), None)


def _record(unit: Unit, folder: Path, reused: bool, info: dict, results: dict, wall_s: float | None) -> dict:
    timing = info.get("timing") or {}
    return {
        "sequence": unit.sequence,
        "group": unit.group,
        "methods": list(unit.methods),
        "folder": str(folder),
        "reused": reused,
        "status": info.get("status"),
        "n_cycles": info.get("n_cycles"),
        "cycles_done": info.get("cycles_done"),
        "n_images": info.get("n_images"),
        "n_brackets": info.get("n_brackets"),
        "loop_s": timing.get("wall_s"),
        "unit_s": wall_s,
        "results": results.get("methods", {}),
    }


def _is_complete(folder: Path) -> bool:
    return (folder / RUN_FILE).is_file() and read_run_json(folder).get("status") == "complete"


def run_unit(unit: Unit, out_dir: str | os.PathLike, config) -> dict:
    """Run one (sequence, method group) into ``out_dir/sequence/group`` (idempotent, atomic).

    ``config`` is the :class:`~emulator.playback.RunConfig` of every unit.  An existing
    complete folder is returned as is (``reused``); otherwise the run goes to a staging
    folder beside it that is renamed into place when complete; if another attempt renamed
    its folder first, this one's is discarded.  Returns the unit's record (per-method
    results, cycles, images, loop seconds), built from what the run returned (nothing is
    read back).
    """
    out_dir = Path(out_dir)
    final = out_dir / unit.sequence / unit.group
    if _is_complete(final):
        return _unit_record(unit, final, reused=True)
    if final.exists():
        raise DatasetRunError(f"{final}: exists but is not a complete run; remove it to recompute")
    final.parent.mkdir(parents=True, exist_ok=True)
    staging = final.parent / f".{unit.group}{_STAGING}{uuid.uuid4().hex[:12]}"
    t0 = time.perf_counter()
    seq = load_sequence(unit.path, imu_warning=config.blur != "none")  # the IMU is read only for blur
    extra = {"n_images": count_images(seq), "n_brackets": len(seq.brackets), "dataset_unit": unit.key}
    try:
        # the closed loop runs the methods under one BLAS thread (emulator.pools): the same
        # arithmetic in this process and on any worker
        run_json, tables = write_run(seq, list(unit.methods), staging, config, run_json_extra=extra,
                                     command=f"exposim run (dataset unit {unit.key})")
        try:
            os.rename(staging, final)
        except OSError:
            if not _is_complete(final):
                raise
            shutil.rmtree(staging, ignore_errors=True)  # another attempt finished first: keep its folder
            return _unit_record(unit, final, reused=True)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    summary = write_run_report(final, run_json, tables)
    return _record(unit, final, False, run_json, summary, time.perf_counter() - t0)


def remove_stale_staging(out_dir: str | os.PathLike) -> list[Path]:
    """Remove staging folders left by killed units (only names :func:`run_unit` makes)."""
    removed = []
    for seq_dir in sorted(p for p in Path(out_dir).iterdir() if p.is_dir()):
        for p in sorted(seq_dir.iterdir()):
            if p.is_dir() and p.name.startswith(".") and _STAGING in p.name:
                shutil.rmtree(p, ignore_errors=True)
                removed.append(p)
    return removed


# ---------------------------------------------------------------------------- the run
def _config(root, sequences, methods, group_size, config) -> dict:
    run = {k: v for k, v in config.to_json().items() if k != "jobs"}  # results do not depend on jobs
    run["response_path"] = config.response_path
    run["noise_model"] = config.noise_model if isinstance(config.noise_model, str) else None
    return {
        "root": str(Path(root).resolve()),
        "sequences": {name: str(Path(p).resolve()) for name, p in sequences.items()},
        "methods": list(methods),
        "group_size": int(group_size),
        "config": run,
    }


def run_dataset(
    root: str | os.PathLike,
    out_dir: str | os.PathLike,
    config=None,
    *,
    sequences: str = "all",
    methods="all",
    group_size: int | None = None,
    scheduler="serial",
    scheduler_file: str | os.PathLike | None = None,
    n_workers: int | None = None,
    retries: int = 2,
    resume: bool = False,
    progress: Callable[[int, int], None] | None = None,
    **settings,
) -> dict:
    """Run methods on every selected sequence under ``root`` into ``out_dir``; returns the summary.

    ``config``: the :class:`~emulator.playback.RunConfig` of every unit (keyword
    ``settings`` override its fields, e.g. ``save="png16"``, ``noise="consistent"``,
    ``method_timeout_s=1``).  ``scheduler``: ``serial`` (in this process), ``threads``
    (``n_workers`` threads of this process), ``local`` (a Dask ``LocalCluster`` of
    ``n_workers`` processes, default sized to the machine), ``tcp://HOST:PORT`` or
    ``tls://HOST:PORT`` (an existing Dask cluster that sees the same paths), or an open
    :class:`distributed.Client` (used, not closed); ``scheduler_file`` instead names a
    Dask scheduler file (see :mod:`emulator.orchestration.distributed`).  Refuses an existing ``out_dir``
    that holds a dataset run unless ``resume`` (then the configuration must be the same;
    complete units are kept, others computed).  Every path runs the units through
    :func:`emulator.orchestration.distributed.run_tasks`: a unit that raises any exception becomes an
    error row (Dask retries it ``retries`` times first), the others are kept, and the
    bytes written are the same on every path.
    ``progress(done, total)`` after each unit.
    """
    out = Path(os.path.abspath(out_dir))  # absolute: a plugin's os.chdir cannot move the output
    cfg = RunConfig.from_kwargs(config, **settings)
    if scheduler_file is not None and scheduler in ("serial", None):
        scheduler = "file"
    if scheduler not in ("file", "threads"):
        check_scheduler(scheduler)
    scheduler_name = (f"client {scheduler.scheduler.address}" if is_client(scheduler) else
                      f"file {scheduler_file}" if scheduler == "file" else str(scheduler))
    found = discover_sequences(root, sequences)
    names = parse_methods(methods) if isinstance(methods, str) else list(methods)
    group_size = len(names) if group_size is None else int(group_size)
    config_json = _config(root, found, names, group_size, cfg)
    units = plan_units(found, names, group_size)
    cfg_path = out / DATASET_FILE
    _check_output(out, config_json, resume)

    in_process = scheduler in ("serial", "threads")
    ctx = contextlib.nullcontext() if in_process else open_client(
        scheduler, scheduler_file=None if scheduler_file is None else str(scheduler_file), n_workers=n_workers,
        retries=retries)
    out.mkdir(parents=True, exist_ok=True)
    # one process per dataset folder: a concurrent --resume is refused and never removes a live run's staging
    with RunLock.acquire(out), ctx as client:  # a scheduler that cannot be reached fails before anything is written
        if cfg_path.is_file():
            remove_stale_staging(out)
        else:
            write_metadata(cfg_path, config_json)
        if progress is not None:
            progress(0, len(units))
        t0 = time.perf_counter()
        outcomes = run_tasks(run_unit, [(u, str(out), cfg) for u in units], client=client,
                             threads=(n_workers or 2) if scheduler == "threads" else 1, retries=retries,
                             progress=progress, keys=[u.key for u in units])
        remove_stale_staging(out)  # attempts of units that were killed and ran again (under the lock)
    wall_s = time.perf_counter() - t0
    summary = _summary(config_json["root"], found, names, group_size, scheduler_name, outcomes, wall_s)
    return write_dataset_report(out, summary)


def _check_output(out: Path, config_json: Mapping, resume: bool) -> None:
    """Refuse an output folder a dataset run cannot start (or resume) in: one that holds a dataset run
    without ``resume`` or with another configuration, a non-empty folder, a resume with nothing to resume."""
    cfg_path = out / DATASET_FILE
    if cfg_path.is_file():
        if not resume:
            raise OutputExistsError(f"{out}: holds a dataset run; use --resume to continue it or another -o")
        old = read_metadata(cfg_path, DatasetRunError)
        diff = [k for k in config_json if old.get(k) != to_plain(config_json[k])]
        if diff:
            raise DatasetRunError(f"{cfg_path}: --resume with a different configuration ({', '.join(diff)})")
    else:
        if out.exists() and any(out.iterdir()):
            raise OutputExistsError(f"{out}: exists and is not empty; refusing to overwrite")
        if resume:
            raise DatasetRunError(f"{cfg_path}: no dataset run to resume")


def _summary(root: str, found: Mapping, names: list, group_size: int, scheduler_name: str, outcomes,
             wall_s: float) -> dict:
    """The dataset summary (``results.json``) from the units' outcomes: per-sequence results, errors,
    throughput and the methods that failed everywhere."""
    records = [o.result for o in outcomes if o.error is None]
    errors = [{"unit": o.key, "error": o.error} for o in outcomes if o.error is not None]
    run_names = _run_names(names)
    summary = {
        "root": root,
        "sequences": list(found),
        "methods": run_names,
        "method_specs": {n: spec for spec, n in zip(names, run_names) if n != spec},
        "groups": [list(g) for g in plan_groups(names, group_size)],
        "scheduler": scheduler_name,
        "units": [{k: v for k, v in r.items() if k != "results"} for r in records],
        "errors": errors,
        "per_sequence": {name: {} for name in found},
        "throughput": throughput(records, wall_s, len(plan_groups(names, group_size))),
    }
    for r in records:
        summary["per_sequence"][r["sequence"]].update(r["results"])
    summary["failed_methods"] = _failed_everywhere(summary["per_sequence"], run_names)
    return summary


def _run_names(specs) -> list[str]:
    """The name each method runs under (an import path ``pkg.mod:Class`` -> its plugin name), so
    that the summary finds its results, which the units record under that name."""
    return [plugin_from_path(s).name if isinstance(s, str) and is_import_path(s) else s for s in specs]


def _failed_everywhere(per_sequence: Mapping, names) -> dict[str, str]:
    """Methods that failed on every sequence they ran on: name -> the first reason."""
    out = {}
    for name in names:
        statuses = [per[name].get("status", "ok") for per in per_sequence.values() if name in per]
        if statuses and all(str(st).startswith("failed") for st in statuses):
            out[name] = statuses[0]
    return out


def to_plain(value):
    """``value`` as it reads back from JSON (tuples -> lists), for comparing configurations."""
    return json.loads(json.dumps(value, default=str))

