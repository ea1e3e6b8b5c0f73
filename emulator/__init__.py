"""exposim's emulator: the part that runs on real bracketed recordings.

numpy and OpenCV only; nothing here imports ``synth``, ``scenes`` or ``validation``
(the command line loads their sub-commands lazily).

The user verbs::

    import emulator as ex

    seq = ex.load_sequence("backpack_2023-09-25-15-05-03")     # a BorealHDR recording
    img = ex.emulate(raw, 4.0, 9.5, ex.sequence_response(seq))   # one image at 9.5 ms
    ms = ex.select_bracket("higher-no-sat", 9.5, {4.0: 0.0, 16.0: 0.2})
    res = ex.run(seq, "classical-50,shim", ex.RunConfig(initial_ms=4.0))   # closed loop, in memory
    ex.run_to_folder(seq, "all", "out/run", ex.RunConfig(save="png8"))    # ... written to a run folder
    m = ex.make_method("zhang", mode="paper")

Submodules keep their names: ``import emulator.select as s`` gives the module (the selector
function is :func:`select_bracket` here).  The package-level ``emulate`` is the function; its
module is reached by ``from emulator.emulate import ...``.
"""

from emulator.autoexposure import make_method
from emulator.emulate import emulate, emulation_lut
from emulator.errors import DatasetError, EmulationError, ExposimError, OutputExistsError, PlaybackError, ResponseError
from emulator.io.borealhdr import load_sequence, sequence_response
from emulator.playback import RunConfig, iter_run, run
from emulator.response import CameraResponse
from emulator.runner import run_to_folder
from emulator.select import SELECTORS, closest, higher_no_sat, saturated_fraction
from emulator.select import select as select_bracket
from emulator.version import __version__

__all__ = [
    "load_sequence",
    "sequence_response",
    "emulate",
    "emulation_lut",
    "select_bracket",
    "run",
    "iter_run",
    "run_to_folder",
    "make_method",
    "RunConfig",
    "CameraResponse",
    "higher_no_sat",
    "closest",
    "saturated_fraction",
    "SELECTORS",
    "ExposimError",
    "ResponseError",
    "DatasetError",
    "EmulationError",
    "OutputExistsError",
    "PlaybackError",
    "__version__",
]
