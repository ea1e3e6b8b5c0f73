"""A native-rate run's frames and ticks (:class:`~emulator.playback.native.NativeProvider`).

:class:`RecordedFrames` indexes a recording's frames of the first camera in time order (what each
has for every camera, and which frame each recorder cycle benchmarks); a :class:`NativeTick` is one
of them as the closed loop sees it: it selects the source frame of a target exposure
(:func:`emulator.core.native.native_select`) and makes the :class:`~emulator.playback.loop.Shot`,
with the :class:`NativeInfo` its row records.  A tick reads its provider through the provider's
public attributes and methods only (``frames``, ``images``, ``emulate``, ``excess_blur_px``, ...).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from emulator.core.native import NativeCandidate, invalid_fraction, native_select
from emulator.playback.emulated import clip_fractions, Memo
from emulator.playback.loop import Shot

if TYPE_CHECKING:  # the provider module imports this one
    from emulator.playback.native import NativeProvider

__all__ = ["NativeInfo", "NativeTick", "RecordedFrames"]


@dataclass(frozen=True)
class NativeInfo:
    """What a native-rate step adds to its row (``exposures.csv``'s native columns)."""

    recorder_cycle: int
    benchmarked: bool
    source_offset: int
    source_timestamp_ns: int
    warp_deg: float  #: rotation undone by the warp, degrees (0: own frame or at rest; NaN: not warped)


class RecordedFrames:
    """The recording's frames of the first camera, in time order, with what each has for every camera."""

    def __init__(self, sequence, cameras) -> None:
        lead = cameras[0]
        rows = []
        for cycle in sequence.cycles:
            for e, fr in cycle.frames.get(lead, {}).items():
                rows.append((int(fr.timestamp_ns), float(e), cycle))
        rows.sort(key=lambda r: r[0])
        self.timestamps = [r[0] for r in rows]
        self.exposures = [r[1] for r in rows]
        self.cycles = [r[2] for r in rows]
        # every camera's shot at this instant (same exposure, same timestamp)
        self.complete = [all(c in cyc.frames and cyc.frames[c].get(e) is not None
                             and int(cyc.frames[c][e].timestamp_ns) == ts for c in cameras)
                         for ts, e, cyc in rows]
        self.index = {ts: k for k, ts in enumerate(self.timestamps)}
        first = set()
        for cycle in sequence.cycles:  # the instant of the native-rate live condition (its first shot)
            avail = cycle.available(tuple(cameras))
            if avail:
                first.add(self.index.get(int(cycle.frames[lead][avail[0]].timestamp_ns)))
        self.benchmarked = first

    def __len__(self) -> int:
        return len(self.timestamps)


class NativeTick(Memo):
    """One recorded frame of a :class:`NativeProvider` (see :meth:`shot`)."""

    def __init__(self, provider: "NativeProvider", k: int, hidden: bool = False) -> None:
        p = self.provider = provider
        fr = p.frames
        self.index = k
        cycle, e = fr.cycles[k], fr.exposures[k]
        self.missing = {c: [e] for c in p.cameras if not (c in cycle.frames and e in cycle.frames[c])}
        lo, hi = max(0, k - p.window), min(len(fr) - 1, k + p.window)
        self.sources = [j for j in range(lo, hi + 1) if fr.complete[j] and not (hidden and j == k)]
        self.skipped = None if self.sources else "no frame within one cycle has every camera's shot"
        if self.skipped is None and p.skip_partial and cycle.missing_by_camera(p.cameras):
            self.skipped = "frame of a partial cycle left out (--skip-partial)"
        self._memo_init()

    def select(self, target_ms: float) -> int:
        """The source frame (index) of ``target_ms``."""
        p, fr = self.provider, self.provider.frames
        cands = []
        for j in self.sources:
            e = fr.exposures[j]
            _, hist = p.images(j).get(p.cameras[0], e)
            lost = invalid_fraction(hist, target_ms / e, white_level=p.white, black_level=p.black)
            excess = 0.0 if p.blur_stops_per_px is None else p.excess_blur_px(j, self.index, target_ms)
            cands.append(NativeCandidate(j - self.index, e, lost, excess))
        best = native_select(target_ms, cands, motion_stops_per_frame=p.motion_stops_per_frame,
                             saturation_limit=p.saturation_limit, blur_stops_per_px=p.blur_stops_per_px)
        return self.index + best.offset

    def shot(self, target_ms: float, want_right: bool = False) -> Shot:
        p, fr = self.provider, self.provider.frames
        k = self.index
        j = self._memo(("select", float(target_ms)), lambda: self.select(target_ms))
        e = fr.exposures[j]
        ratio = target_ms / e
        table, valid = p.response.lut(ratio)
        lead, other = p.cameras[0], (p.cameras[1] if len(p.cameras) > 1 else None)
        images = p.images(j)
        _, hist = images.get(lead, e)
        left, inside, angle = self._memo((lead, j, ratio), lambda: p.emulate(lead, j, k, ratio, table, target_ms))
        sat, val = clip_fractions(hist, table, valid, p.white, p.black)
        info = NativeInfo(int(fr.cycles[k].index), k in fr.benchmarked, j - k, fr.timestamps[j], angle)
        shot = Shot(timestamp_ns=fr.timestamps[k], exposure_ms=float(target_ms), bracket_ms=float(e), ratio=float(ratio),
                    left=left, saturated_fraction=sat, valid_fraction=val * inside,
                    bracket_saturated_fraction=images.saturated(lead, e),
                    missing_left_ms=tuple(self.missing.get(lead, ())),
                    missing_right_ms=tuple(self.missing.get(other, ())) if other else (), native=info)
        if other is not None:
            _, rhist = images.get(other, e)
            rsat, rval = clip_fractions(rhist, table, valid, p.white, p.black)
            shot.saturated_fraction_right, shot.valid_fraction_right = rsat, rval * inside
            if want_right:
                shot.right = self._memo((other, j, ratio),
                                        lambda: p.emulate(other, j, k, ratio, table, target_ms))[0]
        return shot
