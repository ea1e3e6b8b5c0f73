"""Scoring a response: on a recording (cross-bracket emulation error) and against a known true response.

**Scoring a response on a recording** (:func:`cross_bracket_error`): emulate each bracket
from its neighbour in the same sweep (both directions) and compare quantiles 1..99 % of
the emulated and the real pixel values (RMSE in % of the DN range).

:func:`response_error` compares a recovered g with the true one (synthetic stacks).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence as SequenceType

import numpy as np

from emulator.calibration.result import Progress, planes_of, sweep_neighbours
from emulator.errors import CalibrationError
from emulator.io.pcalib import PCALIB_TOP_VALUE
from emulator.core.response import CameraResponse
from emulator.core.dataset import Sequence
from emulator.core.emulate import emulate
from emulator.io.borealhdr import load_sequence

__all__ = ["CrossBracketError", "cross_bracket_error", "response_error", "DEFAULT_QUANTILES"]

#: Quantile levels of the cross-bracket score: 1 %, 2 %, ... 99 %.
DEFAULT_QUANTILES = np.arange(1, 100) / 100.0


@dataclass
class CrossBracketError:
    """Cross-bracket distribution error of a response on a recording.

    ``pairs`` holds one dict per (cycle, camera, source, target): ``rmse_pct`` is the RMSE
    between quantiles of the emulated and the real target bracket, in % of the DN range.
    """

    pairs: list[dict]
    median_pct: float
    mean_pct: float
    response_name: str
    settings: dict

    def to_dict(self) -> dict:
        return {
            "response": self.response_name,
            "median_pct": self.median_pct,
            "mean_pct": self.mean_pct,
            "n_pairs": len(self.pairs),
            "settings": self.settings,
            "pairs": self.pairs,
        }


def cross_bracket_error(
    sequence,
    response: CameraResponse,
    *,
    cameras: SequenceType[str] | None = None,
    stride: int = 4,
    quantiles: np.ndarray | None = None,
    max_ratio: float = 2.0,
    progress: Progress = None,
) -> CrossBracketError:
    """Score a response on a recording by emulating brackets from their sweep neighbours.

    For every cycle, camera and pair of consecutive brackets ``a < b`` of that sweep with
    ``b / a <= max_ratio``, emulate b from a and a from b; compare the quantiles
    (``quantiles``, default 1 %, 2 % ... 99 %) of the emulated and the real pixel values
    and take the RMSE in % of the DN range (white - black).  Images are read every
    ``stride``-th pixel of each Bayer plane (all four planes pooled).  The response is
    clipped to the recording's levels.  Motion between the brackets (~46 ms) barely changes
    the distributions, so this needs no alignment.
    """
    seq = sequence if isinstance(sequence, Sequence) else load_sequence(sequence)
    qs = DEFAULT_QUANTILES if quantiles is None else np.asarray(quantiles, float)
    resp = response
    if resp.white_level > seq.white_level or resp.black_level != seq.black_level:
        resp = resp.with_levels(white_level=min(resp.white_level, seq.white_level), black_level=seq.black_level)
    span = float(seq.white_level - seq.black_level)
    cams = tuple(cameras) if cameras is not None else tuple(seq.cameras)
    pairs: list[dict] = []
    for cyc, cam, a, b, img_a, img_b in sweep_neighbours(
            seq, cams, max_ratio, lambda raw: np.concatenate(planes_of(raw, stride)).reshape(1, -1), progress, "scoring"):
        images = {a: img_a, b: img_b}
        for src, tgt in ((a, b), (b, a)):
            emu = emulate(images[src], src, tgt, resp).ravel()
            real = images[tgt].ravel()
            d = np.quantile(emu, qs) - np.quantile(real, qs)
            pairs.append(
                {
                    "cycle": int(cyc.index),
                    "camera": cam,
                    "source_ms": float(src),
                    "target_ms": float(tgt),
                    "rmse_pct": float(100.0 * np.sqrt(np.mean(d * d)) / span),
                }
            )
    if not pairs:
        raise CalibrationError(f"{seq.path}: no sweep holds two consecutive brackets to compare")
    errs = np.array([p["rmse_pct"] for p in pairs])
    settings = {
        "stride": int(stride),
        "quantiles": f"{len(qs)} levels {qs[0]:g}..{qs[-1]:g}",
        "max_ratio": float(max_ratio),
        "cameras": list(cams),
        "white_level": int(seq.white_level),
        "black_level": int(seq.black_level),
    }
    return CrossBracketError(pairs, float(np.median(errs)), float(np.mean(errs)), resp.name, settings)


def response_error(
    recovered: CameraResponse | np.ndarray,
    true: CameraResponse | np.ndarray,
    *,
    dn_range: tuple[int, int] = (16, 4079),
    align: str = "top",
) -> dict:
    """Error of a recovered g against the true one, in % of the true range.

    Both are g tables over the same DN (or responses).  ``align="top"`` scales both to
    g(top) = 255 (what files hold); ``"scale"`` fits the recovered curve's scale to the true
    one by least squares over ``dn_range`` (g is identified only up to scale).  Returns max
    and RMS of ``|g_rec - g_true|`` over ``dn_range`` in % of ``g_true(top) - g_true(0)``,
    and the same as a DN-equivalent error (``|f_true(g_rec(d)) - d|``).
    """
    gr = recovered.g if isinstance(recovered, CameraResponse) else np.asarray(recovered, float)
    gt = true.g if isinstance(true, CameraResponse) else np.asarray(true, float)
    n = min(gr.size, gt.size)
    gr, gt = gr[:n], gt[:n]
    lo, hi = int(dn_range[0]), min(int(dn_range[1]), n - 1)
    sl = slice(lo, hi + 1)
    gt = gt * (PCALIB_TOP_VALUE / gt[-1])
    if align == "top":
        gr = gr * (PCALIB_TOP_VALUE / gr[-1])
    elif align == "scale":
        gr = gr * float(np.dot(gr[sl], gt[sl]) / np.dot(gr[sl], gr[sl]))
    else:
        raise ValueError(f"align must be 'top' or 'scale', got {align!r}")
    rng_g = gt[-1] - gt[0]
    err = (gr[sl] - gt[sl]) / rng_g * 100
    dn = np.arange(n, dtype=float)
    dn_eq = np.interp(gr[sl], gt, dn) - dn[sl]
    return {
        "max_pct": float(np.max(np.abs(err))),
        "rms_pct": float(np.sqrt(np.mean(err**2))),
        "max_dn_equiv": float(np.max(np.abs(dn_eq))),
        "rms_dn_equiv": float(np.sqrt(np.mean(dn_eq**2))),
        "dn_range": [lo, hi],
        "align": align,
    }
