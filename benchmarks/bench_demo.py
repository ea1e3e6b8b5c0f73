"""Wall time of ``exposim demo``: cold (an empty render cache) and warm (the cache it filled).

Each run is a child process (``python -m emulator.commands.cli demo``), as a user starts it, with
``EXPOSIM_CACHE`` set to a new temporary folder; the load average is printed before and after
every run, because on a shared machine it moves the figure more than anything else.  The
Dr.Jit kernel cache (``~/.drjit``) is the user's unless ``--fresh-home`` gives the runs an empty
home folder (a machine that never rendered).

Usage::

    python benchmarks/bench_demo.py                 # one cold and one warm run
    python benchmarks/bench_demo.py --repeat 2 --fresh-home
    python benchmarks/bench_demo.py --quick         # the test configuration
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def run_once(folder: Path, env: dict, quick: bool, label: str) -> float:
    """Run the demo into ``folder/label``; print and return its wall time in seconds."""
    cmd = [sys.executable, "-m", "emulator.commands.cli", "demo", "-q", "-o", str(folder / label)] + (["--quick"] if quick else [])
    before = _load()
    t0 = time.perf_counter()
    subprocess.run(cmd, cwd=folder, env=env, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    print(f"{label}: {wall:.1f} s wall (load average before {before}, after {_load()})", flush=True)
    return wall


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeat", type=int, default=1, help="cold/warm pairs, each with a new empty cache")
    p.add_argument("--quick", action="store_true", help="the smallest configuration")
    p.add_argument("--fresh-home", action="store_true", help="an empty home folder (no Dr.Jit kernel cache)")
    args = p.parse_args(argv)
    if args.repeat < 1:
        p.error(f"--repeat must be at least 1, got {args.repeat}")
    for i in range(args.repeat):
        with tempfile.TemporaryDirectory(prefix="exposim-bench-demo-") as tmp:
            folder = Path(tmp)
            env = {**os.environ, "EXPOSIM_CACHE": str(folder / "cache"),
                   "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
            if args.fresh_home:
                (folder / "home").mkdir()
                env["HOME"] = str(folder / "home")
            run_once(folder, env, args.quick, f"cold-{i + 1}")
            run_once(folder, env, args.quick, f"warm-{i + 1}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
