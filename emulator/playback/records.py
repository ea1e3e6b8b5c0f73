"""What a closed loop yields and keeps: :class:`MethodStep`, :class:`CycleStep`, :class:`RunStats`, :class:`RunResult`."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np

__all__ = ["MethodStep", "CycleStep", "RunStats", "RunResult"]


# ============================================================================ records
@dataclass
class MethodStep:
    """What one method did in one cycle (its CSV row: :func:`emulator.io.runfolder.format_row`)."""

    method: str
    cycle: int
    timestamp_ns: int
    target_ms: float
    bracket_ms: float
    ratio: float
    saturated_fraction: float
    valid_fraction: float
    next_ms: float
    proposed_ms: float
    guarded: bool
    clamped: bool
    bracket_saturated_fraction: float
    saturated_fraction_right: float | None = None
    valid_fraction_right: float | None = None
    missing_left_ms: tuple[float, ...] = ()
    missing_right_ms: tuple[float, ...] = ()
    left: np.ndarray | None = field(default=None, repr=False)
    right: np.ndarray | None = field(default=None, repr=False)
    #: Native rate: the frame's recorder cycle, source frame and warp (:class:`~emulator.playback.native.NativeInfo`).
    native: object = None


@dataclass
class CycleStep:
    """One cycle of a run: each method's step, or why the cycle was skipped."""

    cycle: int
    steps: dict[str, MethodStep]
    missing: dict[str, list[float]]
    skipped: str | None = None
    #: Methods that failed in this cycle (no step; dropped from later cycles): name -> reason.
    failed: dict[str, str] = field(default_factory=dict)


@dataclass
class RunStats:
    """Counters and timers of a run (wall-clock seconds; thread-safe)."""

    decodes: int = 0
    decode_s: float = 0.0
    histogram_s: float = 0.0
    emulate_s: float = 0.0
    emulations: int = 0
    method_s: dict[str, float] = field(default_factory=dict)
    method_calls: dict[str, int] = field(default_factory=dict)
    cycles: int = 0
    wall_s: float = 0.0
    #: Seconds from the start of the run to the end of its first cycle (set-up, first decodes, first tables).
    startup_s: float | None = None
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def add(self, name: str, seconds: float, count: int = 1) -> None:
        with self._lock:
            setattr(self, name, getattr(self, name) + seconds)
            if name == "decode_s":
                self.decodes += count
            elif name == "emulate_s":
                self.emulations += count

    def add_method(self, method: str, seconds: float) -> None:
        with self._lock:
            self.method_s[method] = self.method_s.get(method, 0.0) + seconds
            self.method_calls[method] = self.method_calls.get(method, 0) + 1

    def as_dict(self) -> dict:
        def per(total, n):
            return 1000.0 * total / n if n else None

        return {
            "cycles": self.cycles,
            "wall_s": self.wall_s,
            "cycles_per_s": self.cycles / self.wall_s if self.wall_s > 0 else None,
            "startup_s": self.startup_s,
            "steady_cycles": max(self.cycles - 1, 0),
            "steady_cycles_per_s": ((self.cycles - 1) / (self.wall_s - self.startup_s)
                                    if self.startup_s is not None and self.cycles > 1
                                    and self.wall_s > self.startup_s else None),
            "decodes": self.decodes,
            "decode_ms_per_image": per(self.decode_s, self.decodes),
            "emulations": self.emulations,
            "emulate_ms_per_image": per(self.emulate_s, self.emulations),
            "method_ms_per_frame": {m: per(s, self.method_calls.get(m, 0)) for m, s in self.method_s.items()},
        }


@dataclass
class RunResult:
    """In-memory result of :func:`run`: per-method steps (images dropped) and skipped cycles."""

    steps: dict[str, list[MethodStep]]
    skipped: list[tuple[int, str]]
    methods: dict
    stats: RunStats
    #: Methods that failed: name -> "failed: <reason> at cycle N" (their steps stop before N).
    failed: dict[str, str] = field(default_factory=dict)

    def column(self, method: str, name: str) -> np.ndarray:
        """One field of every step of ``method`` as an array (e.g. ``"target_ms"``)."""
        return np.array([getattr(s, name) for s in self.steps[method]])
