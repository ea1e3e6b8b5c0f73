"""The published BorealHDR loop's frames, and exposim's methods driven on them.

The published code (``scripts/emulator_threads.py`` of norlab-ulaval/BorealHDR, "REF") runs
each AE method in closed loop on its own emulated images: it pairs the bracket folders of the
left camera *by file index* (column k = the k-th file of every sorted folder), emulates the
target from the "closer_least_sat" bracket through ``scipy.interpolate.interp1d`` response
curves, truncates to ``uint16``, and hands the Bayer mosaic to the method.  Column k's
proposal is the exposure of column k + 1; the last column is never shown.

``scripts/published_sequences.py`` runs that code itself (from a checkout given on the command
line: no published code is part of exposim) and stores every method's exposure sequence, with
the dependency versions, in ``tests/validation/data/published_sequences.json``.  This module re-creates the
loop's *frames* from the description above (:class:`PublishedFrames`), so that a test can drive
exposim's methods in ``borealhdr`` mode through exactly those frames (:func:`drive`) and compare
their proposals with the stored sequences: any drift of a method, or of this re-creation, shows.

Kim's optimizer restarts draw from NumPy's global random state in REF; the stored runs seed it
with ``np.random.seed(s)`` before the method is built, which exposim's ``Kim2018(seed=s)``
(``restart_seeding="stream"``) reproduces draw for draw.

:func:`replay_layout` builds a longer recording from few frames (links with increasing names),
so the CI, which has only the shared sample's first sweeps, still checks long sequences.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from emulator.autoexposure.base import MAX_DN
from emulator.core.levels import BOREALHDR_LEVELS

__all__ = ["REF_BRACKETS_MS", "REF_INITIAL_MS", "REF_METHODS", "PublishedFrames", "columns", "drive",
           "make_ref_method", "replay_layout", "sequences_equal"]

#: REF's BRACKETING_VALUES (ms), in the order of its dataframe rows.
REF_BRACKETS_MS = (1.0, 2.0, 4.0, 8.0, 16.0, 32.0)
#: REF's ``exposure_time_init`` (parameters.yaml).
REF_INITIAL_MS = 4.0
#: REF's method names (``automatic_exposure_techniques``) -> exposim's.
REF_METHODS = {"fixed-0": "fixed", "classical-30": "classical-30", "classical-50": "classical-50",
               "classical-70": "classical-70", "shim-0": "shim", "zhang-0": "zhang", "kim-0": "kim"}
#: REF's saturation test (``update_saturation_levels``): exactly the sample's black or white level.
_REF_BLACK, _REF_WHITE = BOREALHDR_LEVELS.black, BOREALHDR_LEVELS.white
#: REF's 12-bit full scale (its response curves' DN and radiance range).
_REF_TOP = MAX_DN


def columns(camera_dir: Path, brackets_ms: Sequence[float] = REF_BRACKETS_MS) -> list[list[Path]]:
    """REF's ``create_dataframe`` pairing: column k holds the k-th file (sorted by name) of every
    bracket folder ``camera_dir/<ms>/``; as many columns as the shortest folder has files."""
    lists = [sorted(os.listdir(Path(camera_dir, str(float(b))))) for b in brackets_ms]
    n = min(len(x) for x in lists)
    return [[Path(camera_dir, str(float(b)), lists[i][k]) for i, b in enumerate(brackets_ms)] for k in range(n)]


class PublishedFrames:
    """REF's ``Image_Emulator(path, "radiance", "closer_least_sat", color_bayer=True)``.

    ``pcalib`` is the inverse-response file REF reads (``calibration_files/pcalib_inside1.txt``):
    256 values over DN ``linspace(0, 4095, 256)``, times 16, its ends forced to 0 and 4095.
    """

    def __init__(self, pcalib: Path, brackets_ms: Sequence[float] = REF_BRACKETS_MS) -> None:
        from scipy.interpolate import interp1d

        from emulator.io.pcalib import read_pcalib

        dn = np.linspace(0, _REF_TOP, 256)
        irradiance = np.array(read_pcalib(pcalib), dtype=np.float64) * 16.0
        irradiance[0] = 0
        irradiance[-1] = _REF_TOP
        self.icrf = interp1d(dn, irradiance, kind="linear", fill_value=(0, _REF_TOP))
        self.crf = interp1d(irradiance, dn, kind="linear", fill_value=(0, _REF_TOP))
        self.brackets_ms = np.array(sorted(float(b) for b in brackets_ms))

    def select(self, images: Sequence[np.ndarray], target_ms: float) -> int:
        """closer_least_sat: the first bracket >= target, one lower when its saturated fraction
        exceeds the lower one's; above every bracket, the last."""
        sat = np.array([((im == _REF_BLACK).sum() + (im == _REF_WHITE).sum()) / im.size for im in images])
        higher = np.where(self.brackets_ms >= float(target_ms))[0]
        idx = int(higher[0]) if len(higher) else -1
        if idx not in (0, -1) and sat[idx] > sat[idx - 1]:
            idx -= 1
        return len(self.brackets_ms) - 1 if idx == -1 else idx

    def emulate(self, images: Sequence[np.ndarray], target_ms: float) -> tuple[np.ndarray, float]:
        """(the emulated uint16 mosaic, the source bracket in ms) for one column's images."""
        idx = self.select(images, target_ms)
        factor = target_ms / float(self.brackets_ms[idx])
        radiance = np.clip(self.icrf(images[idx]) * factor, 0, _REF_TOP)
        return self.crf(radiance.astype(np.float64)).astype(np.uint16), float(self.brackets_ms[idx])


def make_ref_method(ref_name: str, *, seed: int = 0, pcalib: Path | None = None):
    """exposim's method in borealhdr mode for a REF method name (``kim-0``: ``seed`` is REF's
    ``np.random.seed``); zhang gets the response REF's Zhang reads (``pcalib``)."""
    from emulator.autoexposure.builtin import make_method

    name = REF_METHODS[ref_name]
    opts: dict = {"mode": "borealhdr", "range_ms": None}
    if name == "kim":
        opts["seed"] = seed
    if name == "zhang":
        from emulator.io.pcalib import read_response

        opts["response"] = read_response(pcalib) if pcalib is not None else None
    return make_method(name, **opts)


def drive(method, camera_dir: Path, pcalib: Path, *, initial_ms: float = REF_INITIAL_MS,
          frames: PublishedFrames | None = None, cache: dict | None = None) -> dict:
    """Run ``method`` (exposim's ``next_exposure``) through REF's loop on ``camera_dir``.

    Returns ``{"exposures_ms": [initial, p_0, ...], "source_ms": [...]}`` as the published
    script records them (one proposal per column but the last).  ``cache`` keeps decoded
    columns between methods.
    """
    from emulator.io.png import read_png16

    frames = frames or PublishedFrames(pcalib)
    cache = {} if cache is None else cache
    cols = columns(camera_dir, frames.brackets_ms)
    t, out, used = float(initial_ms), [float(initial_ms)], []
    for k in range(len(cols) - 1):
        key = tuple(str(p) for p in cols[k])
        if key not in cache:
            cache[key] = [read_png16(p, white_level=_REF_TOP) for p in cols[k]]
        img, src = frames.emulate(cache[key], t)
        used.append(src)
        t = float(method.next_exposure(img, t))
        out.append(t)
    return {"exposures_ms": out, "source_ms": used}


def replay_layout(camera_dir: Path, out_dir: Path, pattern: Sequence[int],
                  brackets_ms: Sequence[float] = REF_BRACKETS_MS) -> Path:
    """A longer camera folder from few frames: column j of ``out_dir`` links to column
    ``pattern[j]`` of ``camera_dir`` (REF's pairing), under names that sort in j's order.
    Returns ``out_dir`` (``out_dir/<ms>/<j>.png``)."""
    src = columns(camera_dir, brackets_ms)
    for b in brackets_ms:
        Path(out_dir, str(float(b))).mkdir(parents=True, exist_ok=True)
    for j, k in enumerate(pattern):
        for i, b in enumerate(brackets_ms):
            link = Path(out_dir, str(float(b)), f"{j:06d}.png")
            if not link.exists():
                os.symlink(Path(src[k][i]).resolve(), link)
    return Path(out_dir)


def sequences_equal(ours: Mapping, ref: Mapping, rel: float = 0.0) -> bool:
    """Whether two ``exposures_ms`` lists agree (exactly, or to ``rel`` relative)."""
    a, b = list(ours["exposures_ms"]), list(ref["exposures_ms"])
    return len(a) == len(b) and all(abs(x - y) <= rel * max(abs(x), abs(y)) for x, y in zip(a, b))
