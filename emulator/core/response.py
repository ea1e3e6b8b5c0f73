"""Camera response: the inverse response g = f^-1 (DN -> linear exposure) and its forward f.

The response is held as a table of g at every integer DN in ``0..white_level``, strictly
increasing, so that

* ``inverse(dn)`` is a table lookup (linear interpolation between integers for
  non-integer DN), and
* ``forward(h)`` is the piecewise-linear inverse of that table, so that
  ``forward(inverse(d)) == d`` exactly for every integer ``d``.

Units of g are arbitrary (the TUM / BorealHDR ``pcalib`` files use g(white) = 255);
emulation only uses ratios of g, so a global scale is irrelevant.  An *offset* is not
neutral under a ratio, which is why pcalib samples are read exactly as given
(DESIGN.md, "How the table is read matters").  Files are read and written by
:mod:`emulator.io.pcalib` (:func:`~emulator.io.pcalib.read_response`).
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from emulator.errors import ResponseError
from emulator.core.levels import BOREALHDR_LEVELS, Levels

__all__ = ["CameraResponse", "BOREALHDR_WHITE_LEVEL", "BOREALHDR_BLACK_LEVEL"]

#: The one default white level, DN (alias of ``BOREALHDR_LEVELS.white``, defined in
#: :mod:`emulator.core.levels`): the BorealHDR sample saturates at 4094, one below the 12-bit
#: maximum 4095 (DESIGN.md).  Everything that needs a white level and is not given one falls
#: back to this: the response constructors here, the readers of recordings, stacks and run
#: folders (:mod:`emulator.io`), calibration and the synthetic camera.  A camera's own level
#: (``exposim.json``, ``run.json``, an argument) always wins.
BOREALHDR_WHITE_LEVEL = BOREALHDR_LEVELS.white
#: The one default black level, DN (alias of ``BOREALHDR_LEVELS.black``: 0).
BOREALHDR_BLACK_LEVEL = BOREALHDR_LEVELS.black

#: How many per-ratio emulation tables a response keeps (each is 8 KiB for 12 bits).
LUT_CACHE_SIZE = 512


def _check_increasing(g: np.ndarray, source: str) -> None:
    steps = np.diff(g)
    bad = ~(steps > 0)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ResponseError(
            f"{source}: inverse response is not strictly increasing: sample {i + 1} ({float(g[i + 1])!r}) "
            f"<= sample {i} ({float(g[i])!r}); {int(bad.sum())} such step(s)"
        )


@dataclass(eq=False)
class CameraResponse:
    """A strictly increasing inverse response g over DN ``0..white_level``.

    Parameters
    ----------
    g : ndarray, shape (white_level + 1,), float64
        Linear exposure (arbitrary units) at each integer DN.
    white_level : int, optional
        Highest DN the sensor produces; emulated images are clipped to it and pixels at
        or above it count as saturated.  Default: the top of the table, ``len(g) - 1``.
    black_level : int
        Lowest DN; pixels at or below it count as clipped dark.
    name : str
        Where the response came from (file path or constructor), used in messages.
    knots : ndarray or None
        The raw samples when loaded from a pcalib file (the reference AE code needs them).
    """

    g: np.ndarray
    white_level: int | None = None
    black_level: int = BOREALHDR_BLACK_LEVEL
    name: str = "custom"
    knots: np.ndarray | None = None
    _luts: OrderedDict = field(default_factory=OrderedDict, init=False, repr=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, init=False, repr=False)

    def __reduce__(self):
        # the LUT cache and its lock stay behind (method workers get the table, not the cache)
        return (type(self), (np.array(self.g), self.white_level, self.black_level, self.name,
                             None if self.knots is None else np.array(self.knots)))

    def __post_init__(self) -> None:
        # private, and immutable at the buffer level (a view of a bytes object): the caller's
        # array stays theirs, and no setflags(write=True) can change the table afterwards
        g = np.array(self.g, dtype=np.float64, copy=True)
        if g.ndim == 1:
            g = np.frombuffer(g.tobytes(), dtype=np.float64)
        self.white_level = int(g.size - 1 if self.white_level is None else self.white_level)
        self.black_level = int(self.black_level)
        if g.ndim != 1 or g.size != self.white_level + 1:
            raise ResponseError(
                f"{self.name}: inverse response must have white_level + 1 = {self.white_level + 1} "
                f"samples, got shape {g.shape}"
            )
        Levels.checked(self.black_level, self.white_level, where=self.name, error=ResponseError)
        if not np.all(np.isfinite(g)):
            first = int(np.flatnonzero(~np.isfinite(g))[0])
            raise ResponseError(f"{self.name}: non-finite inverse response at DN {first}")
        _check_increasing(g, self.name)
        g.setflags(write=False)
        self.g = g
        self._dn = np.arange(self.white_level + 1, dtype=np.float64)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_samples(
        cls,
        samples: np.ndarray,
        white_level: int,
        *,
        black_level: int = BOREALHDR_BLACK_LEVEL,
        name: str = "samples",
    ) -> "CameraResponse":
        """Build from N samples of g placed evenly over DN ``0..white_level``.

        Sample k sits at DN ``white_level * k / (N - 1)``; g at integer DN is the
        piecewise-linear interpolation through the samples, exactly as given.
        """
        samples = np.asarray(samples, dtype=np.float64)
        if samples.ndim != 1 or samples.size < 2:
            raise ResponseError(f"{name}: need at least 2 samples of the inverse response, got {samples.size}")
        if not np.all(np.isfinite(samples)):
            first = int(np.flatnonzero(~np.isfinite(samples))[0])
            raise ResponseError(f"{name}: non-finite sample at index {first}")
        _check_increasing(samples, name)
        knots_dn = np.linspace(0.0, float(white_level), samples.size)
        g = np.interp(np.arange(int(white_level) + 1, dtype=np.float64), knots_dn, samples)
        return cls(g, white_level, black_level, name, samples)

    @classmethod
    def linear(cls, white_level: int = BOREALHDR_WHITE_LEVEL, *, black_level: int = BOREALHDR_BLACK_LEVEL) -> "CameraResponse":
        """g(d) = (d - black) / (white - black): a linear sensor with its black offset.

        DN below the black level map to negative exposure (they only arise from noise).
        """
        dn = np.arange(int(white_level) + 1, dtype=np.float64)
        return cls((dn - black_level) / (white_level - black_level), white_level, black_level, "linear")

    @classmethod
    def gamma(
        cls, gamma: float, white_level: int = BOREALHDR_WHITE_LEVEL, *, black_level: int = BOREALHDR_BLACK_LEVEL
    ) -> "CameraResponse":
        """g(d) = x ** gamma with x = (d - black) / (white - black), i.e. f(h) = black + (white - black) h ** (1/gamma).

        Below the black level the curve is continued odd-symmetrically (-|x| ** gamma) so it
        stays strictly increasing.
        """
        if not (math.isfinite(gamma) and gamma > 0):
            raise ResponseError(f"gamma must be finite and positive, got {gamma!r}")
        dn = np.arange(int(white_level) + 1, dtype=np.float64)
        x = (dn - black_level) / (white_level - black_level)
        g = np.sign(x) * np.abs(x) ** float(gamma)
        return cls(g, white_level, black_level, f"gamma{gamma:g}")

    @classmethod
    def from_function(
        cls,
        g_of_dn,
        white_level: int = BOREALHDR_WHITE_LEVEL,
        *,
        black_level: int = BOREALHDR_BLACK_LEVEL,
        name: str = "function",
    ) -> "CameraResponse":
        """Tabulate a vectorised callable g(dn) at every integer DN."""
        dn = np.arange(int(white_level) + 1, dtype=np.float64)
        return cls(np.asarray(g_of_dn(dn), dtype=np.float64), white_level, black_level, name)

    def with_levels(self, *, white_level: int | None = None, black_level: int | None = None) -> "CameraResponse":
        """The same curve with other clip levels (a white level below the table top truncates it)."""
        white = self.white_level if white_level is None else int(white_level)
        black = self.black_level if black_level is None else int(black_level)
        if white > self.white_level:
            raise ResponseError(f"{self.name}: cannot raise white_level above the table top {self.white_level}")
        return CameraResponse(self.g[: white + 1].copy(), white, black, self.name, self.knots)

    @property
    def levels(self) -> Levels:
        """The clip levels as one :class:`~emulator.core.levels.Levels` value."""
        return Levels(self.black_level, self.white_level)

    # ------------------------------------------------------------------ evaluation
    @property
    def bit_depth(self) -> int:
        return int(self.white_level).bit_length()

    def inverse(self, dn) -> np.ndarray:
        """g(dn): linear exposure for DN values (float64, same shape). Integer DN index the table."""
        dn = np.asarray(dn)
        if dn.dtype.kind in "ui":
            return self.g[np.clip(dn, 0, self.white_level)]
        return np.interp(dn.astype(np.float64), self._dn, self.g)

    def forward(self, h) -> np.ndarray:
        """f(h): continuous DN (float64) for linear exposure h, clamped to [0, white_level]."""
        return np.interp(np.asarray(h, dtype=np.float64), self.g, self._dn)

    # ------------------------------------------------------------------ emulation tables
    def lut(self, ratio: float) -> tuple[np.ndarray, np.ndarray]:
        """(uint16 table L_k, bool validity table) for ratio k, cached (see emulator.core.emulate).

        Raises :class:`ResponseError` for a ratio that is not a finite positive number.
        """
        if isinstance(ratio, (bool, np.bool_, str, bytes)):
            raise ResponseError(f"lut: ratio must be a finite positive number, got {ratio!r}")
        try:
            key = float(ratio)
        except (TypeError, ValueError):
            raise ResponseError(f"lut: ratio must be a finite positive number, got {ratio!r}") from None
        if not (math.isfinite(key) and key > 0.0):
            raise ResponseError(f"lut: ratio must be a finite positive number, got {ratio!r}")
        with self._lock:  # methods of one run may emulate from several threads
            hit = self._luts.get(key)
            if hit is not None:
                self._luts.move_to_end(key)
                return hit
        if key == 1.0:
            table = np.arange(self.white_level + 1, dtype=np.uint16)
        else:
            with np.errstate(over="ignore"):  # a huge ratio overflows to inf, which clips to white as it should
                target = self.forward(key * self.g)
            table = np.clip(np.rint(target), self.black_level, self.white_level).astype(np.uint16)
        dn = np.arange(self.white_level + 1)
        clipped_high = dn >= self.white_level
        clipped_low = dn <= self.black_level
        valid = ~(clipped_high | clipped_low)
        if key >= 1.0:
            valid |= clipped_high  # a saturated pixel stays saturated when brightened
        if key <= 1.0:
            valid |= clipped_low  # a black pixel stays black when darkened
        table.setflags(write=False)
        valid.setflags(write=False)
        with self._lock:
            self._luts[key] = (table, valid)
            self._luts.move_to_end(key)
            while len(self._luts) > LUT_CACHE_SIZE:
                self._luts.popitem(last=False)
        return table, valid

    def __repr__(self) -> str:
        return f"CameraResponse({self.name!r}, white_level={self.white_level}, black_level={self.black_level})"
