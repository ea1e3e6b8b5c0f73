"""Per-frame arithmetic of shim, zhang and kim: pre-change (tests/emulator/autoexposure/ae_reference.py) vs now; not a test.

Usage: python benchmarks/bench_ae_kernels.py [SEQUENCE] [--repeat N]

On one full-resolution gray image of the sample (cycle 1, 8 ms bracket, each mode's gray
conversion), the process CPU time of each kernel, old and new calls interleaved so that
load from other processes spreads over both; prints the least and the median of
``--repeat`` calls in ms, and a plain ``np.sort`` of as many float64 values for scale
(Zhang's borealhdr derivative sorts every pixel's d).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests" / "emulator" / "autoexposure"))

import ae_reference as ref  # noqa: E402
from emulator.autoexposure import Zhang2017  # noqa: E402
from emulator.autoexposure import kim as kim_mod  # noqa: E402
from emulator.autoexposure import shim as shim_mod  # noqa: E402
from emulator.autoexposure.base import REF_BAYER_CODE, RGGB_BAYER_CODE  # noqa: E402
from emulator.io.borealhdr import load_sequence, sequence_response  # noqa: E402
from _timing import SAMPLE_SEQ  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequence", nargs="?", type=Path, default=SAMPLE_SEQ)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)
    seq = load_sequence(args.sequence, frame_cache=False)
    response = sequence_response(seq)
    raw = seq[1].frames["left"][8.0].load()
    y_ref, y_paper = cv2.cvtColor(raw, REF_BAYER_CODE), cv2.cvtColor(raw, RGGB_BAYER_CODE)
    z_ref = Zhang2017(mode="borealhdr", response=response, range_ms=None)
    z_paper = Zhang2017(mode="paper", response=response, range_ms=None)
    values = np.random.default_rng(0).standard_normal(y_ref.size)
    kernels = {
        ("shim", "borealhdr"): (lambda: ref.gamma_metrics_ref(y_ref), lambda: shim_mod.gamma_metrics_ref(y_ref)),
        ("shim", "paper"): (lambda: ref.gamma_metrics_paper(y_paper), lambda: shim_mod.gamma_metrics_paper(y_paper)),
        ("zhang", "borealhdr"): (lambda: ref._ref_derivative(z_ref, y_ref, 8.0),
                                 lambda: z_ref._ref_derivative(y_ref, 8.0)),
        ("zhang", "paper"): (lambda: ref._paper_derivative(z_paper, y_paper, 8.0),
                             lambda: z_paper._paper_derivative(y_paper, 8.0)),
        ("kim", "borealhdr"): (lambda: ref.metric_ref(y_ref), lambda: kim_mod.metric_ref(y_ref)),
        ("kim", "paper"): (lambda: ref.metric_paper(y_paper), lambda: kim_mod.metric_paper(y_paper)),
        ("np.sort", "-"): (lambda: np.sort(values), lambda: np.sort(values)),
    }
    times = {k: ([], []) for k in kernels}
    for _ in range(max(1, args.repeat)):
        for key, fns in kernels.items():
            for fn, out in zip(fns, times[key]):
                t0 = time.process_time()
                fn()
                out.append(1e3 * (time.process_time() - t0))
    print(f"{raw.shape[1]}x{raw.shape[0]} gray image; CPU ms per call, least / median of {args.repeat}")
    print(f"{'kernel':8s} {'mode':9s} {'pre-change':>17s} {'now':>17s} {'ratio':>6s}")
    for (name, mode), (old, new) in times.items():
        print(f"{name:8s} {mode:9s} {min(old):8.1f} / {statistics.median(old):6.1f} "
              f"{min(new):8.1f} / {statistics.median(new):6.1f} {min(old) / min(new):6.2f}")


if __name__ == "__main__":
    main()
