"""A parametric inverse response fitted to the real BorealHDR table, and the script that fits it.

The BorealHDR camera's inverse response ``g = f^-1`` ships as 256 samples over DN 0..4095
(``calibration/pcalib_inside1.txt``, units where the last sample is 255).  Its shape:

* a *toe*: g(0) = 0.173, not 0, then a quick rise to ~0.33 and a near-flat stretch up to
  DN ~100 (the response is very steep there);
* a convex *body*, close to a power law of exponent ~2 whose local exponent drifts;
* a *knee* near DN 3490 above which g rises about four times faster (the top of the
  response is compressed).

The family that follows these three parts, with ``x = DN / 4095`` and g in table units::

    g(x) = a + b * (1 - exp(-x / tau))          toe: offset a, step b over tau
             + c * x**p * exp(k * x)            body
             + s * max(x - x_knee, 0)**q        knee (q > 1 keeps g' continuous)

Nine numbers, :data:`BOREALHDR_FIT`.  They minimise (Nelder-Mead on a p=60 norm, i.e.
near-minimax) the *mixed* error ``(g_fit - g_table) / (g_table + 1)``: relative where the
table is well above one unit, absolute in the toe where it is not, so that neither end
dominates.  Every term is increasing for x > 0 with the bounds used, so the curve is
strictly increasing (checked at every integer DN by :class:`~emulator.core.response.CameraResponse`).

Measured against the table (the test ``tests/synth/test_synth_camera.py`` recomputes them):
maximum absolute error 2.35 table units (0.92 % of g(4095) = 255), at sample 215
(DN 3453, inside the knee); maximum mixed error 2.11 %; RMS 0.82 units; g(0) = 0.1729
(table: 0.1729).

Refit with ``python -m synth.response_fit [path/to/pcalib.txt]`` (prints JSON; about
half a minute).  The table itself is never copied into the repository.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

from emulator.io.pcalib import PCALIB_TABLE_TOP

__all__ = [
    "BOREALHDR_FIT",
    "PARAMETER_NAMES",
    "inverse_response_curve",
    "fit_inverse_response",
    "fit_errors",
    "main",
]

#: Parameter order of :func:`inverse_response_curve`.
PARAMETER_NAMES = ("a", "b", "tau", "c", "p", "k", "s", "x_knee", "q")

#: The fitted parameters (7 significant digits), from ``python -m synth.response_fit``
#: on ``data/borealhdr_sample/calibration/pcalib_inside1.txt``.
BOREALHDR_FIT: dict[str, float] = {
    "a": 0.1729181,
    "b": 0.117912,
    "tau": 0.001121502,
    "c": 98.58351,
    "p": 1.839685,
    "k": 0.531808,
    "s": 746.1312,
    "x_knee": 0.8533946,
    "q": 1.131777,
}

# Bounds of the fit; they also make every term increasing (b, c, s >= 0, p, q >= 1, tau > 0).
_LOWER = (0.0, 0.0, 2.0 / PCALIB_TABLE_TOP, 0.0, 1.0, -5.0, 0.0, 0.5, 1.0)
_UPPER = (1.0, 1.0, 0.05, 500.0, 5.0, 5.0, 5000.0, 0.99, 3.0)
_START = (0.17, 0.12, 4.0 / PCALIB_TABLE_TOP, 98.4, 1.84, 0.53, 700.0, 0.855, 1.1)
#: The mixed error is (g_fit - g) / (g + _MIXED_OFFSET): absolute below ~1 unit, relative above.
_MIXED_OFFSET = 1.0


def inverse_response_curve(x, params: dict[str, float] | None = None) -> np.ndarray:
    """Evaluate the parametric inverse response g at normalised DN ``x``.

    Parameters
    ----------
    x : array-like of float
        ``DN / 4095``, normally in [0, 1] (x < 0 is not defined: the toe term diverges).
    params : dict or None
        The nine parameters (:data:`PARAMETER_NAMES`); None uses :data:`BOREALHDR_FIT`.

    Returns
    -------
    ndarray of float64
        g in pcalib table units (g(1) ~ 255), same shape as ``x``.
    """
    p = BOREALHDR_FIT if params is None else params
    x = np.asarray(x, dtype=np.float64)
    toe = p["b"] * -np.expm1(-x / p["tau"])
    body = p["c"] * np.power(x, p["p"]) * np.exp(p["k"] * x)
    knee = p["s"] * np.power(np.maximum(x - p["x_knee"], 0.0), p["q"])
    return p["a"] + toe + body + knee


def _as_dict(values) -> dict[str, float]:
    return {n: float(v) for n, v in zip(PARAMETER_NAMES, values)}


def fit_errors(samples, params: dict[str, float] | None = None) -> dict:
    """Errors of the curve against a table of N samples over DN 0..4095.

    Returns a JSON-ready dict: ``max_abs`` (table units), ``max_abs_sample`` and
    ``max_abs_dn`` (where), ``max_abs_percent_of_top`` (of the last sample), ``rms``,
    ``max_mixed`` (max of ``|g_fit - g| / (g + 1)``) and ``g0_fit`` / ``g0_table``.
    """
    g = np.asarray(samples, dtype=np.float64)
    x = np.linspace(0.0, 1.0, g.size)
    err = inverse_response_curve(x, params) - g
    i = int(np.argmax(np.abs(err)))
    return {
        "n_samples": int(g.size),
        "max_abs": float(np.abs(err).max()),
        "max_abs_sample": i,
        "max_abs_dn": float(x[i] * PCALIB_TABLE_TOP),
        "max_abs_percent_of_top": float(100.0 * np.abs(err).max() / g[-1]),
        "rms": float(np.sqrt(np.mean(err * err))),
        "max_mixed": float(np.max(np.abs(err) / (g + _MIXED_OFFSET))),
        "g0_fit": float(inverse_response_curve(0.0, params)),
        "g0_table": float(g[0]),
    }


def fit_inverse_response(samples, *, restarts: int = 6) -> dict[str, float]:
    """Fit the nine parameters to N samples of g over DN 0..4095 (offline; tens of seconds).

    A weighted least-squares start (``scipy.optimize.least_squares`` on the mixed error)
    is refined by Nelder-Mead on the p=60 norm of the mixed error plus 0.02 times its
    RMS (the small RMS term pins parameters the minimax leaves free, e.g. the toe).
    Deterministic.  Returns the parameters rounded to 7 significant digits.
    """
    from scipy.optimize import least_squares, minimize

    g = np.asarray(samples, dtype=np.float64)
    x = np.linspace(0.0, 1.0, g.size)
    scale = g + _MIXED_OFFSET
    lower, upper = np.array(_LOWER), np.array(_UPPER)

    def mixed(values):
        return (inverse_response_curve(x, _as_dict(values)) - g) / scale

    start = least_squares(mixed, _START, bounds=(lower, upper)).x

    def objective(values, power=60):
        if np.any(values < lower) or np.any(values > upper):
            return 1e9
        e = mixed(values) / 0.01
        return float(np.mean(np.abs(e) ** power) ** (1.0 / power) + 0.02 * np.sqrt(np.mean(e * e)))

    best = start
    for _ in range(restarts):
        best = minimize(objective, best, method="Nelder-Mead",
                        options=dict(maxiter=20000, maxfev=20000, xatol=1e-12, fatol=1e-15, adaptive=True)).x
    return {n: float(f"{v:.7g}") for n, v in zip(PARAMETER_NAMES, best)}


def main(argv: list[str] | None = None) -> int:
    """Fit the table given on the command line (default: the shared BorealHDR one), print JSON."""
    args = sys.argv[1:] if argv is None else argv
    if args:
        path = Path(args[0])
    else:
        path = (Path(__file__).resolve().parents[2] / "shared" / "data" / "borealhdr_sample" / "calibration"
                / "pcalib_inside1.txt")
    from emulator.io.pcalib import read_pcalib

    samples = read_pcalib(path)
    params = fit_inverse_response(samples)
    report = {"source": str(path), "params": params, "errors": fit_errors(samples, params)}
    if not all(math.isfinite(v) for v in params.values()):  # pragma: no cover - defensive
        return 1
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
