"""Run the published BorealHDR AE loop itself and store every method's exposure sequence.

    python scripts/published_sequences.py --borealhdr-repo CLONE --name upstream-complete \
        --recording DIR [--replay-from DIR --pattern 0,1,2,...] [--kim-seeds 0,1,6] -o tests/validation/data/published_sequences.json

CLONE is a checkout of github.com/norlab-ulaval/BorealHDR (its ``scripts/`` and
``calibration_files/pcalib_inside1.txt`` are used; none of its code is part of exposim).  The
loop is ``emulate()`` of its ``scripts/emulator_threads.py`` without display, saving and
threads: each method runs alone, left camera, ``Image_Emulator(..., "radiance",
"closer_least_sat", True)``, ``exposure_time_init`` 4.0 ms.  Kim's restarts draw from NumPy's
global random state: it is seeded with ``np.random.seed(s)`` before the method is built, once
per seed in ``--kim-seeds``.  With ``--replay-from`` the recording is a replay built by
``validation.published.replay_layout`` (links under DIR) from that camera folder.

The entry ``--name`` is added to the output file with the dependency versions and the clone's
commit; an existing entry of that name is refused unless ``--replace``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import warnings
from importlib import metadata
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from validation.published import REF_BRACKETS_MS, REF_INITIAL_MS, REF_METHODS, columns, replay_layout  # noqa: E402

DEPENDENCIES = ("numpy", "scipy", "scikit-learn", "opencv-python-headless", "scikit-image", "pandas")


def _versions() -> dict:
    out = {"python": sys.version.split()[0]}
    for name in DEPENDENCIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def run_published(clone: Path, camera_dir: Path, ref_name: str, seed: int | None) -> dict:
    """One method through the published loop; returns exposures (initial first) and source brackets."""
    sys.path.insert(0, str(clone / "scripts"))
    from classes.class_auto_exposure_methods import Metric  # the published code, from the clone
    from classes.class_image_emulator import Image_Emulator
    from sklearn.exceptions import ConvergenceWarning

    warnings.filterwarnings("ignore", category=ConvergenceWarning)
    if seed is not None:
        np.random.seed(seed)
    metric, percent = ref_name.split("-")[0], int(ref_name.split("-")[-1])
    emulator = Image_Emulator(camera_dir, "radiance", "closer_least_sat", True)
    method = Metric(metric, percent)
    cols = columns(camera_dir)
    t, exposures, sources = REF_INITIAL_MS, [REF_INITIAL_MS], []
    for k in range(len(cols) - 1):
        emulator.update_image_list([p.name for p in cols[k]])
        image = emulator.emulate_image(t)
        sources.append(float(image["exposure_time"]))
        t = float(method.find_next_exposure_time(image["emulated_img"], t))
        exposures.append(t)
    return {"exposures_ms": exposures, "source_ms": sources}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--borealhdr-repo", type=Path, required=True, help="checkout of norlab-ulaval/BorealHDR")
    p.add_argument("--recording", type=Path, help="recording folder (BorealHDR layout); its camera_left is used")
    p.add_argument("--replay-from", type=Path, help="camera folder to build a replay from (with --pattern)")
    p.add_argument("--pattern", help="replay: comma-separated source columns, e.g. 0,1,2,1,0")
    p.add_argument("--replay-dir", type=Path, help="replay: where the links are made (must not exist)")
    p.add_argument("--name", required=True, help="entry name in the output file")
    p.add_argument("--kim-seeds", default="0", help="np.random.seed values for kim (default 0)")
    p.add_argument("--methods", default=",".join(REF_METHODS), help="published method names")
    p.add_argument("-o", "--output", type=Path, required=True)
    p.add_argument("--replace", action="store_true", help="replace an existing entry of this name")
    p.add_argument("--published-commit", help="the clone's commit, where it is not a git work tree")
    a = p.parse_args(argv)
    clone = a.borealhdr_repo.resolve()
    if a.replay_from is not None:
        if not (a.pattern and a.replay_dir):
            p.error("--replay-from needs --pattern and --replay-dir")
        if a.replay_dir.exists():
            p.error(f"{a.replay_dir} exists")
        pattern = [int(x) for x in a.pattern.split(",")]
        camera = replay_layout(a.replay_from, a.replay_dir / "camera_left", pattern)
        source = {"replay_of": str(a.replay_from), "pattern": pattern}
    elif a.recording is not None:
        camera, source = a.recording / "camera_left", {"recording": a.recording.name}
    else:
        p.error("give --recording or --replay-from")
    store = json.loads(a.output.read_text()) if a.output.exists() else {"entries": {}}
    if a.name in store["entries"] and not a.replace:
        p.error(f"{a.output}: entry {a.name!r} exists (--replace to replace it)")
    try:
        commit = subprocess.run(["git", "-C", str(clone), "rev-parse", "HEAD"], capture_output=True, text=True,
                                check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit = None
    commit = a.published_commit or commit
    entry = {"source": source, "published_commit": commit, "dependencies": _versions(),
             "columns": [[str(Path(q).relative_to(camera)) for q in col] for col in columns(camera)]
             if a.replay_from is None else None,
             "brackets_ms": list(REF_BRACKETS_MS), "methods": {}}
    for ref_name in a.methods.split(","):
        seeds = [int(s) for s in a.kim_seeds.split(",")] if ref_name.startswith("kim") else [None]
        for seed in seeds:
            key = ref_name if seed is None else f"{ref_name}@seed{seed}"
            entry["methods"][key] = run_published(clone, camera, ref_name, seed)
            print(key, [round(x, 4) for x in entry["methods"][key]["exposures_ms"]], file=sys.stderr)
    store["entries"][a.name] = entry
    a.output.parent.mkdir(parents=True, exist_ok=True)
    a.output.write_text(json.dumps(store, indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
