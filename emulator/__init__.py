"""exposim's emulator: the part that runs on real bracketed recordings.

numpy and OpenCV only; nothing here imports ``synth``, ``scenes`` or ``validation``
(the command line loads their sub-commands lazily).
"""

from emulator.emulate import emulate, emulation_lut
from emulator.errors import DatasetError, EmulationError, ExposimError, OutputExistsError, ResponseError
from emulator.response import CameraResponse
from emulator.select import SELECTORS, closest, higher_no_sat, saturated_fraction, select

__version__ = "0.1.0"

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
