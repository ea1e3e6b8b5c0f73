"""A camera's clip levels as one value: :class:`Levels` (black, white), in DN.

The BorealHDR defaults, :data:`BOREALHDR_LEVELS` (black 0, white 4094: the sample saturates
one below the 12-bit maximum), are defined here once, in a leaf module, and are reached
through :mod:`emulator.io.borealhdr` (the reader whose fallback they are).  They cannot be
defined in ``emulator/io/borealhdr.py`` itself: :mod:`emulator.core.response` needs them for its
constructors' defaults, and ``io.borealhdr -> io.pcalib -> response`` already runs the other
way, so that would be an import circle (``tests/project/test_import_contract.py``).
``emulator.core.response.BOREALHDR_WHITE_LEVEL`` / ``BOREALHDR_BLACK_LEVEL`` stay as aliases of
these two numbers for the many callers that use them.
"""

from __future__ import annotations

from dataclasses import dataclass

from emulator.errors import ExposimError

__all__ = ["Levels", "BOREALHDR_LEVELS"]


@dataclass(frozen=True)
class Levels:
    """Black and white clip levels of a camera, DN: ``0 <= black < white <= 2**bit_depth - 1``.

    ``bit_depth`` (default 16, the uint16 container) bounds ``white``; pass 12 where the data
    are 12-bit.  A bad pair raises :class:`~emulator.errors.ExposimError`; :meth:`checked`
    raises the caller's error class and names where the numbers came from.
    """

    black: int
    white: int
    bit_depth: int = 16

    def __post_init__(self) -> None:
        problem = self._problem(self.black, self.white, self.bit_depth)
        if problem:
            raise ExposimError(f"levels: {problem}")
        object.__setattr__(self, "black", int(self.black))
        object.__setattr__(self, "white", int(self.white))

    @staticmethod
    def _problem(black, white, bit_depth) -> str:
        if not isinstance(bit_depth, int) or isinstance(bit_depth, bool) or not 1 <= bit_depth <= 16:
            return f"bit_depth must be an integer in 1..16, got {bit_depth!r}"
        for name, v in (("black_level", black), ("white_level", white)):
            if isinstance(v, bool) or not float(v).is_integer():
                return f"{name} must be an integer DN, got {v!r}"
        top = (1 << bit_depth) - 1
        if not 0 <= black < white <= top:
            return (f"need 0 <= black_level < white_level <= {top} ({bit_depth} bits), "
                    f"got black_level {black}, white_level {white}")
        return ""

    @classmethod
    def checked(cls, black, white, *, bit_depth: int = 16, where: str = "levels",
                error: type[ExposimError] = ExposimError) -> "Levels":
        """``Levels(black, white, bit_depth)``, raising ``error("<where>: ...")`` when bad."""
        problem = cls._problem(black, white, bit_depth)
        if problem:
            raise error(f"{where}: {problem}")
        return cls(int(black), int(white), bit_depth)

    @property
    def span_dn(self) -> int:
        """``white - black``, DN."""
        return self.white - self.black


#: The BorealHDR sample's levels, the one fallback anywhere in exposim (a recording's
#: ``exposim.json``, a run's ``run.json`` or an argument always wins).
BOREALHDR_LEVELS = Levels(black=0, white=4094, bit_depth=12)
