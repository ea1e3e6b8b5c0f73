"""Sizes of the blur study (full and ``--quick``)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from validation.common import ValidationError

__all__ = ["BlurConfig", "default_real_imu"]


def default_real_imu() -> str | None:
    """The shared BorealHDR sample's ``imu/imu.csv`` (``../shared`` beside the repository), if there."""
    root = Path(__file__).resolve().parents[2]
    for parent in (root, *root.parents):  # ../shared; from a git worktree the first shared/ further up
        base = parent / "shared" / "data" / "borealhdr_sample"
        found = sorted(base.glob("*/imu/imu.csv")) if base.is_dir() else []
        if found:
            return str(found[0])
    return None


@dataclass(frozen=True)
class BlurConfig:
    """What the blur study measures, and at which size.

    Attributes
    ----------
    scene : str
        Walkable scene of every measurement.
    walk : str
        Walk preset (:func:`scenes.walks.make_walk`).
    width, height : int
        Image size of the reference measurement and of the render cost.
    sharpness_width, sharpness_height : int
        Image size of the sharpness comparison (default the BorealHDR camera's 1920x1200: at
        480x300 a 32 ms frame at the walk's median turn rate blurs by about 2 px, and the
        sharpness measure scatters by +-2-3 % between instants, as much as the blur changes it).
    spp : int
        Samples per pixel of the blurred shots (raw path tracing: the reference is raw too).
    reference_subinstants, reference_spp : int
        Brute-force reference: this many sub-instant renders per half, each at this spp.
    exposure_ms : float
        Exposure of the reference comparison and of the live capture.
    source_ms : float
        Bracket the emulated frame of the sharpness comparison comes from.
    n_instants : int
        Shot instants of the reference and sharpness comparisons (the fastest-turning
        instants of the walk's first ``walk_s`` seconds, at least 0.3 s apart).
    walk_s : float
        Length of the walk the rates are measured on, s.
    timing_repeats : int
        Timings per frame kind (median kept).
    sharpness_denoise : str
        Denoiser of the sharpness renders.
    real_imu : str or None
        The real gyro (BorealHDR ``imu.csv``); None: the shared sample's when present.
    versus_walks, versus_cycles, versus_spp : int
        Live against emulated (:mod:`validation.blur.versus`): walks (seeds from ``seed``),
        bracket sweeps per walk, samples per pixel of its renders (0 walks: not measured).
    versus_methods : tuple of str
        AE methods of that table.
    versus_initial_ms, versus_vo_ratio : float
        Their initial exposure, and the Lowe ratio of the stereo VO.
    """

    scene: str = "forest_summer"
    walk: str = "borealhdr"
    width: int = 480
    height: int = 300
    sharpness_width: int = 1920
    sharpness_height: int = 1200
    spp: int = 16
    reference_subinstants: int = 32
    reference_spp: int = 16
    exposure_ms: float = 32.0
    source_ms: float = 8.0
    n_instants: int = 4
    walk_s: float = 200.0
    timing_repeats: int = 3
    sharpness_denoise: str = "oidn-fast"
    seed: int = 0
    real_imu: str | None = None
    cache_dir: str | None = None
    versus_walks: int = 3
    versus_cycles: int = 12
    versus_spp: int = 4
    versus_methods: tuple = ("fixed", "classical-30", "classical-50", "classical-70", "shim", "zhang", "kim")
    versus_initial_ms: float = 4.0
    versus_vo_ratio: float = 0.9

    @classmethod
    def quick(cls, **overrides) -> "BlurConfig":
        base = dict(width=64, height=40, sharpness_width=64, sharpness_height=40, spp=4, reference_subinstants=8, reference_spp=4, n_instants=1,
                    walk_s=30.0, timing_repeats=1, sharpness_denoise="off", versus_walks=1, versus_cycles=3,
                    versus_spp=2, versus_methods=("fixed", "classical-50"))
        base.update(overrides)
        return cls(**base)

    def __post_init__(self) -> None:
        for name in ("width", "height", "sharpness_width", "sharpness_height", "spp", "reference_subinstants", "reference_spp", "n_instants",
                     "timing_repeats"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValidationError(f"blur study: {name} must be a positive integer, got {v!r}")
        if not 0 < self.source_ms < self.exposure_ms <= 1000.0 / 22.0:
            raise ValidationError(f"blur study: need 0 < source_ms < exposure_ms <= 45.45 ms, got "
                                  f"{self.source_ms!r}, {self.exposure_ms!r}")
        if isinstance(self.versus_walks, bool) or not isinstance(self.versus_walks, int) or self.versus_walks < 0:
            raise ValidationError(f"blur study: versus_walks must be an integer >= 0, got {self.versus_walks!r}")
        for name in ("versus_cycles", "versus_spp"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < (3 if name == "versus_cycles" else 1):
                raise ValidationError(f"blur study: {name} must be an integer >= "
                                      f"{3 if name == 'versus_cycles' else 1}, got {v!r}")
        if not self.versus_methods:
            raise ValidationError("blur study: versus_methods needs at least one AE method")
        if not self.walk_s >= 5.0:
            raise ValidationError(f"blur study: walk_s must be >= 5 s, got {self.walk_s!r}")

    def as_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["versus_methods"] = list(self.versus_methods)
        return d
