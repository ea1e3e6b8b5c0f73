"""What every auto-exposure method shares: the protocol, gray conversion, guards, clamps.

The contract (``specs/ae_methods.md`` section 0): ``next_ms = method.next_exposure(raw,
exposure_ms)`` reads an H x W uint16 Bayer mosaic (12-bit DN) captured at ``exposure_ms``
and returns the exposure of the next frame as a built-in ``float``.  Two modes:

``mode="paper"`` (default)
    The published method's intent, the reference code's defects of spec section 7
    corrected (among them the gray conversion: OpenCV's ``COLOR_BayerRG2GRAY`` names the
    BGGR layout, so on the RGGB sensor the reference weighs R with 0.114 and B with 0.299;
    paper mode uses ``COLOR_BayerBG2GRAY``, the true RGGB weights).
``mode="borealhdr"``
    The published BorealHDR reference code (REF), quirks included.

Guards that only replace a REF crash, NaN or non-finite result are on in both modes:
a computed exposure that is not finite or not positive is replaced by the input
exposure, counted in :attr:`AutoExposureMethod.guard_count` and logged (``logging``,
never printed).  The optional clamp ``range_ms`` is off by default in borealhdr mode
(REF has none) and :data:`DEFAULT_RANGE_MS` in paper mode, the same clamp the closed loop
(:mod:`emulator.playback`) applies to every proposal.
"""

from __future__ import annotations

import logging
import math
from typing import Protocol, runtime_checkable

import cv2
import numpy as np

from emulator.autoexposure.frame import FRAME_MEMO
from emulator.errors import ExposimError

__all__ = [
    "MethodFailed",
    "AutoExposure",
    "AutoExposureMethod",
    "AutoExposureError",
    "MODES",
    "DEFAULT_RANGE_MS",
    "REF_BAYER_CODE",
    "RGGB_BAYER_CODE",
    "FULL_SCALE_DN",
    "MAX_DN",
    "to_gray",
    "bayer_to_gray_reference",
    "check_mode",
    "check_seed",
    "SEED_MAX",
    "check_range",
]

logger = logging.getLogger("emulator.autoexposure")

#: The two behaviours every method offers (spec, "Project decision").
MODES = ("paper", "borealhdr")
#: The one default clamp of an exposure proposal, ms: of paper-mode methods (REF mode has
#: none) and of the closed loop (``exposim run --range-ms``).  The upper end is 50 ms because
#: BorealHDR's recorder shoots every ~46 ms (22 frames/s), so a longer integration is not
#: physical for the camera being emulated; 50 ms is what ``exposim run`` has always used.
#: The lower end, 0.02 ms, is the spec's exposure floor (Zhang's).
DEFAULT_RANGE_MS = (0.02, 50.0)
#: OpenCV code REF uses; OpenCV's "RG" names the BGGR layout (spec section 0).
REF_BAYER_CODE = cv2.COLOR_BayerRG2GRAY
#: OpenCV code that gives the standard luma weights on a true RGGB mosaic.
RGGB_BAYER_CODE = cv2.COLOR_BayerBG2GRAY
#: 12-bit full scale the percent targets of the spec refer to (2 ** 12).
FULL_SCALE_DN = 4096
#: Largest 12-bit DN; the spec's constants assume white = 4095.
MAX_DN = 4095
#: Smallest image side a method accepts (3 x 3 gradient kernels need some interior).
MIN_SIDE = 4


class AutoExposureError(ExposimError):
    """Invalid input to an auto-exposure method (image type or shape, exposure, option)."""


class MethodFailed(AutoExposureError):
    """A method's call failed: it raised, returned a non-finite or non-positive exposure, or
    took longer than the per-call limit.  The closed loop records it and drops the method."""


@runtime_checkable
class AutoExposure(Protocol):
    """The protocol of an AE method: a name, ``reset()`` and ``next_exposure``."""

    name: str

    def reset(self) -> None:  # pragma: no cover - protocol
        ...

    def next_exposure(self, raw: np.ndarray, exposure_ms: float) -> float:  # pragma: no cover - protocol
        ...


def check_mode(mode: str) -> str:
    if mode not in MODES:
        raise AutoExposureError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    return mode


def check_range(range_ms) -> tuple[float, float] | None:
    """Validate an exposure clamp (lo, hi) in ms, or None (no clamp)."""
    if range_ms is None:
        return None
    try:
        lo, hi = (float(v) for v in range_ms)
    except (TypeError, ValueError):
        raise AutoExposureError(f"range_ms must be (low_ms, high_ms) or None, got {range_ms!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
        raise AutoExposureError(f"range_ms must satisfy 0 < low <= high, finite; got {range_ms!r}")
    return lo, hi


def check_exposure_ms(value) -> float:
    try:
        t = float(value)
    except (TypeError, ValueError):
        raise AutoExposureError(f"exposure_ms must be a number of milliseconds, got {value!r}") from None
    if not (math.isfinite(t) and t > 0):
        raise AutoExposureError(f"exposure_ms must be finite and positive (milliseconds), got {value!r}")
    return t


#: Largest seed of NumPy's legacy ``RandomState`` (Kim's optimizer restarts): 2**32 - 1.
SEED_MAX = 2**32 - 1


def check_seed(value, name: str = "seed") -> int:
    """An integer seed in 0 .. 2**32 - 1 (``bool`` and non-integral numbers refused)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise AutoExposureError(f"{name} must be an integer in 0..{SEED_MAX}, got {value!r}")
    if not 0 <= int(value) <= SEED_MAX:
        raise AutoExposureError(f"{name} must be in 0..{SEED_MAX}, got {value!r}")
    return int(value)


def check_raw(raw) -> np.ndarray:
    if not isinstance(raw, np.ndarray):
        raise AutoExposureError(f"raw must be a numpy array, got {type(raw).__name__}")
    if raw.dtype != np.uint16:
        raise AutoExposureError(f"raw must be uint16 (12-bit Bayer DN), got dtype {raw.dtype}")
    if raw.ndim != 2 or min(raw.shape) < MIN_SIDE:
        raise AutoExposureError(f"raw must be a 2-D Bayer mosaic of at least {MIN_SIDE}x{MIN_SIDE}, got shape {raw.shape}")
    return raw


def to_gray(raw: np.ndarray, code: int = REF_BAYER_CODE) -> np.ndarray:
    """Gray image of a Bayer mosaic by OpenCV's bilinear demosaic (uint16, same shape).

    ``code`` is an OpenCV ``COLOR_Bayer*2GRAY`` constant: :data:`REF_BAYER_CODE` (what REF
    does) or :data:`RGGB_BAYER_CODE` (correct weights on an RGGB sensor).
    """
    if not raw.flags.c_contiguous:
        raw = np.ascontiguousarray(raw)
    return cv2.cvtColor(raw, code)


def bayer_to_gray_reference(raw: np.ndarray) -> np.ndarray:
    """OpenCV-free equivalent of ``to_gray(raw, REF_BAYER_CODE)`` within +-1 DN (spec section 0).

    R-hat and B-hat are each channel's own samples convolved with
    ``[[1,2,1],[2,4,2],[1,2,1]]/4``, G-hat the green samples with ``[[0,1,0],[1,4,1],[0,1,0]]/4``;
    ``Y = round(0.114 R + 0.587 G + 0.299 B)`` with R at even rows and columns; the outer rows
    and columns are copied from their neighbours.  Used to check the OpenCV path.
    """
    from scipy.ndimage import convolve

    x = np.asarray(raw, dtype=np.float64)
    h, w = x.shape
    rows, cols = np.mgrid[0:h, 0:w]
    r_mask = (rows % 2 == 0) & (cols % 2 == 0)
    b_mask = (rows % 2 == 1) & (cols % 2 == 1)
    g_mask = ~(r_mask | b_mask)
    k_rb = np.array([[1, 2, 1], [2, 4, 2], [1, 2, 1]], dtype=np.float64) / 4.0
    k_g = np.array([[0, 1, 0], [1, 4, 1], [0, 1, 0]], dtype=np.float64) / 4.0
    r = convolve(x * r_mask, k_rb, mode="constant")
    b = convolve(x * b_mask, k_rb, mode="constant")
    g = convolve(x * g_mask, k_g, mode="constant")
    y = np.rint(0.114 * r + 0.587 * g + 0.299 * b)
    y[0, :], y[-1, :] = y[1, :], y[-2, :]
    y[:, 0], y[:, -1] = y[:, 1], y[:, -2]
    return np.clip(y, 0, 65535).astype(np.uint16)


class AutoExposureMethod:
    """Base class: input checks, gray conversion, the non-finite guard and the clamp.

    Subclasses implement ``_step(raw, t) -> float`` (may be non-finite; the guard handles
    it) and ``_reset()``, and set ``name``.  :attr:`last` holds diagnostics of the most
    recent call (mean, metric, fallback used, ...), for tests and reports.
    """

    name: str = "method"
    #: The keyword option that seeds the random numbers the method draws (a stochastic method declares it:
    #: a study runs it with several seeds, :func:`emulator.autoexposure.builtin.seed_option`); None: draws none.
    seed_option: str | None = None

    def __init__(self, *, mode: str = "paper", range_ms="default") -> None:
        self.mode = check_mode(mode)
        if isinstance(range_ms, str) and range_ms == "default":
            range_ms = DEFAULT_RANGE_MS if self.mode == "paper" else None
        self.range_ms = check_range(range_ms)
        self.gray_code = REF_BAYER_CODE if self.mode == "borealhdr" else RGGB_BAYER_CODE
        self.guard_count = 0
        self.calls = 0
        self.last: dict = {}

    # ------------------------------------------------------------------ protocol
    def reset(self) -> None:
        """Forget all state: the next call behaves like the first one after construction."""
        self.guard_count = 0
        self.calls = 0
        self.last = {}
        self._reset()

    def next_exposure(self, raw: np.ndarray, exposure_ms: float) -> float:
        """Exposure in ms for the next frame, given the frame ``raw`` captured at ``exposure_ms``."""
        t = check_exposure_ms(exposure_ms)
        raw = check_raw(raw)
        self.calls += 1
        self.last = {}
        proposed = self._step(raw, t)
        return self._finish(proposed, t)

    def gray(self, raw: np.ndarray) -> np.ndarray:
        """The mode's gray conversion of a mosaic (uint16).

        For a read-only frame the result is computed once and shared, read-only, by every
        method reading the same frame (:data:`emulator.autoexposure.frame.FRAME_MEMO`).
        """
        code = self.gray_code
        return FRAME_MEMO.get(raw, ("gray", code), lambda: to_gray(raw, code))

    def gray_mean(self, raw: np.ndarray) -> float:
        """Mean of :meth:`gray` (float64 accumulation; exact: a sum of integers below 2**53)."""
        code = self.gray_code
        return FRAME_MEMO.get(raw, ("gray_mean", code), lambda: float(self.gray(raw).mean(dtype=np.float64)))

    def config(self) -> dict:
        """JSON-ready options that reproduce this instance (name, mode, range, method options)."""
        return {"name": self.name, "mode": self.mode, "range_ms": list(self.range_ms) if self.range_ms else None,
                **self._options()}

    # ------------------------------------------------------------------ helpers
    def _finish(self, proposed, t: float) -> float:
        try:
            value = float(proposed)
        except (TypeError, ValueError):
            value = math.nan
        if not (math.isfinite(value) and value > 0.0):
            self.guard_count += 1
            self.last["guarded"] = True
            logger.info("%s: non-finite or non-positive exposure %r replaced by %r ms", self.name, proposed, t)
            value = t
        if self.range_ms is not None:
            lo, hi = self.range_ms
            value = min(max(value, lo), hi)
        return float(value)

    def _options(self) -> dict:
        return {}

    def _reset(self) -> None:
        pass

    def _step(self, raw: np.ndarray, t: float) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, mode={self.mode!r})"
