"""``exposim demo``: the main job end to end on the embedded synthetic default."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from tqdm import tqdm

from emulator.commands.progress import add_json, add_quiet, bars_enabled, print_json
from emulator.io.files import read_results
from scenes.commands.synth import stop_between_images
from validation.demo import run_demo

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="run the main job end to end on the embedded synthetic default",
        description=(
            "Synthesise a small scene, emulate it, run the AE methods in closed loop and "
            "write a short report into a new output folder. The synthetic recording is kept in "
            "the render cache ($EXPOSIM_CACHE, default ~/.cache/exposim/renders, under datasets/) "
            "and reused by the next demo with the same configuration; the output folder holds "
            "the run results only."
        ),
    )
    p.add_argument("-o", "--output", type=Path, default=None, help="output folder (default: a new exposim-demo-N)")
    p.add_argument("--quick", action="store_true", help="smallest configuration (for tests)")
    add_quiet(p, "no progress bars")
    add_json(p, "print the demo's results.json to stdout instead of its report")
    p.set_defaults(func=_demo, extras=("synth",))


register.order = 90  # place in `exposim --help`


def _demo(args) -> int:
    bars: dict[str, tqdm] = {}
    on_terminal = bars_enabled(args.quiet)
    t0 = time.perf_counter()

    def progress(stage: str, done: int, total: int) -> None:
        check()  # Ctrl-C: stop cleanly between images (rc 130)
        bar = bars.get(stage)
        if bar is None:
            for old in bars.values():
                old.close()
            bar = bars[stage] = tqdm(total=total, desc=stage, file=sys.stderr, disable=not on_terminal)
            if not on_terminal and not args.quiet:  # a log: one line as each stage starts
                print(f"exposim demo [{time.perf_counter() - t0:.0f} s]: {stage}", file=sys.stderr, flush=True)
        bar.total = total
        bar.n = done
        bar.refresh()

    try:
        with stop_between_images("exposim demo") as check:
            result = run_demo(args.output, quick=args.quick, progress=progress)
    finally:
        for bar in bars.values():
            bar.close()
    results = read_results(result["output"])
    if args.json:
        print_json(results)
        return 0
    print("\n".join(summary_lines(results, result)))
    return 0


def summary_lines(results: dict, result: dict) -> list[str]:
    """The few lines ``exposim demo`` ends with: what ran, headline figures, the time and the report."""
    cfg, emu = results["config"], results["emulation"]
    feats = results["features"].get("methods", {})
    vo = results["vo"].get("methods", {})
    methods = list(results["run"].get("methods", {}))
    lines = [f"exposim demo: {cfg['scene']}, {cfg['n_cycles']} bracket cycles at {cfg['width']}x{cfg['height']} px, "
             f"{len(methods)} AE methods in closed loop ({', '.join(methods)}), feature and stereo-VO benchmarks"]
    if emu.get("median_rmse_percent") is not None:
        lines.append(f"  emulation against exact ground truth: median RMSE {emu['median_rmse_percent']:.2f} % of "
                     f"the range, max {emu['max_rmse_percent']:.2f} %")
    ranked = sorted((m for m in feats if feats[m].get("median_matches") is not None),
                    key=lambda m: -feats[m]["median_matches"])
    if ranked:
        lines.append("  median SIFT matches between consecutive frames: " + ", ".join(f"{m} {feats[m]['median_matches']:.0f}" for m in ranked))
    failed = {m: len(v.get("failures", [])) for m, v in vo.items()}
    frames = sum(v.get("n_frames", 0) for v in vo.values())
    lines.append(f"  stereo VO: {sum(failed.values())} of {frames} frames failed over {len(vo)} methods"
                 + ("" if not any(failed.values()) else
                    " (" + ", ".join(f"{m} {n}" for m, n in failed.items() if n) + ")"))
    how = "reused from an earlier demo" if result["dataset_reused"] else "synthesised now, kept for the next demo"
    lines.append(f"  recording: {result['dataset']} ({how})")
    lines.append(f"exposim demo: done in {result['total_s']:.0f} s; report: {Path(result['output']) / 'report.html'} "
                 "(also report.md, results.json, figures)")
    return lines
