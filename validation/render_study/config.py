"""Render study configuration: :class:`RenderStudyConfig`, the ``full`` and ``quick`` :data:`CONFIGS`, the targets."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from validation.common import SHOT_INTERVAL_MS, ValidationError, study_scene

__all__ = ["DEFAULT_REAL_SEQUENCE", "TARGET_TOLERANCE", "TARGET_REPEATABILITY", "RenderStudyConfig", "CONFIGS", "MODES",
           "DENOISED"]


def _shared_folder() -> Path:
    """``../shared`` beside the repository; from a git worktree the first ``shared/data`` further up."""
    repo = Path(__file__).resolve().parents[2]
    for parent in repo.parents:
        if (parent / "shared" / "data").is_dir():
            return parent / "shared"
    return repo.parent / "shared"


#: The shared BorealHDR sample (beside the repository, never copied into it).
DEFAULT_REAL_SEQUENCE = _shared_folder() / "data" / "borealhdr_sample" / "backpack_2023-09-25-15-05-03"
#: Texture statistics must be within this fraction of the real frames' (issue 13).
TARGET_TOLERANCE = 0.25
#: Keypoint repeatability target between two renders of one pose (issue 13).
TARGET_REPEATABILITY = 0.80
#: Render paths compared: the raw estimate and every named denoiser (:data:`scenes.denoise.DENOISERS`).
MODES = ("off", "oidn", "oidn-fast")
DENOISED = MODES[1:]


@dataclass(frozen=True)
class RenderStudyConfig:
    """What the render study measures (see the module docstring)."""

    scenes: tuple = ("forest_winter", "sun_glare")
    width: int = 480
    height: int = 300
    spp_levels: tuple = (1, 2, 4, 8, 16, 32, 64)
    reference_spp: int = 1024
    exposure_ms: float = 8.0
    error_exposures_ms: tuple = (1.0, 8.0, 32.0)
    seeds: tuple = (1, 2, 3)
    walk_step_s: float = 6 * SHOT_INTERVAL_MS / 1000.0
    halo_px: int = 3
    texture_scenes: tuple = ("forest_winter",)
    texture_sizes: tuple = ((480, 300), (960, 600))
    texture_spp: int = 16
    texture_poses: int = 3
    texture_pose_step_s: float = 3.0
    real_sequence: str | None = str(DEFAULT_REAL_SEQUENCE)
    cache_dir: str | None = None

    def __post_init__(self) -> None:
        for key in self.scenes + self.texture_scenes:
            study_scene(key)
        if self.width < 16 or self.height < 16:
            raise ValidationError(f"study size must be at least 16x16, got {self.width}x{self.height}")
        if not self.spp_levels or any(int(s) < 1 for s in self.spp_levels):
            raise ValidationError(f"spp levels must be >= 1, got {self.spp_levels!r}")
        if self.reference_spp <= max(self.spp_levels):
            raise ValidationError(f"reference_spp ({self.reference_spp}) must exceed every spp level")
        if len(self.seeds) < 3 or len(set(self.seeds)) != len(self.seeds):
            raise ValidationError(f"need at least three distinct render seeds, got {self.seeds!r}")
        if self.texture_poses < 1 or self.texture_spp < 1:
            raise ValidationError("texture_poses and texture_spp must be >= 1")


#: ``full``: the issue's settings; ``quick``: a pipeline check in a few minutes on 2 cores.
CONFIGS = {
    "full": RenderStudyConfig(),
    "quick": RenderStudyConfig(scenes=("forest_winter",), width=120, height=75, spp_levels=(1, 4, 16),
                               reference_spp=256, texture_sizes=((240, 150),), texture_spp=4, texture_poses=1),
}
