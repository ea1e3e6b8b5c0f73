"""The plot of a recovered inverse camera response (``exposim calibrate``)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from emulator.io.pcalib import PCALIB_TOP_VALUE
from emulator.report.figures import new_figure, save

__all__ = ["plot_calibration"]


def plot_calibration(
    result,
    path: str | os.PathLike,
    *,
    reference=None,
    reference_label: str = "reference",
    overwrite: bool = False,
) -> Path:
    """Plot the recovered g with the fitted samples (and a reference curve), and the fit residual by DN.

    Parameters
    ----------
    result : emulator.calibration.CalibrationResult
    path : path
        PNG to write (refused when it exists unless ``overwrite``).
    reference : CameraResponse, optional
        A response to draw for comparison, scaled to g(top) = 255.
    """
    fig, (ax, axr) = new_figure(2, 5.5, 4.2)
    resp = result.response
    dn = np.arange(resp.white_level + 1)
    ax.scatter(result.samples_dn, result.samples_g, s=1, alpha=0.15, color="tab:gray", rasterized=True,
               label="samples (DN, t*B)" if result.method.startswith("als") else "samples (d_hi, r*g(d_lo))")
    ax.plot(dn, resp.g, color="tab:blue", lw=1.5, label=f"recovered ({result.method})")
    if reference is not None:
        gref = reference.g * (PCALIB_TOP_VALUE / reference.g[-1])
        ax.plot(np.arange(gref.size), gref, color="tab:red", lw=1, ls="--", label=reference_label)
    lo, hi = result.observed_dn
    ax.axvspan(0, lo, color="k", alpha=0.06)
    ax.axvspan(hi, resp.white_level, color="k", alpha=0.06, label="extrapolated")
    ax.set_xlabel("DN")
    ax.set_ylabel("g = f^-1 (pcalib units, g(top) = 255)")
    ax.set_title(f"inverse response; residual {result.residual_rms_dn:.2f} DN RMS")
    ax.legend(loc="upper left", fontsize=8)
    # residual in DN, binned
    pred_dn = resp.forward(result.samples_g)
    r = result.samples_dn - pred_dn
    bins = np.linspace(0, resp.white_level, 65)
    which = np.digitize(result.samples_dn, bins)
    centers, rms = [], []
    for k in range(1, bins.size):
        m = which == k
        if m.sum() >= 5:
            centers.append(0.5 * (bins[k - 1] + bins[k]))
            rms.append(np.sqrt(np.mean(r[m] ** 2)))
    axr.plot(centers, rms, "o-", ms=3)
    axr.set_xlabel("DN")
    axr.set_ylabel("RMS residual (DN)")
    axr.set_title("fit residual by DN")
    axr.grid(alpha=0.3)
    return save(fig, path, overwrite=overwrite)
