"""The unit of an in-situ noise measurement: :class:`BracketGroup` (consecutive brackets of one sweep), and
:func:`bracket_groups`, which collects them from a recording."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from emulator.core.blur import exposure_window_s, predict_blur
from emulator.core.dataset import Sequence
from emulator.noise.model import NoiseModelError
from emulator.core.response import CameraResponse

__all__ = ["BracketGroup", "checked_groups", "bracket_groups"]


@dataclass(frozen=True)
class BracketGroup:
    """Two or three consecutive brackets of one sweep of one camera.

    Attributes
    ----------
    raws : tuple of ndarray, uint16 (H, W)
        Bayer mosaics in DN, in capture order.
    exposures_ms : tuple of float
        Their exposure times, ms.
    times_s : tuple of float or None
        Their capture instants, seconds (any origin), increasing; None means equally spaced.
    label : str
        Names the group in results (e.g. ``left c1 2-4-8``).

    Notes
    -----
    :meth:`weights` are the coefficients of the exposure-normalised images in the difference
    :func:`estimate_noise_model` measures: ``(-1, 1)`` for a pair; for a triple
    ``(-(tau_c - tau_b), tau_c - tau_a, -(tau_b - tau_a)) / (tau_c - tau_a)``, i.e. the middle
    shot minus the linear interpolation of the outer two to its instant, which cancels any
    motion (or illumination change) linear in time.
    """

    raws: tuple
    exposures_ms: tuple
    times_s: tuple | None = None
    label: str = ""

    @classmethod
    def pair(cls, raw_a, exposure_a_ms, raw_b, exposure_b_ms, label: str = "") -> "BracketGroup":
        return cls((raw_a, raw_b), (exposure_a_ms, exposure_b_ms), None, label)

    def weights(self) -> tuple[float, ...]:
        if len(self.raws) == 2:
            return (-1.0, 1.0)
        ta, tb, tc = (0.0, 1.0, 2.0) if self.times_s is None else (float(t) for t in self.times_s)
        span = tc - ta
        return (-(tc - tb) / span, 1.0, -(tb - ta) / span)


def checked_groups(groups, response: CameraResponse) -> list:
    """``groups`` as a list, each checked (:func:`estimate_noise_model`, Raises)."""
    groups = list(groups)
    if not groups:
        raise NoiseModelError("no bracket groups given")
    if not isinstance(response, CameraResponse):
        raise NoiseModelError(f"response must be an emulator CameraResponse, got {type(response).__name__}")
    for i, gr in enumerate(groups):
        where = f"group {i} ({getattr(gr, 'label', '') or 'unnamed'})"
        if not isinstance(gr, BracketGroup):
            raise NoiseModelError(f"{where}: expected a BracketGroup, got {type(gr).__name__}")
        if len(gr.raws) not in (2, 3) or len(gr.exposures_ms) != len(gr.raws):
            raise NoiseModelError(f"{where}: need 2 or 3 images with one exposure each, got {len(gr.raws)} images "
                                  f"and {len(gr.exposures_ms)} exposures")
        for raw in gr.raws:
            if not isinstance(raw, np.ndarray) or raw.dtype != np.uint16 or raw.ndim != 2:
                raise NoiseModelError(f"{where}: images must be 2-D uint16 Bayer mosaics")
            if raw.shape != gr.raws[0].shape:
                raise NoiseModelError(f"{where}: shapes differ ({raw.shape} vs {gr.raws[0].shape})")
            if int(raw.max()) > response.white_level:
                raise NoiseModelError(f"{where}: DN {int(raw.max())} above the response's white level "
                                      f"{response.white_level}")
        if min(gr.raws[0].shape) < 16:
            raise NoiseModelError(f"{where}: images too small ({gr.raws[0].shape})")
        for t in gr.exposures_ms:
            if not (isinstance(t, (int, float, np.floating, np.integer)) and math.isfinite(t) and t > 0):
                raise NoiseModelError(f"{where}: exposure {t!r} must be finite and > 0 ms")
        if gr.times_s is not None:
            times = np.asarray(gr.times_s, dtype=np.float64)
            if times.shape != (len(gr.raws),) or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
                raise NoiseModelError(f"{where}: times_s must be one finite, increasing instant per image, "
                                      f"got {gr.times_s!r}")
    return groups


def bracket_groups(sequence, *, size: int = 3, cameras=None, cycles=None, max_groups: int | None = None,
                   max_gap: float = 1.5, progress=None, motion=None, max_motion_px: float | None = None
                   ) -> list[BracketGroup]:
    """Groups of ``size`` (2 or 3) consecutive shots of every sweep of a recording, images loaded.

    Parameters
    ----------
    sequence : emulator.core.dataset.Sequence
        The recording (:func:`emulator.io.borealhdr.load_sequence`).
    size : int
        3 (default): triples, whose time-interpolated difference cancels motion linear in
        time; 2: pairs of neighbouring brackets.
    cameras : sequence of str or None
        Cameras to use (default: all of the sequence's).
    cycles : iterable of int or None
        Cycle indices to use (default: all).
    max_groups : int or None
        At most this many groups, spread evenly over the candidates (deterministic).
    max_gap : float
        Shots of a group must follow each other within ``max_gap`` shot periods (the median
        interval between shots): a missing bracket breaks a group.
    progress : callable(done, total, label), optional
        Called after each group's images are loaded.
    motion, max_motion_px : emulator.playback.motion.RecordingMotion, float, optional
        Keep only groups over whose whole span (first shot's start to last shot's end) the
        gyro turns the image by at most ``max_motion_px`` pixels (largest over the image):
        the still frames, for a fit robust to motion.  A group the gyro does not cover is kept.

    Returns
    -------
    list of BracketGroup
        Capture order within a group; ``times_s`` from the file timestamps.
    """
    if not isinstance(sequence, Sequence):
        raise NoiseModelError(f"sequence must be an emulator.core.dataset.Sequence, got {type(sequence).__name__}")
    if size not in (2, 3):
        raise NoiseModelError(f"size must be 2 (pairs) or 3 (triples), got {size!r}")
    cams = tuple(sequence.cameras if cameras is None else cameras)
    unknown = [c for c in cams if c not in sequence.cameras]
    if unknown:
        raise NoiseModelError(f"{sequence.path}: no camera {', '.join(map(repr, unknown))} "
                              f"(has {', '.join(sequence.cameras)})")
    wanted = None if cycles is None else {int(c) for c in cycles}
    stamps = sorted({f.timestamp_ns for c in sequence for cam in cams for f in c.frames.get(cam, {}).values()})
    period = float(np.median(np.diff(stamps))) if len(stamps) > 1 else 0.0
    candidates = []
    for cycle in sequence:
        if wanted is not None and cycle.index not in wanted:
            continue
        for cam in cams:
            shots = sorted(cycle.frames.get(cam, {}).values(), key=lambda f: f.timestamp_ns)
            for k in range(len(shots) - size + 1):
                win = shots[k: k + size]
                gaps = np.diff([f.timestamp_ns for f in win])
                if period > 0 and np.any(gaps > max_gap * period):
                    continue
                if motion is not None and max_motion_px is not None and \
                        _span_motion_px(motion, cam, win) > max_motion_px:
                    continue
                candidates.append((cam, cycle.index, win))
    if max_groups is not None and len(candidates) > max_groups:
        pick = np.unique(np.round(np.linspace(0, len(candidates) - 1, int(max_groups))).astype(int))
        candidates = [candidates[i] for i in pick]
    groups = []
    for cam, index, win in candidates:
        t0 = win[0].timestamp_ns
        groups.append(BracketGroup(
            tuple(f.load() for f in win), tuple(float(f.exposure_ms) for f in win),
            tuple((f.timestamp_ns - t0) * 1e-9 for f in win),
            f"{cam} c{index} " + "-".join(f"{f.exposure_ms:g}" for f in win)))
        if progress is not None:
            progress(len(groups), len(candidates), f"loading {groups[-1].label}")
    return groups


def _span_motion_px(motion, camera: str, shots) -> float:
    """Image motion (px, path length, largest over the image) over a group's span; 0 where unknown."""
    t0 = min(exposure_window_s(motion.t_s(f.timestamp_ns), f.exposure_ms, motion.stamp)[0] for f in shots)
    t1 = max(exposure_window_s(motion.t_s(f.timestamp_ns), f.exposure_ms, motion.stamp)[1] for f in shots)
    K, size = motion.K(camera)
    px = predict_blur(motion.omega, K, size, t0, (t1 - t0) * 1e3, "start").max_px
    return px if math.isfinite(px) else 0.0
