"""``exposim info``: describe a recording (cameras, brackets, cycles, partial cycles and gaps)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "info",
        help="describe a recording: cameras, brackets, cycles, partial cycles and gaps",
        description="Describe a BorealHDR-layout recording (cycles are grouped by timestamp).",
    )
    p.add_argument("sequence", type=Path, help="recording folder holding camera_left/ and camera_right/, or a trajectory .zip")
    p.add_argument("--frame-cache", type=Path, default=None, metavar="DIR",
                   help="read decoded frames from this frame cache (made by 'exposim cache SEQ --frame-cache DIR'; "
                        "default: SEQUENCE/.exposim-frames when it exists)")
    p.add_argument("--json", action="store_true", help="print one JSON object (cycles as a list)")
    p.set_defaults(func=_info)


register.order = 10  # place in `exposim --help`


def _info(args) -> int:
    from emulator.io.borealhdr import load_sequence

    seq = load_sequence(args.sequence, frame_cache=args.frame_cache)
    desc = seq.describe()
    if args.json:
        print(json.dumps(desc, indent=1))
        return 0
    print(f"sequence   {seq.path}")
    print(f"cameras    {', '.join(seq.cameras)}")
    print(f"brackets   {', '.join(f'{b:g}' for b in seq.brackets)} ms")
    print(f"levels     black {seq.black_level}, white {seq.white_level}")
    print(f"cycles     {len(seq)} ({len(seq) - len(seq.partial_cycles)} complete, partial: {seq.partial_cycles or 'none'})")
    for c in desc["cycles"]:
        cams = "  ".join(f"{cam}: {len(c.get(cam, {}))}/{len(seq.brackets)}" for cam in seq.cameras)
        print(f"  cycle {c['index']:4d}  t0 {c['timestamp_ns']}  {cams}{'  partial' if c['partial'] else ''}")
    if seq.gaps:
        print("gaps")
        for g in seq.gaps:
            print(f"  {g}")
    return 0
