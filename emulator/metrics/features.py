"""SIFT feature metrics of an AE method's run (paper section V-D-1, Fig. 4).

Three measurements on the emulated left images of a run:

* **uniformity**: the fraction of the cells of a 20 x 20 grid over the image that hold at
  least one SIFT keypoint (:func:`grid_uniformity`);
* **matches** between consecutive images: SIFT descriptors matched by nearest neighbour
  with Lowe's ratio test, threshold 0.8 (:func:`match_descriptors`);
* **success rate**: a run succeeds for a threshold ``tau`` when every consecutive pair has
  at least ``tau`` matches; the curve is the fraction of runs that succeed, over ``tau``
  (:func:`success_curve`).

Images reach SIFT as 8-bit grey.  A 12-bit RGGB Bayer mosaic is converted by
:func:`emulator.core.gray.bayer_to_gray8` (the conversion ``--save png8`` uses too): OpenCV's
``COLOR_BayerRG2GRAY`` demosaicing to grey, then a *fixed linear* scale of the camera's DN
range to 0..255.  The scale is the same for every image; a per-image normalisation would
hide exactly the exposure effects the benchmark measures.

SIFT is OpenCV's (``cv2.SIFT_create``) with its default parameters (all keypoints, 3
octave layers, contrast threshold 0.04, edge threshold 10, sigma 1.6) unless stated.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from emulator.errors import DatasetError, MetricsError, RunFolderError
from emulator.core.gray import bayer_to_gray8
from emulator.io.png import read_image
from emulator.metrics.sift import (  # re-exported: SIFT lives in emulator.metrics.sift
    MATCHERS,
    RATIO_TEST,
    SiftFeatures,
    detect_sift,
    match_descriptors,
)

__all__ = [
    "to_gray8",
    "load_gray8",
    "SiftFeatures",
    "detect_sift",
    "grid_occupancy",
    "grid_uniformity",
    "match_descriptors",
    "run_succeeds",
    "success_curve",
    "FeatureSequence",
    "analyse_sequence",
    "RATIO_TEST",
    "GRID_CELLS",
    "DEFAULT_TAUS",
    "MATCHERS",
]

#: Grid of the uniformity metric, (rows, columns), as in the paper's Fig. 4a.
GRID_CELLS = (20, 20)
#: Thresholds tau_matches of the success curve: 5 (the minimum for motion estimation,
#: Nister 2004) to 500 in steps of 5.
DEFAULT_TAUS = np.arange(5, 505, 5)


def to_gray8(image: np.ndarray, *, white_level: int, black_level: int) -> np.ndarray:
    """8-bit grey from a saved run image: ``uint16`` Bayer (png16) or ``uint8`` grey (png8).

    Parameters
    ----------
    image : numpy.ndarray
        (H, W) ``uint16`` RGGB mosaic in DN, (H, W) ``uint8`` grey, or (H, W, 3) ``uint8`` BGR.
    white_level, black_level : int
        The camera's clip levels in DN, used for ``uint16`` input only
        (:func:`emulator.core.gray.bayer_to_gray8`).

    Returns
    -------
    numpy.ndarray
        (H, W) ``uint8``.
    """
    image = np.asarray(image)
    if image.dtype == np.uint16 and image.ndim == 2:
        return bayer_to_gray8(image, white_level=white_level, black_level=black_level)
    if image.dtype == np.uint8 and image.ndim == 2:
        return image
    if image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    raise MetricsError(
        f"to_gray8: expected a (H, W) uint16 Bayer mosaic or a uint8 grey image, got {image.dtype} {image.shape}"
    )


def load_gray8(path: str | Path, *, white_level: int, black_level: int) -> np.ndarray:
    """Read a run image (png16 Bayer or png8 grey) as (H, W) ``uint8`` grey.

    Raises
    ------
    RunFolderError
        When the file cannot be decoded or holds an unexpected image type.
    """
    try:
        image = read_image(path)
    except (FileNotFoundError, DatasetError):
        raise RunFolderError(f"{path}: cannot read image (missing or not a PNG)") from None
    try:
        return to_gray8(image, white_level=white_level, black_level=black_level)
    except MetricsError as exc:
        raise RunFolderError(f"{path}: {exc}") from None


def grid_occupancy(points_xy: np.ndarray, image_shape: tuple[int, int], grid: tuple[int, int] = GRID_CELLS) -> np.ndarray:
    """Which cells of a regular grid over the image hold at least one point.

    Parameters
    ----------
    points_xy : numpy.ndarray
        (N, 2) point positions (x, y) in pixels; pixel centres of column ``c`` are at
        ``x = c`` (OpenCV convention).  Points outside ``[0, W) x [0, H)`` or not finite are
        ignored.
    image_shape : tuple of int
        (H, W) of the image, in pixels.
    grid : tuple of int
        Number of cells (rows, columns).  Cell ``(i, j)`` covers
        ``x in [j W / cols, (j + 1) W / cols)`` and ``y in [i H / rows, (i + 1) H / rows)``.

    Returns
    -------
    numpy.ndarray
        (rows, columns) ``bool``.
    """
    rows, cols = (int(grid[0]), int(grid[1]))
    height, width = (int(image_shape[0]), int(image_shape[1]))
    if rows < 1 or cols < 1:
        raise MetricsError(f"grid must have at least one cell per axis, got {grid}")
    if height < 1 or width < 1:
        raise MetricsError(f"image_shape must be positive, got {image_shape}")
    pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    x, y = pts[:, 0], pts[:, 1]
    keep = np.isfinite(x) & np.isfinite(y) & (x >= 0) & (x < width) & (y >= 0) & (y < height)
    col = np.minimum((x[keep] * cols / width).astype(np.int64), cols - 1)
    row = np.minimum((y[keep] * rows / height).astype(np.int64), rows - 1)
    occupied = np.zeros((rows, cols), dtype=bool)
    occupied[row, col] = True
    return occupied


def grid_uniformity(points_xy: np.ndarray, image_shape: tuple[int, int], grid: tuple[int, int] = GRID_CELLS) -> float:
    """Fraction of grid cells holding at least one keypoint (paper Fig. 4a).

    Parameters
    ----------
    points_xy, image_shape, grid
        See :func:`grid_occupancy`.

    Returns
    -------
    float
        In [0, 1]; 1 when every cell of the (default 20 x 20) grid has a keypoint.

    Examples
    --------
    >>> grid_uniformity(np.array([[5.0, 5.0], [15.0, 5.0]]), (20, 20), grid=(2, 2))
    0.5
    """
    occupied = grid_occupancy(points_xy, image_shape, grid)
    return float(occupied.mean())


def run_succeeds(match_counts: Sequence[int], tau: int) -> bool:
    """Whether every consecutive pair of a run has at least ``tau`` matches.

    Raises
    ------
    MetricsError
        For a run without any pair (fewer than two images): success is undefined.
    """
    counts = np.asarray(match_counts)
    if counts.size == 0:
        raise MetricsError("run_succeeds: the run has no consecutive image pair")
    return bool(counts.min() >= tau)


def success_curve(runs_match_counts: Sequence[Sequence[int]], taus: Sequence[int] = DEFAULT_TAUS) -> np.ndarray:
    """Fraction of runs that succeed, for every threshold ``tau`` (paper Fig. 4c).

    Parameters
    ----------
    runs_match_counts : sequence of sequences of int
        For each run (one method on one sequence), the matches of its consecutive pairs.
    taus : sequence of int
        Thresholds tau_matches.

    Returns
    -------
    numpy.ndarray
        ``float64`` success rate in [0, 1], one per ``tau``.

    Examples
    --------
    >>> success_curve([[10, 50], [30, 40]], [5, 20, 35]).tolist()
    [1.0, 0.5, 0.0]
    """
    if len(runs_match_counts) == 0:
        raise MetricsError("success_curve: no runs")
    minima = []
    for i, counts in enumerate(runs_match_counts):
        counts = np.asarray(counts)
        if counts.size == 0:
            raise MetricsError(f"success_curve: run {i} has no consecutive image pair")
        minima.append(counts.min())
    minima = np.asarray(minima)[None, :]
    taus = np.asarray(taus)[:, None]
    return (minima >= taus).mean(axis=1).astype(np.float64)


@dataclass
class FeatureSequence:
    """Per-image and per-pair feature measurements of one run (one method, one sequence).

    Attributes
    ----------
    timestamps_ns : list of int
        Image timestamps, integer ns.
    exposure_ms : list of float or None
        Exposure time of each image, ms.
    n_keypoints : list of int
        SIFT keypoints per image.
    uniformity : list of float
        Grid uniformity per image, in [0, 1].
    matches : list of int
        Ratio-test matches between image ``i`` and ``i + 1`` (length N - 1).
    image_shape : tuple of int
        (H, W) of the images SIFT ran on (after any downscaling).
    """

    timestamps_ns: list[int] = field(default_factory=list)
    exposure_ms: list[float | None] = field(default_factory=list)
    n_keypoints: list[int] = field(default_factory=list)
    uniformity: list[float] = field(default_factory=list)
    matches: list[int] = field(default_factory=list)
    image_shape: tuple[int, int] = (0, 0)

    def to_dict(self) -> dict:
        """JSON-ready dictionary (lists and summary statistics)."""
        return {
            "n_images": len(self.timestamps_ns),
            "image_shape": list(self.image_shape),
            "timestamps_ns": list(self.timestamps_ns),
            "exposure_ms": list(self.exposure_ms),
            "n_keypoints": list(self.n_keypoints),
            "uniformity": list(self.uniformity),
            "matches": list(self.matches),
            "median_uniformity": float(np.median(self.uniformity)) if self.uniformity else None,
            "median_matches": float(np.median(self.matches)) if self.matches else None,
            "min_matches": int(min(self.matches)) if self.matches else None,
        }


def analyse_sequence(
    images: Iterable[tuple[int, float | None, np.ndarray]],
    *,
    grid: tuple[int, int] = GRID_CELLS,
    ratio: float = RATIO_TEST,
    n_features: int = 0,
    matcher: str = "flann",
    scale: float = 1.0,
    seed: int = 0,
) -> FeatureSequence:
    """Uniformity and consecutive matches over a sequence of 8-bit images.

    Parameters
    ----------
    images : iterable of (timestamp_ns, exposure_ms, gray8)
        Images in time order; ``gray8`` is (H, W) ``uint8``.  Consumed lazily, so only two
        images' features are held at a time.
    grid, ratio, n_features, matcher, seed
        See :func:`grid_uniformity`, :func:`match_descriptors`, :func:`detect_sift`.
    scale : float
        Resize factor applied before SIFT (``cv2.INTER_AREA``), in (0, 1]; 1 keeps the
        full resolution (the paper's setting).

    Returns
    -------
    FeatureSequence
    """
    if not 0.0 < scale <= 1.0:
        raise MetricsError(f"scale must lie in (0, 1], got {scale}")
    result = FeatureSequence()
    previous: SiftFeatures | None = None
    for timestamp_ns, exposure_ms, gray8 in images:
        if scale != 1.0:
            gray8 = cv2.resize(gray8, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        feats = detect_sift(gray8, n_features=n_features)
        result.timestamps_ns.append(int(timestamp_ns))
        result.exposure_ms.append(None if exposure_ms is None else float(exposure_ms))
        result.n_keypoints.append(len(feats))
        result.uniformity.append(grid_uniformity(feats.points, feats.image_shape, grid))
        result.image_shape = tuple(int(v) for v in feats.image_shape)
        if previous is not None:
            pairs = match_descriptors(previous.descriptors, feats.descriptors, ratio=ratio, matcher=matcher, seed=seed)
            result.matches.append(int(pairs.shape[0]))
        previous = feats
    return result
