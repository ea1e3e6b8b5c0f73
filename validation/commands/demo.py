"""``exposim demo``: the main job end to end on the embedded synthetic default."""

from __future__ import annotations

import argparse
from pathlib import Path

from emulator.commands.progress import add_json, add_quiet, bars_enabled, print_json

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
    import sys

    from tqdm import tqdm

    from scenes.commands.synth import stop_between_images
    from validation.demo import run_demo

    bars: dict[str, tqdm] = {}

    def progress(stage: str, done: int, total: int) -> None:
        check()  # Ctrl-C: stop cleanly between images (rc 130)
        bar = bars.get(stage)
        if bar is None:
            for old in bars.values():
                old.close()
            bar = bars[stage] = tqdm(total=total, desc=stage, file=sys.stderr, disable=not bars_enabled(args.quiet))
        bar.total = total
        bar.n = done
        bar.refresh()

    try:
        with stop_between_images("exposim demo") as check:
            result = run_demo(args.output, quick=args.quick, progress=progress)
    finally:
        for bar in bars.values():
            bar.close()
    if args.json:
        from emulator.io.files import read_results

        print_json(read_results(result["output"]))
        return 0
    print(result["report"])
    how = "reused from an earlier demo" if result["dataset_reused"] else "synthesised now, kept for the next demo"
    print(f"\nexposim demo: recording {result['dataset']} ({how})")
    print(f"exposim demo: wrote {result['output']} in {result['total_s']:.0f} s (report.md, report.html, results.json, figures)")
    return 0
