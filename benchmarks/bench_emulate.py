"""Emulation speed on full-resolution BorealHDR images, next to PNG decoding.

Usage: python benchmarks/bench_emulate.py [SEQUENCE] [--repeat N]

Prints ms per 1920x1200 image for: PNG decode, emulate() with a cached lookup table,
emulate() including building the table (first use of a ratio), the same with the
validity mask, and the reference implementation's per-pixel interpolation
(np.interp over every pixel), all measured in one run.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from emulator.core.emulate import emulate
from emulator.io.borealhdr import load_sequence, sequence_response
from emulator.io.png import read_png16
from _timing import SAMPLE_SEQ, median_ms

DEFAULT_SEQ = SAMPLE_SEQ



def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequence", nargs="?", type=Path, default=DEFAULT_SEQ)
    ap.add_argument("--repeat", type=int, default=30)
    args = ap.parse_args(argv)

    seq = load_sequence(args.sequence)
    response = sequence_response(seq)
    frame = seq[1].frames["left"][8.0]
    raw = frame.load()
    ratios = iter(np.linspace(0.3, 0.9, 10_000))

    decode = median_ms(lambda: read_png16(frame.path), max(5, args.repeat // 3))
    emulate(raw, 8.0, 5.3, response)  # warm the table and the thread pool
    cached = median_ms(lambda: emulate(raw, 8.0, 5.3, response), args.repeat)
    cold = median_ms(lambda: emulate(raw, 8.0, 8.0 * next(ratios), response), args.repeat)
    masked = median_ms(lambda: emulate(raw, 8.0, 5.3, response, return_mask=True), args.repeat)

    g, dn = response.g, np.arange(response.white_level + 1, dtype=np.float64)

    def per_pixel():  # what the reference code does: interpolate every pixel in float
        h = np.interp(raw.astype(np.float64), dn, g) * (5.3 / 8.0)
        return np.clip(np.rint(np.interp(h, g, dn)), 0, response.white_level).astype(np.uint16)

    ref = median_ms(per_pixel, max(3, args.repeat // 5))
    assert np.array_equal(per_pixel(), emulate(raw, 8.0, 5.3, response))

    h, w = raw.shape
    print(f"image {w}x{h} uint16, {frame.path}")
    print(f"{'PNG decode':38s} {decode:8.2f} ms")
    print(f"{'emulate (cached table)':38s} {cached:8.2f} ms")
    print(f"{'emulate (new ratio: table + gather)':38s} {cold:8.2f} ms")
    print(f"{'emulate + validity mask':38s} {masked:8.2f} ms")
    print(f"{'per-pixel interpolation (reference)':38s} {ref:8.2f} ms   ({ref / cached:.0f}x slower)")


if __name__ == "__main__":
    main()
