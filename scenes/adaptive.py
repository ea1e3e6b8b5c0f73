"""Spatially adaptive samples per pixel: more path-traced samples where render noise is worst.

Render noise matters to a study where it is large against the sensor's own noise, whose
variance grows with the radiance (shot noise).  So the measure of a region is its render
variance relative to its radiance, which does not depend on the exposure:

1. the base estimate is rendered as two passes of ``spp / 2`` samples with distinct seeds;
   their mean is the base estimate and ``(a - b)**2 / 4`` an unbiased estimate of its
   per-pixel variance;
2. the frame is cut into square tiles (``tile`` pixels); a tile's score is its summed
   luminance variance over its summed ``max(luminance, floor)`` (``floor``: a fraction
   :data:`FLOOR_FRACTION` of the frame's mean luminance, so near-black tiles, where the
   sensor's read noise rules, do not win on a tiny denominator);
3. the ``fraction`` of tiles with the highest scores get ``(factor - 1) * spp`` more samples,
   rendered through the film's crop window (Mitsuba ``crop_offset_x/y``, ``crop_width/height``),
   one crop per tile row spanning its selected tiles, neighbours merged where that costs fewer
   samples than a render's fixed cost, so that a frame takes few renders;
4. every pixel is the mean of all its samples (each pass weighted by its spp).

The selection looks at the samples it then keeps, which biases a selected tile's mean by far
less than its noise (docs/results/render-adaptive-2026-12-04.md measures the mean radiance).
Written in a setting string as ``~xFACTOR:PERCENT%`` (:mod:`scenes.presets`), e.g.
``oidn-hq@64+sun=16~x4:25%``; tile size other than :data:`DEFAULT_TILE` as ``~x4:25%/60``.

Where much of a frame clips at the exposures a study sees (the sun disk and its glints, a bright
sky), the brightest tiles would win extra samples the sensor then throws away.  ``@MSms`` (e.g.
``~x16:20%@32ms``) makes the score blind above the luminance that saturates the synthetic camera at
``MS`` ms (the scene's reference radiance fills the well at :data:`scenes.camera.DEFAULT_SATURATE_MS`):
both passes' luminance is clamped there before the variance and the radiance are summed.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import numpy as np

from scenes.camera import DEFAULT_SATURATE_MS
from scenes.dynamic_range import luminance
from scenes.errors import RenderError

__all__ = ["AdaptiveSampling", "parse_adaptive", "as_adaptive", "pass_seed", "tile_scores", "select_tiles", "tile_crops",
           "combine_passes", "render_adaptive", "DEFAULT_TILE", "FLOOR_FRACTION", "MERGE_SAMPLES"]

#: Tile side in render pixels (16 x 10 tiles at the study's 480x300).
DEFAULT_TILE = 30
#: The score's radiance floor, as a fraction of the frame's mean luminance.
FLOOR_FRACTION = 0.05
#: Extra samples (pixels times spp) worth one more crop: two crops are merged into their bounding
#: box when it adds fewer (a crop's fixed cost, about 1.2 s on two cores, is about 1.5 M samples).
MERGE_SAMPLES = 1_500_000


@dataclass(frozen=True)
class AdaptiveSampling:
    """``factor`` times the spp in the ``fraction`` of tiles (side ``tile`` px) with the worst relative variance.

    ``clip_ms``: the score ignores luminance above what saturates the synthetic camera at that exposure
    (None: nothing is clamped).
    """

    factor: int
    fraction: float
    tile: int = DEFAULT_TILE
    clip_ms: float | None = None

    def __post_init__(self):
        if isinstance(self.factor, bool) or not isinstance(self.factor, (int, np.integer)) or not 2 <= self.factor <= 64:
            raise RenderError(f"adaptive sampling: factor must be an integer in [2, 64], got {self.factor!r}")
        if not (isinstance(self.fraction, (int, float)) and 0.0 < float(self.fraction) <= 1.0):
            raise RenderError(f"adaptive sampling: fraction must be in (0, 1], got {self.fraction!r}")
        if isinstance(self.tile, bool) or not isinstance(self.tile, (int, np.integer)) or not 4 <= self.tile <= 1024:
            raise RenderError(f"adaptive sampling: tile must be an integer in [4, 1024] px, got {self.tile!r}")
        if self.clip_ms is not None and not (isinstance(self.clip_ms, (int, float)) and not isinstance(self.clip_ms, bool)
                                             and math.isfinite(self.clip_ms) and 0.0 < float(self.clip_ms) <= 1e6):
            raise RenderError(f"adaptive sampling: clip_ms must be a finite exposure in (0, 1e6] ms, got {self.clip_ms!r}")

    def clip_luminance(self, reference_radiance: float) -> float:
        """The luminance above which the score is blind: ``inf`` without ``clip_ms``."""
        if self.clip_ms is None:
            return math.inf
        return float(reference_radiance) * DEFAULT_SATURATE_MS / float(self.clip_ms)

    @property
    def text(self) -> str:
        """The ``xFACTOR:PERCENT%[/TILE][@MSms]`` form that :func:`parse_adaptive` reads back."""
        out = f"x{int(self.factor)}:{100.0 * float(self.fraction):g}%"
        out = out if self.tile == DEFAULT_TILE else f"{out}/{int(self.tile)}"
        return out if self.clip_ms is None else f"{out}@{float(self.clip_ms):g}ms"

    def key_material(self) -> dict:
        """What enters a render's cache key."""
        out = {"factor": int(self.factor), "fraction": round(float(self.fraction), 9), "tile": int(self.tile),
               "floor": FLOOR_FRACTION, "scheme": 1}
        if self.clip_ms is not None:  # absent otherwise: the keys of earlier renders stay as they were
            out.update(clip_ms=round(float(self.clip_ms), 9), saturate_ms=DEFAULT_SATURATE_MS)
        return out


def parse_adaptive(text: str, setting: str = "") -> AdaptiveSampling:
    """``"x4:25%"``, ``"x4:25%/60"`` or ``"x16:20%@32ms"`` -> :class:`AdaptiveSampling` (a clear error
    naming ``setting`` otherwise)."""
    head, at, clip = str(text).partition("@")
    body, slash, tile = head.partition("/")
    factor, colon, percent = body.partition(":")
    try:
        if not (factor.startswith("x") and colon and percent.endswith("%")) or (slash and not tile.isdigit()) or (
                at and not clip.endswith("ms")):
            raise ValueError
        clip_ms = float(clip[:-2]) if at else None
        return AdaptiveSampling(int(factor[1:]), float(percent[:-1]) / 100.0, int(tile) if slash else DEFAULT_TILE,
                                clip_ms)
    except (ValueError, RenderError) as exc:
        why = f": {exc}" if isinstance(exc, RenderError) else ""
        raise RenderError(f"render setting {setting or text!r}: expected ~xFACTOR:PERCENT%[/TILE][@MSms] after '~', "
                          f"e.g. ~x4:25% or ~x16:20%@32ms, got {text!r}{why}") from None


def as_adaptive(value) -> AdaptiveSampling | None:
    """None, an :class:`AdaptiveSampling` or its ``xFACTOR:PERCENT%...`` text -> None or the sampling (checked)."""
    if isinstance(value, str):
        return parse_adaptive(value)
    if value is not None and not isinstance(value, AdaptiveSampling):
        raise RenderError(f"adaptive must be None, a string like 'x4:25%' or an AdaptiveSampling, got {value!r}")
    return value


def pass_seed(seed: int, index: int) -> int:
    """Sampler seed of pass ``index`` of a render with ``seed`` (a hash: no two passes share one)."""
    digest = hashlib.sha256(f"exposim-adaptive:{int(seed)}:{int(index)}".encode()).digest()
    return int.from_bytes(digest[:4], "little")


def tile_scores(a: np.ndarray, b: np.ndarray, tile: int, clip: float = math.inf) -> np.ndarray:
    """(rows, cols) score of each tile: summed variance of the mean of ``a`` and ``b`` over summed floored luminance
    (both luminances clamped at ``clip`` first)."""
    la, lb = np.minimum(luminance(a), clip), np.minimum(luminance(b), clip)
    var = 0.25 * (la - lb) ** 2
    mean = 0.5 * (la + lb)
    floor = FLOOR_FRACTION * max(float(mean.mean()), 1e-12)
    h, w = mean.shape
    rows, cols = -(-h // tile), -(-w // tile)
    pad = ((0, rows * tile - h), (0, cols * tile - w))

    def tiled(x):
        return np.pad(x, pad).reshape(rows, tile, cols, tile).sum(axis=(1, 3))

    return tiled(var) / np.maximum(tiled(np.maximum(mean, floor)), 1e-30)


def select_tiles(scores: np.ndarray, fraction: float) -> np.ndarray:
    """Boolean mask of the ``ceil(fraction * n)`` highest-scoring tiles (ties: the first in row-major order)."""
    s = np.asarray(scores, dtype=np.float64)
    n = int(math.ceil(float(fraction) * s.size - 1e-9))
    order = np.argsort(-s.ravel(), kind="stable")[:n]
    mask = np.zeros(s.size, dtype=bool)
    mask[order] = True
    return mask.reshape(s.shape)


def tile_crops(mask: np.ndarray, tile: int, width: int, height: int, merge_px: int = 0) -> list[tuple[int, int, int, int]]:
    """``(x, y, w, h)`` crops covering the selected tiles (clipped to the frame).

    One crop per tile row, spanning its first to its last selected tile; then, while the two
    crops next to each other (in row order) whose bounding box adds the fewest pixels add fewer
    than ``merge_px``, they become that box: each crop is a render of its own, whose fixed cost
    (Dr.Jit compiles a kernel for each crop's geometry: about a second on two CPU cores) buys
    ``merge_px`` pixels of extra samples.
    """
    crops = []
    for r, row in enumerate(np.asarray(mask, dtype=bool)):
        cols = np.flatnonzero(row)
        if cols.size:
            x0, y0 = int(cols[0]) * tile, r * tile
            crops.append((x0, y0, min(width, (int(cols[-1]) + 1) * tile) - x0, min(height, (r + 1) * tile) - y0))

    def box(a, b):
        x0, y0 = min(a[0], b[0]), min(a[1], b[1])
        return x0, y0, max(a[0] + a[2], b[0] + b[2]) - x0, max(a[1] + a[3], b[1] + b[3]) - y0

    while len(crops) > 1:
        added = [box(a, b)[2] * box(a, b)[3] - a[2] * a[3] - b[2] * b[3] for a, b in zip(crops, crops[1:])]
        i = int(np.argmin(added))
        if added[i] >= merge_px:
            break
        crops[i:i + 2] = [box(crops[i], crops[i + 1])]
    return crops


def combine_passes(width: int, height: int, passes) -> np.ndarray:
    """Per-pixel spp-weighted mean of ``(image, spp, crop)`` passes (crop None: the whole frame), float32."""
    acc = np.zeros((height, width, 3), dtype=np.float64)
    count = np.zeros((height, width, 1), dtype=np.float64)
    for image, spp, crop in passes:
        x, y, w, h = (0, 0, width, height) if crop is None else crop
        acc[y:y + h, x:x + w] += float(spp) * np.asarray(image, dtype=np.float64).reshape(h, w, 3)
        count[y:y + h, x:x + w] += float(spp)
    if np.any(count == 0):
        raise RenderError("adaptive sampling: a pixel got no samples (the passes do not cover the frame)")
    return (acc / count).astype(np.float32)


def render_adaptive(render_pass, spec: AdaptiveSampling, *, width: int, height: int, spp: int, seed: int,
                    effective_spp=lambda n: n, reference_radiance: float | None = None) -> tuple[np.ndarray, dict]:
    """The adaptive estimate and ``{"tiles", "crops", "extra_pixels", "mean_spp"}``.

    ``render_pass(spp, seed, crop)`` renders the frame (crop None) or the ``(x, y, w, h)``
    crop and returns (h, w, 3) radiance; ``effective_spp`` maps a requested count to the
    sampler's (the weights use it); ``reference_radiance``, the scene's, is needed with ``spec.clip_ms``.
    """
    if spec.clip_ms is not None and not (reference_radiance is not None and math.isfinite(reference_radiance)
                                         and reference_radiance > 0):
        raise RenderError(f"adaptive sampling {spec.text}: clipping needs the scene's reference radiance > 0, "
                          f"got {reference_radiance!r}")
    clip = spec.clip_luminance(reference_radiance)
    half = effective_spp(max(1, int(spp) // 2))
    a = render_pass(half, pass_seed(seed, 0), None)
    b = render_pass(half, pass_seed(seed, 1), None)
    mask = select_tiles(tile_scores(a, b, spec.tile, clip), spec.fraction)
    extra = effective_spp(max(1, (int(spec.factor) - 1) * int(spp)))
    crops = tile_crops(mask, spec.tile, width, height, merge_px=MERGE_SAMPLES // extra)
    passes = [(a, half, None), (b, half, None)]
    for i, crop in enumerate(crops):
        passes.append((render_pass(extra, pass_seed(seed, 2 + i), crop), extra, crop))
    pixels = sum(c[2] * c[3] for c in crops)
    info = {"tiles": int(mask.sum()), "crops": len(crops), "extra_pixels": int(pixels),
            "mean_spp": float(2 * half + extra * pixels / (width * height))}
    return combine_passes(width, height, passes), info
