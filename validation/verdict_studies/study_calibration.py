"""The plasmode calibration of a finished live study, from its folder's ``walks.csv``:
``exposim validate study-calibration OUT`` prints it (and writes it to a new ``--json`` file) without
touching the folder (:mod:`validation.verdicts.plasmode`; ``validate live`` writes the same into the folder).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from emulator.errors import ExposimError
from emulator.io.files import read_results, write_results
from validation.live.config import METRICS
from validation.live.evidence import walk_labels
from validation.live.table_check import read_folder_table
from validation.protocol import Study
from validation.verdicts.plasmode import NOISY_FACTOR, STUDIES, calibrate, calibration_markdown

__all__ = ["STUDY", "check_options", "emit", "add_arguments", "run"]


def emit(text: str, json_path, data: dict) -> int:
    """Print ``text`` and write ``data`` to the new file ``json_path`` (when given); returns the exit code 0."""
    print(text, end="")
    if json_path is not None:
        write_results(json_path, data, overwrite=False)
    return 0


def check_options(studies: int, json_path) -> None:
    """Refuse (:class:`~emulator.errors.ExposimError`) fewer than one study and a ``--json`` file that exists."""
    if studies < 1:
        raise ExposimError(f"--studies must be >= 1, got {studies}")
    if json_path is not None and json_path.exists():
        raise ExposimError(f"{json_path}: exists; give a new file name (results are never overwritten)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``exposim validate study-calibration``."""
    p.add_argument("folder", type=Path, help="a live study folder with walks.csv")
    p.add_argument("--studies", type=int, default=STUDIES, help=f"plasmode studies per emulator and size "
                   f"(default {STUDIES})")
    p.add_argument("--seed", type=int, help="seed of the draws (default: the study's, from its results.json)")
    p.add_argument("--noisy-factor", type=float, default=NOISY_FACTOR,
                   help=f"the noisier method's injected noise, times its own residual SD (default {NOISY_FACTOR:g})")
    p.add_argument("--json", type=Path, help="also write the numbers to this new JSON file")


def run(args: argparse.Namespace) -> int:
    """The calibration of a live study folder's ``walks.csv``, printed (and written to ``--json``), without touching
    the folder; a bad folder or option: one line on stderr, exit code 1."""
    try:
        check_options(args.studies, args.json)
        walks, methods, tables = read_folder_table(args.folder)
        seed = args.seed
        if seed is None:
            res = args.folder / "results.json"
            seed = int(read_results(res).get("config", {}).get("seed", 0)) if res.is_file() else 0
        t0 = time.perf_counter()
        cal = calibrate(tables, walk_labels(walks)[1], methods, metrics=list(METRICS), n_studies=args.studies,
                        seed=seed, noisy_factor=args.noisy_factor)
        wall = time.perf_counter() - t0
    except (ExposimError, OSError, ValueError) as exc:
        print(f"study_calibration: {exc}", file=sys.stderr)
        return 1
    return emit(calibration_markdown(cal) + f"{len(walks)} walks, {args.studies} plasmode studies per emulator and "
                f"size: {wall:.1f} s\n", args.json, cal)


#: ``exposim validate study-calibration``.
STUDY = Study("study-calibration", "how often the live-versus-emulated verdict rule is right on a finished live "
              "study's own walks (plasmode studies drawn from its walks.csv; the folder is not touched)",
              add_arguments, run)
