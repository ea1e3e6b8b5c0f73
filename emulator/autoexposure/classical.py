"""Mean-brightness baselines of the paper: M_30, M_50, M_70 and M_fixed (spec sections 1-2).

``Classical`` drives the mean gray level towards a target with an additive proportional
step and a dead band; ``Fixed`` runs Classical-50 for the first few frames, then holds the
exposure forever.

Dynamics (spec section 1): on an unclipped linear scene, mean = k t, the error obeys
``e_{n+1} = (1 - K k) e_n``: monotone convergence for k < 500 DN/ms, oscillating for
500 <= k < 1000, no convergence above (a limit cycle in bright snow).
"""

from __future__ import annotations

import math

import numpy as np

from emulator.autoexposure.base import FULL_SCALE_DN, AutoExposureError, AutoExposureMethod

__all__ = [
    "Classical",
    "Fixed",
    "target_dn",
    "DEAD_BAND_DN",
    "GAIN_MS_PER_DN",
    "SAFE_FLOOR_MS",
    "N_AUTO_FRAMES",
    "FIXED_TARGET_PERCENT",
]

#: Half-width of the dead band around the target: |mean - T| < 15 DN keeps t.
DEAD_BAND_DN = 15.0
#: Proportional gain K of the additive step, in ms per DN of error.
GAIN_MS_PER_DN = 0.002
#: Paper mode replaces REF's ``abs(t - K e)`` by ``max(t - K e, SAFE_FLOOR_MS)``.
SAFE_FLOOR_MS = 0.02
#: M_fixed adjusts on this many frames (REF's ``number_frames_auto``), then holds.
N_AUTO_FRAMES = 3
#: M_fixed's brightness target, percent of full scale.
FIXED_TARGET_PERCENT = 50


def target_dn(percent: float, full_scale_dn: int = FULL_SCALE_DN) -> int:
    """Brightness target T = floor(p / 100 * 4096): 1228, 2048, 2867 for 30, 50, 70 %."""
    return int(math.floor(percent / 100.0 * full_scale_dn))


class Classical(AutoExposureMethod):
    """M_p: additive proportional control of the mean gray level (spec section 1).

    Parameters
    ----------
    target_percent : float
        Brightness target, percent of the 12-bit full scale (30, 50, 70 in the paper).
    mode : {"paper", "borealhdr"}
        borealhdr: over-exposure step ``|t - K e|`` (REF's ``abs``: an over-exposed image can
        *lengthen* t, e.g. t = 1 on an all-4095 frame gives 3.094).  paper:
        ``max(t - K e, SAFE_FLOOR_MS)`` (the spec's SAFE flag).
    range_ms : (float, float) or None
        Optional clamp of the output, ms (default: none in borealhdr mode).
    dead_band_dn, gain_ms_per_dn : float
        Dead band (DN) and gain K (ms/DN); defaults :data:`DEAD_BAND_DN`, :data:`GAIN_MS_PER_DN`.
    """

    def __init__(
        self,
        target_percent: float = 50,
        *,
        mode: str = "paper",
        range_ms="default",
        dead_band_dn: float = DEAD_BAND_DN,
        gain_ms_per_dn: float = GAIN_MS_PER_DN,
        floor_ms: float = SAFE_FLOOR_MS,
    ) -> None:
        super().__init__(mode=mode, range_ms=range_ms)
        if not (0 < float(target_percent) < 100):
            raise AutoExposureError(f"target_percent must lie in (0, 100), got {target_percent!r}")
        self.target_percent = float(target_percent)
        self.target_dn = target_dn(self.target_percent)
        self.dead_band_dn = float(dead_band_dn)
        self.gain_ms_per_dn = float(gain_ms_per_dn)
        self.floor_ms = float(floor_ms)
        self.name = f"classical-{self.target_percent:g}"

    def update(self, mean_dn: float, t: float) -> float:
        """The control law on a mean gray level (float) at exposure t (ms); may be 0."""
        e = float(mean_dn) - self.target_dn
        if abs(e) < self.dead_band_dn:
            return t
        step = t - self.gain_ms_per_dn * e
        if self.mode == "borealhdr":
            return abs(step)
        return max(step, self.floor_ms)

    def _step(self, raw: np.ndarray, t: float) -> float:
        mean = self.gray_mean(raw)
        self.last["mean_dn"] = mean
        return self.update(mean, t)

    def _options(self) -> dict:
        return {"target_percent": self.target_percent, "dead_band_dn": self.dead_band_dn,
                "gain_ms_per_dn": self.gain_ms_per_dn, "floor_ms": self.floor_ms}


class Fixed(AutoExposureMethod):
    """M_fixed: Classical-50 on the first frames, then the exposure is frozen (spec section 2).

    REF's counter test ``c <= number_frames_auto`` adjusts on the first ``N + 1 = 4`` calls
    (borealhdr mode); paper mode adjusts on exactly ``n_auto_frames`` calls.  Afterwards the
    input exposure is returned unchanged, whatever the image.

    ``latency_frames`` (L, frames; 0 at cycle rate) is the camera's exposure latency: a
    proposal made after frame k is applied from frame k + 1 + L (``--rate native``, whose run
    sets it from ``--latency-frames``).  With L > 0 the method adjusts only on every (L + 1)-th
    call, on a frame taken at its previous adjustment, and otherwise returns the last
    adjustment; once frozen it returns that value for ever.  Returning the input exposure
    instead would re-queue the proposals still in flight, a period-(L + 1) cycle between the
    last adjustments.  From frame ``n_adjustments * (L + 1)`` on every frame has one exposure.
    """

    name = "fixed"

    def __init__(self, *, mode: str = "paper", range_ms="default", n_auto_frames: int = N_AUTO_FRAMES,
                 latency_frames: int = 0) -> None:
        super().__init__(mode=mode, range_ms=range_ms)
        if int(n_auto_frames) < 0:
            raise AutoExposureError(f"n_auto_frames must be >= 0, got {n_auto_frames!r}")
        if isinstance(latency_frames, bool) or int(latency_frames) != latency_frames or int(latency_frames) < 0:
            raise AutoExposureError(f"latency_frames must be an integer >= 0, got {latency_frames!r}")
        self.n_auto_frames = int(n_auto_frames)
        self.latency_frames = int(latency_frames)
        self._inner = Classical(FIXED_TARGET_PERCENT, mode=mode, range_ms=None)
        self.count = 0
        self._seen = 0
        self._held: float | None = None

    @property
    def n_adjustments(self) -> int:
        """How many calls adjust the exposure: N + 1 in borealhdr mode (REF's ``<=``), N in paper mode."""
        return self.n_auto_frames + 1 if self.mode == "borealhdr" else self.n_auto_frames

    def _reset(self) -> None:
        self.count = 0
        self._seen = 0
        self._held = None

    def _step(self, raw: np.ndarray, t: float) -> float:
        if self.latency_frames:
            return self._step_late(raw, t)
        if self.count < self.n_adjustments:
            self.count += 1
            mean = self.gray_mean(raw)
            self.last["mean_dn"] = mean
            return self._inner.update(mean, t)
        self.last["frozen"] = True
        return t

    def _step_late(self, raw: np.ndarray, t: float) -> float:
        """With proposals in flight: adjust only on a frame taken at the previous adjustment, hold it otherwise."""
        phase = self._seen % (self.latency_frames + 1)
        self._seen += 1
        if self.count < self.n_adjustments and phase == 0:
            self.count += 1
            mean = self.gray_mean(raw)
            self.last["mean_dn"] = mean
            self._held = self._inner.update(mean, t)
            return self._held
        self.last["frozen" if self.count >= self.n_adjustments else "waiting"] = True
        return t if self._held is None else self._held

    def _options(self) -> dict:
        return {"n_auto_frames": self.n_auto_frames, **({"latency_frames": self.latency_frames}
                                                        if self.latency_frames else {})}
