"""What a walk of the live study keeps in memory: the renderers of its live shots and the integrated shots its
live runs share, each bounded in bytes whatever the image size; and the longest live exposure the walk's
renders are sized for.  :mod:`validation.live.walks` sizes its live runs with these.
"""

from __future__ import annotations

from validation.live.config import LiveConfig
from validation.live.loops import SharedRadiance

__all__ = ["MAX_RENDERERS_KEPT", "MAX_RENDERER_BYTES", "RENDERER_BYTES_PER_PX", "MAX_SHARED_SHOT_BYTES",
           "live_window_ms", "shots_shared", "shared_radiance", "renderers_kept"]


def live_window_ms() -> float:
    """The longest exposure a live shot can have (the AE clamp range's upper end): the walk's renders are
    sized for it, so that no live shot needs a render of its own."""
    from emulator.playback import RunConfig

    return float(RunConfig().range_ms[1])


#: Most renderers a walk keeps for its live runs (each holds a render with its margin and its depth: about
#: 3.4 MB at 480x300).
MAX_RENDERERS_KEPT = 64
#: Memory the kept renderers of a walk may take, bytes, whatever the image size.
MAX_RENDERER_BYTES = 512 << 20
#: A renderer's memory per pixel of the image, bytes (its render with margin and its depth: about 3.4 MB at 480x300).
RENDERER_BYTES_PER_PX = 24


#: Memory the integrated shots shared by a walk's live runs may take, bytes, whatever the image size.
MAX_SHARED_SHOT_BYTES = 512 << 20


def shots_shared(cfg: LiveConfig, n_methods: int, n_runs: int) -> int:
    """Integrated shots the live runs advanced together share (:class:`~validation.live.loops.SharedRadiance`):
    one round of theirs (two cameras per method and run), at most as many as :data:`MAX_SHARED_SHOT_BYTES` holds
    at the walk's image size (RGB float32; a shot dropped is integrated again)."""
    fit = MAX_SHARED_SHOT_BYTES // (3 * 4 * cfg.width * cfg.height)
    return max(1, min(2 * n_methods * n_runs, fit))


def shared_radiance(radiance, cfg: LiveConfig, n_methods: int, n_runs: int):
    """``radiance`` for live runs advanced together: an exposure-aware one behind a
    :class:`~validation.live.loops.SharedRadiance` of :func:`shots_shared` shots, any other as it is."""
    if not getattr(radiance, "exposure_aware", False):
        return radiance
    return SharedRadiance(radiance, keep=shots_shared(cfg, n_methods, n_runs))


def renderers_kept(cfg: LiveConfig) -> int:
    """Renderers the walk's live runs keep: one per camera and sweep (or shot) of the walk, at most
    :data:`MAX_RENDERERS_KEPT` and as many as :data:`MAX_RENDERER_BYTES` holds at the walk's image size
    (a larger image keeps fewer: a dropped renderer is prepared again), so that each is prepared once for all
    the runs."""
    from scenes.walkshots import KEEP_RENDERERS

    per_sweep = 2 * (1 if cfg.render_per == "cycle" else 6)
    fit = MAX_RENDERER_BYTES // (RENDERER_BYTES_PER_PX * cfg.width * cfg.height)
    return max(KEEP_RENDERERS, min(MAX_RENDERERS_KEPT, fit, per_sweep * (cfg.n_cycles + 1)))
