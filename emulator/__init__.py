"""exposim's emulator: the part that runs on real bracketed recordings.

numpy and OpenCV only; nothing here imports ``synth``, ``scenes`` or ``validation``
(the command line loads their sub-commands lazily).
"""

from importlib import metadata as _metadata

from emulator.emulate import emulate, emulation_lut
from emulator.errors import DatasetError, EmulationError, ExposimError, OutputExistsError, ResponseError
from emulator.response import CameraResponse
from emulator.select import SELECTORS, closest, higher_no_sat, saturated_fraction, select

try:  # one source: the version in pyproject.toml, as installed
    __version__ = _metadata.version("exposim")
except _metadata.PackageNotFoundError:  # imported from a source tree that was never installed
    __version__ = "0+unknown"

__all__ = [
    "CameraResponse",
    "emulate",
    "emulation_lut",
    "higher_no_sat",
    "closest",
    "select",
    "saturated_fraction",
    "SELECTORS",
    "ExposimError",
    "ResponseError",
    "DatasetError",
    "EmulationError",
    "OutputExistsError",
    "__version__",
]
