"""exposim's emulator: the part that runs on real bracketed recordings.

numpy and OpenCV only; nothing here imports ``synth``, ``scenes`` or ``validation``
(the command line loads their sub-commands lazily).

The user verbs::

    import emulator as ex

    seq = ex.load_sequence("backpack_2023-09-25-15-05-03")     # a BorealHDR recording
    img = ex.emulate_image(raw, 4.0, 9.5, ex.sequence_response(seq))   # one image at 9.5 ms
    ms = ex.select_bracket("higher-no-sat", 9.5, {4.0: 0.0, 16.0: 0.2})
    res = ex.run(seq, "classical-50,shim", ex.RunConfig(initial_ms=4.0))   # closed loop, in memory
    ex.run_to_folder(seq, "all", "out/run", ex.RunConfig(save="png8"))    # ... written to a run folder
    m = ex.make_method("zhang", mode="paper")

The numeric modules live on the core floor (:mod:`emulator.core`): ``import emulator.core.select as s``
and ``import emulator.core.emulate as e`` give the modules, and so do ``emulator.select`` and
``emulator.emulate``, bound here.  Their functions are exported here under names that say what they act on:
:func:`select_bracket` (``emulator.core.select.select``) and :func:`emulate_image`
(``emulator.core.emulate.emulate``).  ``from emulator import emulate`` therefore gives the module
(as ``from emulator import select`` does); the function is ``from emulator.core.emulate import
emulate`` or ``emulator.emulate_image``.
"""

from emulator.autoexposure import make_method
from emulator.core import emulate, select  # the modules, as before the floors (see above)
from emulator.core.emulate import emulate as emulate_image
from emulator.core.emulate import emulation_lut
from emulator.errors import DatasetError, EmulationError, ExposimError, OutputExistsError, PlaybackError, ResponseError
from emulator.io.borealhdr import load_sequence, sequence_response
from emulator.playback import RunConfig, iter_run, run
from emulator.core.response import CameraResponse
from emulator.orchestration.runner import run_to_folder
from emulator.core.select import SELECTORS, closest, higher_no_sat, saturated_fraction
from emulator.core.select import select as select_bracket
from emulator.version import __version__

__all__ = [
    "load_sequence",
    "sequence_response",
    "emulate_image",
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
