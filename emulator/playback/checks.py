"""The checks of a run's settings: :func:`checked_fields` checks every field of a
:class:`~emulator.playback.config.RunConfig` once, in field order, and refuses a bad one with a
:class:`~emulator.errors.PlaybackError` naming it; no other place repeats these checks.

The limits the checks apply (:data:`MODES`, :data:`WORKER_MODES`, :data:`MAX_METHOD_TIMEOUT_S`,
:data:`MAX_LATENCY_FRAMES`) are declared here; :mod:`emulator.playback.config` gives them too.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from emulator.core.blur import BLUR_MODES
from emulator.core.emulate import NOISE_MODES
from emulator.core.native import DEFAULT_NATIVE_WARP, NATIVE_RATE, RATES, WARP_MODES
from emulator.core.select import SELECTORS
from emulator.errors import PlaybackError
from emulator.io.runfolder import SAVE_MODES

__all__ = ["MODES", "WORKER_MODES", "MAX_METHOD_TIMEOUT_S", "MAX_LATENCY_FRAMES", "checked_fields", "number"]

MODES = ("paper", "borealhdr")
#: ``process``: each method in its own worker process (the default); ``inline``: in the run's process.
WORKER_MODES = ("process", "inline")
#: Longest per-call limit, s: the longest wait the system's poll() takes (2**31 - 1 ms, 24.8 days).
MAX_METHOD_TIMEOUT_S = 2_147_483.0
#: Largest exposure latency, frames (a recording's frame count bounds it further, at native rate).
MAX_LATENCY_FRAMES = 1_000_000


def number(value, name: str) -> float:
    """``value`` as a float; a bool or what is not a number raises :class:`PlaybackError` naming ``name``."""
    if isinstance(value, bool):
        raise PlaybackError(f"{name} must be a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise PlaybackError(f"{name} must be a number, got {value!r}") from None


def _is_int(value) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, np.integer))


def checked_fields(config) -> dict[str, Any]:
    """The fields of ``config`` as checking normalises them (floats, ints, a ``(low, high)`` tuple, plain
    dicts, strings for paths, the native warp's default), every field checked in field order.

    ``native_warp`` None becomes :data:`~emulator.core.native.DEFAULT_NATIVE_WARP` at native rate, and that
    default carried over to cycle rate becomes None.  A bad value raises :class:`PlaybackError` naming the field.
    """
    c, out = config, {}
    initial = number(c.initial_ms, "initial_ms")
    if not (math.isfinite(initial) and initial > 0):
        raise PlaybackError(f"initial_ms must be a finite, positive number of ms, got {c.initial_ms!r}")
    out["initial_ms"] = initial
    try:
        lo, hi = (float(v) for v in c.range_ms)
    except (TypeError, ValueError):
        raise PlaybackError(f"range_ms must be (low_ms, high_ms), got {c.range_ms!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
        raise PlaybackError(f"range_ms must satisfy 0 < low <= high (ms), got {c.range_ms!r}")
    out["range_ms"] = (lo, hi)
    if c.selector not in SELECTORS:
        raise PlaybackError(f"unknown selector {c.selector!r}; choose one of {', '.join(SELECTORS)}")
    if c.mode not in MODES:
        raise PlaybackError(f"mode must be one of {', '.join(MODES)}, got {c.mode!r}")
    if not isinstance(c.options, Mapping) or not all(isinstance(v, Mapping) for v in c.options.values()):
        raise PlaybackError(f"options must map a method name to {{key: value}}, got {c.options!r}")
    out["options"] = {str(k): dict(v) for k, v in c.options.items()}
    if not _is_int(c.jobs) or int(c.jobs) < 1:
        raise PlaybackError(f"jobs must be an integer >= 1, got {c.jobs!r}")
    out["jobs"] = int(c.jobs)
    if c.workers not in WORKER_MODES:
        raise PlaybackError(f"workers must be process or inline, got {c.workers!r}")
    if c.save not in SAVE_MODES:
        raise PlaybackError(f"save must be one of {', '.join(SAVE_MODES)}, got {c.save!r}")
    if c.noise not in NOISE_MODES:
        raise PlaybackError(f"noise must be one of {', '.join(NOISE_MODES)}, got {c.noise!r}")
    if not _is_int(c.noise_seed) or c.noise_seed < 0:
        raise PlaybackError(f"noise_seed must be a non-negative integer, got {c.noise_seed!r}")
    out["noise_seed"] = int(c.noise_seed)
    if c.method_timeout_s is not None:
        out["method_timeout_s"] = _checked_timeout(c.method_timeout_s)
    if c.response_path is not None:
        out["response_path"] = str(c.response_path)
    if not _is_int(c.png_level) or not 0 <= c.png_level <= 9:
        raise PlaybackError(f"png_level must be an integer 0..9, got {c.png_level!r}")
    out["png_level"] = int(c.png_level)
    if c.blur not in BLUR_MODES:
        raise PlaybackError(f"blur must be one of {', '.join(BLUR_MODES)}, got {c.blur!r}")
    out["blur_aware"] = bool(c.blur_aware)
    if out["blur_aware"] and c.blur != "consistent":
        raise PlaybackError("blur_aware: the blur-aware selection needs blur 'consistent' (--blur consistent)")
    if out["blur_aware"] and c.selector != "higher-no-sat":
        raise PlaybackError(f"blur_aware: the blur-aware selection refines selector higher-no-sat, not "
                            f"{c.selector!r}")
    if not isinstance(c.skip_partial, (bool, np.bool_)):
        raise PlaybackError(f"skip_partial must be true or false, got {c.skip_partial!r}")
    out["skip_partial"] = bool(c.skip_partial)
    if isinstance(c.noise_model, Path):
        out["noise_model"] = str(c.noise_model)
    out.update(_checked_rate(c))
    return out


def _checked_timeout(given) -> float:
    value = number(given, "method_timeout_s")
    if not (math.isfinite(value) and value > 0):
        raise PlaybackError(f"method_timeout_s must be finite and positive (seconds), got {given!r}")
    if value > MAX_METHOD_TIMEOUT_S:
        raise PlaybackError(f"method_timeout_s must be at most {MAX_METHOD_TIMEOUT_S:.0f} s (24.8 days, the "
                            f"longest wait the system's poll() takes), got {given!r}")
    return value


def _checked_rate(c) -> dict[str, Any]:
    """``rate``, ``latency_frames``, ``native_warp`` and ``native_blur_aware``, checked together."""
    if c.rate not in RATES:
        raise PlaybackError(f"rate must be one of {', '.join(RATES)}, got {c.rate!r}")
    lat = c.latency_frames
    if not _is_int(lat) or not 0 <= lat <= MAX_LATENCY_FRAMES:
        raise PlaybackError(f"latency_frames must be an integer >= 0, at most {MAX_LATENCY_FRAMES} and below "
                            f"the recording's frame count, got {lat!r}")
    native = c.rate == NATIVE_RATE
    warp = c.native_warp
    if warp is None and native:
        warp = DEFAULT_NATIVE_WARP
    elif not native and warp == DEFAULT_NATIVE_WARP:  # a native run's default, carried over (a resume asked
        warp = None  # at cycle rate is refused for its rate)
    if warp is not None and warp not in WARP_MODES:
        raise PlaybackError(f"native_warp must be one of {', '.join(WARP_MODES)}, got {warp!r}")
    blur_aware = bool(c.native_blur_aware)
    if not native and (warp not in (None, "rotation") or blur_aware):
        raise PlaybackError("native_warp and native_blur_aware: used only at native rate (--rate native)")
    return {"latency_frames": int(lat), "native_warp": warp, "native_blur_aware": blur_aware}
