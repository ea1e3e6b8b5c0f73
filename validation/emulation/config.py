"""Emulation study configuration: :class:`EmulationConfig` and the sweep's constants."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from emulator.core.select import SELECTORS
from validation.common import BRACKETS_MS, RESPONSES, STUDY_SCENES, ValidationError, study_scene


__all__ = ["METRICS", "BOUND_TOL_DN", "HIST_BINS", "EmulationConfig", "HARD_EXPOSURES_MS"]

#: Per-(exposure, bracket) error arrays a sweep returns, in DN.
METRICS = (
    "raw_valid", "raw_all", "sigma_valid", "sigma_all", "pair_valid", "pair_all",
    "exact_valid", "exact_all", "exact_invalid", "clean_valid", "clean_all", "clean_invalid",
)
#: Slack of the per-pixel bound check, DN (float rounding of the forward model).
BOUND_TOL_DN = 1e-6
#: Bins of the pixel-value distributions (Fig. 3 right).
HIST_BINS = 64


@dataclass(frozen=True)
class EmulationConfig:
    """Size of the emulation study.

    Attributes
    ----------
    scenes : tuple of str
        Study scene keys (:data:`validation.common.STUDY_SCENES`).
    responses : tuple of str
        Camera response presets, each run with the preset's vignetting.
    vignetting : tuple of float
        Extra vignetting strengths, each run with the first response.
    n_exposures : int
        Ground-truth exposures, log-spaced over ``[lo_ms, hi_ms]``.
    repeats : int
        Noisy captures per ground-truth exposure (noise estimate; >= 2).
    width, height, spp : int
        Render size and samples per pixel of the radiance.
    seed : int
        Base seed of every capture.
    hist_exposures_ms : tuple of float
        Exposures (nearest grid point) whose pixel-value distributions are kept.
    """

    scenes: tuple = tuple(STUDY_SCENES)
    responses: tuple = RESPONSES
    vignetting: tuple = (0.0, 1.0)
    n_exposures: int = 1000
    repeats: int = 25
    width: int = 96
    height: int = 60
    spp: int = 64
    seed: int = 0
    brackets_ms: tuple = BRACKETS_MS
    lo_ms: float = 0.02
    hi_ms: float = 50.0
    selector: str = "higher-no-sat"
    hist_exposures_ms: tuple = (0.05, 0.5, 3.0, 12.0, 45.0)
    hard_cases: bool = True
    cache_dir: str | None = None

    @classmethod
    def quick(cls, **overrides) -> "EmulationConfig":
        """The reduced configuration (tests, --quick): 40 exposures, 5 repeats, 2 scenes, 64x40."""
        base = dict(scenes=("static_lab", "forest_winter"), n_exposures=40, repeats=5, width=64, height=40,
                    spp=16, vignetting=(0.0,))
        base.update(overrides)
        return cls(**base)

    def __post_init__(self) -> None:
        for s in self.scenes:
            study_scene(s)
        for r in self.responses:
            if r not in RESPONSES:
                raise ValidationError(f"unknown camera response {r!r}; choose from {', '.join(RESPONSES)}")
        if not self.scenes or not self.responses:
            raise ValidationError("need at least one scene and one camera response")
        if self.repeats < 2:
            raise ValidationError(f"repeats must be >= 2 to estimate the camera noise, got {self.repeats}")
        if self.selector not in SELECTORS:
            raise ValidationError(f"unknown selector {self.selector!r}; choose from {', '.join(SELECTORS)}")
        for name in ("width", "height", "spp", "n_exposures"):
            v = getattr(self, name)
            if isinstance(v, bool) or int(v) != v or v < 1:
                raise ValidationError(f"{name} must be a positive integer, got {v!r}")

    def cameras(self) -> list[tuple[str, float | None]]:
        """(response, vignetting or None for the preset's) for every camera configuration."""
        out = [(r, None) for r in self.responses]
        out += [(self.responses[0], float(v)) for v in self.vignetting]
        return out

    def n_steps(self) -> int:
        """Progress units: one per scene, camera and ground-truth exposure (+ hard cases)."""
        return len(self.scenes) * (len(self.cameras()) * self.n_exposures + 1) + (
            len(HARD_EXPOSURES_MS) * 2 if self.hard_cases else 0)

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


# ---------------------------------------------------------------------------------- hard cases
#: Exposures of the extreme-frame checks (the two ends of the range, the bracket ends and one between).
HARD_EXPOSURES_MS = (0.02, 1.0, 5.5, 32.0, 50.0)
