"""Noise-consistent emulation speed on full-resolution BorealHDR frames, against the plain table path.

Usage: python benchmarks/bench_emulate_noise.py [SEQUENCE] [--repeat N] [--gain G] [--read-noise R]

Prints ms per 1920x1200 frame, all measured in one run (so the ratios hold under load):
plain emulate() (cached table), plain with the validity mask, ``noise="consistent"`` when
darkening (noise added at every pixel; cached tables, then a new ratio each call: tables
built), when brightening (nothing to add: tables only), and the excess map alone.  The
noise model defaults to the synthetic BorealHDR camera's figures (full well 10500 e-,
read noise 2.4 e-) on the sequence's response.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from emulator.core.emulate import emulate
from emulator.io.borealhdr import load_sequence, sequence_response
from emulator.noise import NoiseModel
from _timing import median_ms

DEFAULT_SEQ = Path(__file__).resolve().parents[2] / "shared/data/borealhdr_sample/backpack_2023-09-25-15-05-03"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequence", nargs="?", type=Path, default=DEFAULT_SEQ)
    ap.add_argument("--repeat", type=int, default=30)
    ap.add_argument("--full-well", type=float, default=10500.0, help="electrons at the white level")
    ap.add_argument("--read-noise", type=float, default=2.4, help="electrons rms")
    args = ap.parse_args(argv)

    seq = load_sequence(args.sequence)
    response = sequence_response(seq)
    model = NoiseModel.from_full_well(response, args.full_well, args.read_noise, name="bench")
    raw = seq[1].frames["left"][8.0].load()
    rng = np.random.default_rng(0)
    new_ratios = iter(np.linspace(0.3, 0.9, 10_000))

    def consistent(target, r=rng):
        return emulate(raw, 8.0, target, response, noise="consistent", noise_model=model, rng=r)

    consistent(5.3)  # warm tables, quantiser, normal table and thread pool
    emulate(raw, 8.0, 5.3, response)
    rows = [
        ("plain (cached table)", median_ms(lambda: emulate(raw, 8.0, 5.3, response), args.repeat)),
        ("plain + validity mask", median_ms(lambda: emulate(raw, 8.0, 5.3, response, return_mask=True),
                                             args.repeat)),
        ("consistent, darkening 8 -> 5.3 ms", median_ms(lambda: consistent(5.3), args.repeat)),
        ("consistent, darkening, new ratio", median_ms(lambda: consistent(8.0 * next(new_ratios)), args.repeat)),
        ("consistent, brightening 8 -> 11 ms", median_ms(lambda: consistent(11.0), args.repeat)),
        ("consistent, int seed (new Generator)", median_ms(lambda: consistent(5.3, 7), args.repeat)),
        ("plain + excess map", median_ms(lambda: emulate(raw, 8.0, 5.3, response, noise_model=model,
                                                          return_excess=True), args.repeat)),
    ]
    base = rows[0][1]
    h, w = raw.shape
    print(f"image {w}x{h} uint16, {model}")
    for name, ms in rows:
        print(f"{name:40s} {ms:8.2f} ms  {ms / base:6.1f}x plain")


if __name__ == "__main__":
    main()
