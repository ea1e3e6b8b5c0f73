"""Throughput of a dataset run (:mod:`emulator.orchestration.datasetrun`): what it measured and its
projection to the full BorealHDR dataset (:data:`BOREALHDR_FULL`).

:func:`throughput` reads the units' records (closed-loop seconds, cycles, images);
:func:`project_throughput` turns the cost of one cycle into the wall time of the whole dataset
on a number of workers.  Pure arithmetic: nothing here reads or writes a file.
"""

from __future__ import annotations

from collections.abc import Mapping

__all__ = ["BOREALHDR_FULL", "project_throughput", "throughput"]

#: The full BorealHDR dataset as published: trajectories, images (one per shot of a sweep,
#: a stereo pair counted once: 6 per cycle at the recorder's 3.66 cycles/s) and duration.
BOREALHDR_FULL = {"trajectories": 55, "images": 393_238, "duration_s": 5 * 3600.0}


def project_throughput(seconds_per_cycle: float, images_per_cycle: float, n_workers: int, *,
                       n_units_per_trajectory: int = 1, dataset: Mapping = BOREALHDR_FULL) -> dict:
    """Projected wall time of a dataset run from the measured cost of one cycle.

    ``seconds_per_cycle`` is the worker-seconds one cycle costs with every method (the sum
    over the method groups); the dataset has ``images / images_per_cycle`` cycles.  Units
    are (trajectory, group), so at most ``trajectories * n_units_per_trajectory`` workers
    are busy: ``wall = cycles * seconds_per_cycle / min(n_workers, units)`` (units taken as
    equal; a lower bound when they are not).  Real-time factor: dataset duration / wall.
    """
    if not (seconds_per_cycle > 0 and images_per_cycle > 0 and int(n_workers) >= 1):
        raise ValueError("seconds_per_cycle and images_per_cycle must be > 0 and n_workers >= 1")
    cycles = dataset["images"] / images_per_cycle
    units = int(dataset["trajectories"]) * int(n_units_per_trajectory)
    busy = min(int(n_workers), units)
    wall = cycles * seconds_per_cycle / busy
    return {
        "n_workers": int(n_workers),
        "busy_workers": busy,
        "dataset_cycles": cycles,
        "dataset_images": int(dataset["images"]),
        "worker_hours": cycles * seconds_per_cycle / 3600.0,
        "wall_hours": wall / 3600.0,
        "cycles_per_s": cycles / wall,
        "images_per_s": dataset["images"] / wall,
        "real_time_factor": dataset["duration_s"] / wall,
    }


def throughput(records: list[dict], wall_s: float, n_groups: int, workers: list[int] = (1, 2, 8, 16, 55)) -> dict:
    """Measured throughput of a dataset run and its projection to the full BorealHDR dataset.

    Cost: the summed closed-loop seconds of every unit (``run.json`` timing, reused units
    included) per cycle of their sequences; ``wall_s`` is this invocation's elapsed time
    (units computed now only).
    """
    per_seq: dict[str, dict] = {}
    for r in records:
        s = per_seq.setdefault(r["sequence"], {"cycles": r["n_cycles"] or 0, "images": r["n_images"] or 0,
                                               "loop_s": 0.0})
        s["loop_s"] += r["loop_s"] or 0.0
    cycles = sum(s["cycles"] for s in per_seq.values())
    images = sum(s["images"] for s in per_seq.values())
    loop_s = sum(s["loop_s"] for s in per_seq.values())
    computed = [r for r in records if not r["reused"]]
    c_cycles = sum(r["n_cycles"] or 0 for r in computed) / max(n_groups, 1)
    c_images = sum(r["n_images"] or 0 for r in computed) / max(n_groups, 1)
    out = {
        "cycles": cycles,
        "images": images,
        "worker_s": loop_s,
        "seconds_per_cycle": loop_s / cycles if cycles else None,
        "cycles_per_s_one_worker": cycles / loop_s if loop_s > 0 else None,
        "images_per_s_one_worker": images / loop_s if loop_s > 0 else None,
        "wall_s": wall_s,
        "units_computed": len(computed),
        "cycles_per_s_wall": c_cycles / wall_s if computed and wall_s > 0 else None,
        "images_per_s_wall": c_images / wall_s if computed and wall_s > 0 else None,
        "per_sequence": {name: {**s, "cycles_per_s": s["cycles"] / s["loop_s"] if s["loop_s"] > 0 else None,
                                "images_per_s": s["images"] / s["loop_s"] if s["loop_s"] > 0 else None}
                         for name, s in per_seq.items()},
        "projection": [],
    }
    # images per full cycle: the brackets of a sweep (partial cycles of a short sample would
    # otherwise inflate the dataset's cycle count); the measured ratio when unknown
    per_cycle = max((r.get("n_brackets") or 0 for r in records), default=0) or (images / cycles if cycles else 0)
    out["images_per_cycle"] = per_cycle
    if cycles and per_cycle and loop_s > 0:
        out["projection"] = [project_throughput(loop_s / cycles, per_cycle, n, n_units_per_trajectory=n_groups)
                             for n in workers]
    return out
