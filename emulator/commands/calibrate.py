"""``exposim calibrate``: recover the inverse camera response (pcalib file + plot), or the noise model.

::

    exposim calibrate STACK -o response.txt                 # static stack, TUM layout (ALS)
    exposim calibrate --from-recording SEQ -o response.txt  # a recording's own sweeps
    exposim calibrate --noise SEQ -o noise.json             # noise model from the sweeps

The response plot goes beside the output as ``<output stem>.png``.  ``--noise`` estimates
the conversion gain, read noise and full well in situ (photon transfer from triples of
consecutive brackets, :func:`emulator.noise.estimate_noise_model`) through the
recording's response (:func:`emulator.io.borealhdr.sequence_response`) and writes the
JSON of :mod:`emulator.io.noisemodel` that ``exposim run --noise consistent`` reads.
Existing outputs are kept unless ``--force``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from emulator.commands.progress import add_quiet
from emulator.commands.body import CommandBody

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "calibrate",
        help="recover the inverse camera response f^-1 (stack or recording), or the noise model (--noise)",
        description=(
            "Recover the inverse camera response f^-1 and write it as a pcalib file (256 samples "
            "over DN 0..4095, g(4095) = 255) plus a plot <output stem>.png. From a static-scene "
            "stack in the TUM layout (STACK/images/*.png, STACK/times.txt: '<name> <timestamp_s> "
            "<exposure_ms>') by alternating least squares (Engel et al. 2016), or with "
            "--from-recording from a bracketed recording's own sweeps by histogram matching "
            "(comparametric, Grossberg and Nayar 2003). With --noise SEQ, estimate the noise model "
            "(conversion gain, read noise, full well, with standard errors) in situ from the recording's "
            "bracket triples and write it as JSON (for noise-consistent emulation)."
        ),
    )
    p.add_argument("stack", nargs="?", type=Path, help="stack folder (TUM layout: images/ and times.txt)")
    p.add_argument("--from-recording", type=Path, metavar="SEQ",
                   help="a BorealHDR-layout recording instead of a stack")
    p.add_argument("--noise", type=Path, metavar="SEQ",
                   help="estimate the noise model of a BorealHDR-layout recording (writes JSON)")
    p.add_argument("-o", "--output", type=Path, required=True,
                   help="file to write: pcalib (e.g. response.txt), or with --noise a JSON noise model")
    p.add_argument("--force", action="store_true", help="overwrite the output and its plot")
    p.add_argument("--knots", type=int, default=None,
                   help="knots of the piecewise-linear response (stack: 256, recording: 128)")
    p.add_argument("--smoothness", type=float, default=None, help="weight of the curvature prior (default 0.1)")
    p.add_argument("--margin", type=int, default=8, help="DN at each end treated as clipped (default 8)")
    p.add_argument("--pixels", type=int, default=65536, help="stack: random pixels used (default 65536)")
    p.add_argument("--white-level", type=int, default=None,
                   help="stack: white level (default: the stack's exposim.json, else BorealHDR's 4094)")
    p.add_argument("--black-level", type=int, default=None, help="stack: black level (default exposim.json or 0)")
    p.add_argument("--no-static-check", action="store_true",
                   help="stack: do not refuse a fit whose residual is far above the noise")
    p.add_argument("--camera", choices=("left", "right", "both"), default="both",
                   help="recording / --noise: cameras to use")
    p.add_argument("--max-groups", type=int, default=None,
                   help="--noise: at most this many bracket triples, spread over the recording (default all)")
    p.add_argument("--stride", type=int, default=4,
                   help="recording: read every n-th pixel of each Bayer plane (default 4)")
    p.add_argument("--no-score", action="store_true", help="recording: skip the cross-bracket score")
    p.add_argument("--seed", type=int, default=0, help="random seed (pixel subset, dither)")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    add_quiet(p)
    p.set_defaults(func=CommandBody("emulator.commands.calibrate_body:calibrate"))


register.order = 50  # place in `exposim --help`
