"""Closed-loop playback of AE methods (paper sections III-B, V-D): one configuration, one loop.

* :mod:`~emulator.playback.config`: :class:`RunConfig`, the run's settings, validated once,
  written to and read from ``run.json``, and the ``--resume`` rule;
* :mod:`~emulator.playback.loop`: :func:`closed_loop`, the one loop (image provider -> AE
  method -> next exposure), with :mod:`~emulator.playback.seam`'s :func:`call_method` the one
  place a method is asked;
* providers: :mod:`~emulator.playback.emulated` (the brackets of a recording, emulated at
  each target: offline, once per cycle), :mod:`~emulator.playback.native` (every recorded frame,
  from its own or a nearby frame's bracket, warped by the gyro: ``--rate native``),
  :mod:`~emulator.playback.live` (live shots once per cycle, or at a
  camera's own frame rate with an exposure latency);
* :mod:`~emulator.playback.offline`: :func:`iter_run` and :func:`run` on a recording;
* :mod:`~emulator.playback.records`: :class:`MethodStep`, :class:`CycleStep`, :class:`RunStats`,
  :class:`RunResult`.

For each cycle (one sweep of the brackets) and each method: the method's current target
exposure selects a bracket (among the brackets present for both cameras; the **left**
camera's saturation decides), the emulator renders the left and right images at the target
from that bracket, the method reads the emulated left image and proposes the next exposure,
which is clamped to the configured range.  Every method starts from the same initial
exposure.  The timestamp of an emulated image is the timestamp of the bracket it came from,
so a stereo pair always comes from one capture instant.  Results do not depend on
``jobs`` nor on the machine's cores (each cycle's methods run under one BLAS thread,
:mod:`emulator.pools`).  A run written to a run folder (with ``resume``) is
:mod:`emulator.orchestration.runner`; the folder's layout, writer and reader are
:mod:`emulator.io.runfolder`.  The clamp default is
:data:`emulator.autoexposure.DEFAULT_RANGE_MS`, shared with the paper-mode methods.

``saturated_fraction`` and ``valid_fraction`` describe the emulated left image the method
saw: pixels at or below black or at or above white, and pixels whose source carried the
information the target needs (see :func:`emulator.core.emulate.emulate`).  Nothing here prints.
"""

from emulator.autoexposure import DEFAULT_RANGE_MS
from emulator.errors import PlaybackError
from emulator.playback.config import (
    DEFAULT_INITIAL_MS,
    DEFAULT_SELECTOR,
    SAVE_MODES,
    RunConfig,
    parse_option,
    parse_options,
)
from emulator.playback.emulated import METHOD_CAMERA, EmulatedProvider
from emulator.playback.live import BOREALHDR_FRAME_RATE_HZ, LiveCycleProvider, LiveRateProvider
from emulator.playback.loop import Shot, closed_loop
from emulator.playback.native import NativeProvider
from emulator.playback.offline import at_rate, iter_run, prepare_run, resolve_sequence, run
from emulator.playback.records import CycleStep, MethodStep, RunResult, RunStats
from emulator.playback.seam import MethodAnswer, call_method, clamp, guard_exposure

__all__ = [
    "RunConfig",
    "parse_option",
    "parse_options",
    "run",
    "iter_run",
    "prepare_run",
    "at_rate",
    "NativeProvider",
    "resolve_sequence",
    "closed_loop",
    "call_method",
    "MethodAnswer",
    "Shot",
    "EmulatedProvider",
    "LiveCycleProvider",
    "LiveRateProvider",
    "BOREALHDR_FRAME_RATE_HZ",
    "MethodStep",
    "CycleStep",
    "RunResult",
    "RunStats",
    "PlaybackError",
    "DEFAULT_INITIAL_MS",
    "DEFAULT_SELECTOR",
    "DEFAULT_RANGE_MS",
    "SAVE_MODES",
    "METHOD_CAMERA",
    "guard_exposure",
    "clamp",
]
