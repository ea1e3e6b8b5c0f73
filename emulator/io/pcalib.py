"""The pcalib inverse-response format (TUM monoVO / BorealHDR), reader and writer.

A pcalib file holds N whitespace-separated samples of the inverse response g = f^-1,
placed evenly over DN ``0..table_top`` (``table_top`` = 4095 for 12-bit data: sample k
sits at DN ``4095 k / (N - 1)``).  TUM files hold N = 256 samples in units where
g(4095) = 255; ``synth`` writes one sample per DN (N = table_top + 1), which is always
accepted.  Samples are read exactly as given: no renormalisation and no forcing of the
end knots (DESIGN.md, "How the table is read matters").

g is linear exposure: non-negative, and about 0 where no light falls (DN at the black
level).  A strictly increasing table that is shifted (negative at the black level, or
far above 0 there) would pass every other check and emulate wrongly (a table negative at
the dark end makes darker targets brighter), so :func:`read_response` refuses one whose
g(black_level) is below ``-PCALIB_NEGATIVE_TOLERANCE`` or above
``PCALIB_ORIGIN_TOLERANCE`` times g(table_top) (:func:`check_origin`).  The upper bound is
loose (5 %) because a recovered table is extrapolated below the lowest observed DN: a
d^0.45 curve, vertical at 0, comes back from a stack with g(0) at 3.9 %.  The real
BorealHDR table has g(0) = 0.173 of 255 (0.07 %).
Tables of a camera with a black-level pedestal (``synth`` with ``black_level > 0``)
continue below the black level with negative values; pass that ``black_level``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from emulator.errors import ResponseError
from emulator.io.files import atomic_write_bytes
from emulator.core.response import CameraResponse

__all__ = [
    "PCALIB_TABLE_TOP",
    "PCALIB_SAMPLES",
    "PCALIB_TOP_VALUE",
    "read_pcalib",
    "write_pcalib",
    "read_response",
    "write_response",
    "check_origin",
    "PCALIB_ORIGIN_TOLERANCE",
    "PCALIB_NEGATIVE_TOLERANCE",
]

#: A pcalib table spans DN 0..4095 (12 bits).
PCALIB_TABLE_TOP = 4095
#: Samples in a TUM pcalib file.
PCALIB_SAMPLES = 256
#: g at the table top in TUM pcalib units.
PCALIB_TOP_VALUE = 255.0
#: How far above 0 g(black_level) may lie, as a fraction of g(table_top).
PCALIB_ORIGIN_TOLERANCE = 0.05
#: How far below 0 g(black_level) may lie (rounding only: negative exposure is meaningless).
PCALIB_NEGATIVE_TOLERANCE = 0.001


#: Largest pcalib file read, bytes (65536 samples of 25 characters fit twice over).
MAX_PCALIB_BYTES = 4 * 2**20


def read_pcalib(path: str | os.PathLike) -> np.ndarray:
    """The samples of g in a pcalib file, float64, unchanged.

    Raises :class:`ResponseError` naming the file for an empty file, unparsable tokens or
    non-finite values.  Monotonicity and count are checked by :func:`read_response`,
    which knows the bit depth.
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            data = fh.read(MAX_PCALIB_BYTES + 1)  # bounded: /dev/zero or a huge file never fills memory
        if len(data) > MAX_PCALIB_BYTES:
            raise ResponseError(f"{path}: larger than {MAX_PCALIB_BYTES // 2**20} MiB; a pcalib file holds one "
                                "number per DN level (a 16-bit table is well under 2 MiB)")
        text = data.decode()
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: response file not found") from None
    except IsADirectoryError:
        raise ResponseError(f"{path}: is a folder, not a pcalib file") from None
    except UnicodeDecodeError:
        raise ResponseError(f"{path}: not a text file (pcalib files hold whitespace-separated numbers)") from None
    tokens = text.split()
    if not tokens:
        raise ResponseError(f"{path}: empty file, expected whitespace-separated samples of the inverse response")
    values = np.empty(len(tokens), dtype=np.float64)
    for i, tok in enumerate(tokens):
        try:
            values[i] = float(tok)
        except ValueError:
            shown = tok if len(tok) <= 40 else f"{tok[:40]}... ({len(tok)} characters)"
            sep = next((c for c in ",;\t" if c in tok), None)
            hint = f"; samples are separated by {sep!r}, a pcalib file separates them by spaces" if sep else ""
            raise ResponseError(f"{path}: sample {i} is {shown!r}, not a number{hint}") from None
    bad = ~np.isfinite(values)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise ResponseError(
            f"{path}: {int(bad.sum())} non-finite sample(s), the first at index {first} ({tokens[first]!r})"
        )
    return values


def check_origin(g, black_level: int, source: str, *, tolerance: float = PCALIB_ORIGIN_TOLERANCE,
                 negative_tolerance: float = PCALIB_NEGATIVE_TOLERANCE) -> None:
    """Refuse an inverse response that is not >= 0 with g(black_level) ~ 0 (:class:`ResponseError`).

    ``g`` is the table at integer DN (``CameraResponse.g``, increasing).  Refused: g not
    positive at the table top; g(black_level) below ``-negative_tolerance`` times g(table_top)
    (a table shifted down, which makes darker emulation targets brighter) or above
    ``tolerance`` times it (a table shifted up, whose dark end would not darken).  The message names
    ``source`` (the file) and the value found.
    """
    g = np.asarray(g, dtype=np.float64)
    black = int(black_level)
    top = float(g[-1])
    if not top > 0:
        raise ResponseError(
            f"{source}: inverse response is not positive anywhere (g = {top:.6g} at the table top DN {g.size - 1}); "
            f"g is linear exposure: >= 0, about 0 at the black level"
        )
    g0 = float(g[black])
    if -negative_tolerance * top <= g0 <= tolerance * top:
        return
    where = "DN 0" if black == 0 else f"the black level DN {black}"
    if g0 < 0:
        raise ResponseError(
            f"{source}: inverse response is negative at {where} (g = {g0:.6g}, {100 * g0 / top:.3g} % of "
            f"g(top) = {top:.6g}): g is linear exposure, >= 0 with g ~ 0 at the black level; a table shifted "
            f"down makes darker emulation targets brighter (subtract nothing from a pcalib table, or give the "
            f"black level of a camera with a pedestal)"
        )
    raise ResponseError(
        f"{source}: inverse response is shifted up: g = {g0:.6g} at {where} is {100 * g0 / top:.3g} % of "
        f"g(top) = {top:.6g} (at most {100 * tolerance:g} % allowed): g is linear exposure, about 0 where no "
        f"light falls"
    )


def write_pcalib(path: str | os.PathLike, samples, *, overwrite: bool = False) -> Path:
    """Write samples of g as one line, space-separated, at full precision (atomic)."""
    samples = np.asarray(samples, dtype=np.float64).ravel()
    if samples.size < 2 or not np.all(np.isfinite(samples)):
        raise ResponseError(f"{path}: need at least 2 finite samples of g, got {samples.size}")
    text = " ".join(repr(float(v)) for v in samples) + "\n"
    return atomic_write_bytes(path, text.encode(), overwrite=overwrite)


def read_response(
    path: str | os.PathLike,
    white_level: int = PCALIB_TABLE_TOP,
    *,
    black_level: int = 0,
    expected_count: int | None = PCALIB_SAMPLES,
) -> CameraResponse:
    """A :class:`CameraResponse` from a pcalib file (N samples of g over DN 0..white_level).

    ``white_level`` is the table top (4095 for the pcalib format; clip to a camera's own
    level with :meth:`CameraResponse.with_levels`).  ``expected_count`` (256 for the TUM
    format) is enforced unless None; a table with ``white_level + 1`` samples (one per DN)
    is always accepted.  A table that is not >= 0 with g(black_level) ~ 0 is refused
    (:func:`check_origin`); ``black_level`` is where g must be ~ 0.
    """
    samples = read_pcalib(path)
    n = samples.size
    if expected_count is not None and n not in (expected_count, int(white_level) + 1):
        raise ResponseError(
            f"{path}: expected {expected_count} samples (or {int(white_level) + 1}, one per DN), got {n}"
        )
    response = CameraResponse.from_samples(samples, white_level, black_level=black_level, name=str(path))
    check_origin(response.g, black_level, str(path))
    return response


def write_response(
    path: str | os.PathLike,
    response: CameraResponse,
    *,
    n_samples: int = PCALIB_SAMPLES,
    overwrite: bool = False,
) -> Path:
    """Write a response as a pcalib file of ``n_samples`` samples over its table.

    When the response was built from exactly ``n_samples`` knots (a pcalib file, or the
    256 knots of a stack calibration), the knots are written as they are, so that
    :func:`read_response` gives back the same response; otherwise g is sampled at evenly
    spaced DN over ``0..response.white_level``.
    """
    n_samples = int(n_samples)
    if response.knots is not None and response.knots.size == n_samples:
        samples = response.knots
    else:
        samples = response.inverse(np.linspace(0.0, float(response.white_level), n_samples))
    return write_pcalib(path, samples, overwrite=overwrite)
