"""Image statistics that say whether synthetic frames look like real ones to the metrics.

Three figures, computed on the 8-bit grey image the feature metrics see
(:func:`emulator.metrics.features.bayer_to_gray8`: OpenCV ``COLOR_BayerRG2GRAY`` on the
12-bit mosaic, then a fixed linear scale of the DN range to 0..255):

``keypoints_per_mp``
    SIFT keypoints (OpenCV defaults, :func:`emulator.metrics.features.detect_sift`) per
    megapixel of the image.
``median_gradient``
    Median over the image (one-pixel border excluded) of the Sobel gradient magnitude
    ``sqrt(Gx**2 + Gy**2)``, 3x3 kernels, computed in float32 on the 0..255 grey values.
``repeatability``
    Keypoint repeatability between two images of one pose: the fraction of the keypoints
    of image A that have a keypoint of image B within ``radius_px`` = 1.5 px.  This is the
    repeatability rate of Schmid, Mohr & Bauckhage (2000), who introduced the 1.5 px
    tolerance, in the form Mikolajczyk et al. (2005) use for detector comparisons,
    simplified to identical geometry (the homography between the two images is the
    identity, so no reprojection and no overlap region are needed) and normalised by the
    keypoint count of A instead of ``min(n_A, n_B)``.  A keypoint of B may serve several
    keypoints of A.

How frames are brought to a common size: a real BorealHDR frame (1920x1200 Bayer) is
converted to grey at full resolution and then reduced with ``cv2.resize(...,
interpolation=cv2.INTER_AREA)`` (:func:`gray8_at`).  A synthetic frame is rendered at the
target size, captured by the synthetic camera (:func:`synthetic_gray8`) and converted
the same way; it is only resized when its size differs from the target.

References
----------
Schmid, C., Mohr, R., Bauckhage, C. (2000). Evaluation of interest point detectors.
International Journal of Computer Vision 37(2), 151-172.

Mikolajczyk, K., Tuytelaars, T., Schmid, C., Zisserman, A., Matas, J., Schaffalitzky, F.,
Kadir, T., Van Gool, L. (2005). A comparison of affine region detectors. International
Journal of Computer Vision 65(1/2), 43-72.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from scenes.errors import SceneError

__all__ = [
    "REPEATABILITY_RADIUS_PX",
    "ImageStats",
    "gray8_at",
    "keypoint_points",
    "keypoints_per_mp",
    "median_gradient",
    "keypoint_repeatability",
    "image_stats",
    "synthetic_camera",
    "synthetic_gray8",
    "real_frames_gray8",
]

#: Distance within which a keypoint counts as re-found (Schmid et al. 2000), pixels.
REPEATABILITY_RADIUS_PX = 1.5


@dataclass(frozen=True)
class ImageStats:
    """Statistics of one 8-bit grey image (see the module docstring).

    Attributes
    ----------
    width, height : int
        Image size, pixels.
    keypoints : int
        SIFT keypoints (OpenCV defaults).
    keypoints_per_mp : float
        ``keypoints / (width * height / 1e6)``.
    median_gradient : float
        Median Sobel gradient magnitude, grey levels per pixel (3x3 Sobel kernel scale).
    mean_gray : float
        Mean grey level, 0..255.
    saturated_fraction : float
        Fraction of pixels at 255.
    """

    width: int
    height: int
    keypoints: int
    keypoints_per_mp: float
    median_gradient: float
    mean_gray: float
    saturated_fraction: float

    def to_dict(self) -> dict:
        return asdict(self)


def _check_gray8(gray8, name: str = "gray8") -> np.ndarray:
    g = np.asarray(gray8)
    if g.ndim != 2 or g.dtype != np.uint8 or min(g.shape) < 3:
        raise SceneError(f"{name} must be a 2-D uint8 image of at least 3x3, got {g.dtype} {g.shape}")
    return g


def gray8_at(gray8, size: tuple[int, int] | None) -> np.ndarray:
    """Resize an 8-bit grey image to ``size`` = (width, height) with ``cv2.INTER_AREA``.

    Returns the image itself when it already has that size (or ``size`` is None).
    """
    import cv2

    g = _check_gray8(gray8)
    if size is None or (g.shape[1], g.shape[0]) == tuple(size):
        return g
    w, h = (int(v) for v in size)
    if w < 3 or h < 3:
        raise SceneError(f"size must be at least 3x3, got {size!r}")
    return cv2.resize(g, (w, h), interpolation=cv2.INTER_AREA)


def keypoint_points(gray8) -> np.ndarray:
    """Positions (x, y) of the SIFT keypoints of an 8-bit grey image, float32 (N, 2)."""
    from emulator.metrics.features import detect_sift

    return detect_sift(_check_gray8(gray8)).points


def keypoints_per_mp(gray8) -> float:
    """SIFT keypoints per megapixel (OpenCV defaults)."""
    g = _check_gray8(gray8)
    return float(len(keypoint_points(g)) / (g.size / 1e6))


def median_gradient(gray8) -> float:
    """Median Sobel gradient magnitude of an 8-bit grey image (one-pixel border excluded).

    Examples
    --------
    >>> ramp = np.tile(np.arange(0, 64, 2, dtype=np.uint8), (16, 1))  # +2 grey levels per pixel
    >>> median_gradient(ramp)  # the 3x3 Sobel kernel weighs a unit step by 8
    16.0
    """
    import cv2

    f = _check_gray8(gray8).astype(np.float32)
    gx = cv2.Sobel(f, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(f, cv2.CV_32F, 0, 1, ksize=3)
    return float(np.median(np.hypot(gx, gy)[1:-1, 1:-1]))


def keypoint_repeatability(points_a, points_b, radius_px: float = REPEATABILITY_RADIUS_PX) -> float:
    """Fraction of the keypoints of A that have a keypoint of B within ``radius_px``.

    Parameters
    ----------
    points_a, points_b : array-like
        (N, 2) and (M, 2) keypoint positions (x, y), pixels, in the same image frame.
    radius_px : float
        Tolerance, pixels (default 1.5, Schmid et al. 2000).

    Returns
    -------
    float
        In [0, 1]; NaN when A has no keypoint.

    Examples
    --------
    >>> keypoint_repeatability([[0, 0], [10, 10]], [[1, 1], [30, 30]])
    0.5
    """
    from scipy.spatial import cKDTree

    a = np.asarray(points_a, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(points_b, dtype=np.float64).reshape(-1, 2)
    if not (np.isfinite(radius_px) and radius_px > 0):
        raise SceneError(f"radius_px must be > 0, got {radius_px!r}")
    if a.shape[0] == 0:
        return float("nan")
    if b.shape[0] == 0:
        return 0.0
    d, _ = cKDTree(b).query(a, k=1)
    return float(np.mean(d <= radius_px))


def image_stats(gray8) -> ImageStats:
    """Keypoints per megapixel, median gradient and grey-level summary of one image."""
    g = _check_gray8(gray8)
    n = len(keypoint_points(g))
    return ImageStats(width=int(g.shape[1]), height=int(g.shape[0]), keypoints=int(n),
                      keypoints_per_mp=float(n / (g.size / 1e6)), median_gradient=median_gradient(g),
                      mean_gray=float(g.mean()), saturated_fraction=float(np.mean(g == 255)))


def synthetic_camera(scene, width: int, height: int, *, camera: str = "borealhdr", saturate_ms: float | None = None):
    """The synthetic camera :func:`scenes.synthesize.synthesize` uses for a scene, at a size.

    Its gain puts the scene's reference radiance (white surface facing the main light) at
    full well at ``saturate_ms`` (default :data:`scenes.camera.DEFAULT_SATURATE_MS`).
    """
    import synth
    from scenes.camera import DEFAULT_SATURATE_MS

    t = DEFAULT_SATURATE_MS if saturate_ms is None else float(saturate_ms)
    cam = synth.Camera.preset(camera, width=int(width), height=int(height))
    return cam.saturating_at(scene.reference_radiance, t)


def synthetic_gray8(radiance, scene, *, exposure_ms: float = 8.0, seed: int = 0, noise: bool = True,
                    size: tuple[int, int] | None = None, camera=None) -> np.ndarray:
    """8-bit grey image of a rendered radiance, as the feature metrics see a real frame.

    The radiance is captured by the synthetic camera at ``exposure_ms`` (sensor noise drawn
    from ``seed`` unless ``noise`` is False), converted by
    :func:`emulator.metrics.features.bayer_to_gray8` and, if ``size`` differs from the
    render's size, reduced with ``cv2.INTER_AREA``.

    Parameters
    ----------
    radiance : numpy.ndarray
        float32 (H, W, 3) linear radiance (:func:`scenes.render`).
    scene : scenes.Scene
        The rendered scene (its reference radiance sets the camera gain).
    camera : synth.Camera, optional
        Default :func:`synthetic_camera` at the render's size.
    """
    import synth
    from emulator.core.gray import bayer_to_gray8

    rad = np.asarray(radiance)
    if rad.ndim != 3 or rad.shape[2] != 3:
        raise SceneError(f"radiance must be (H, W, 3), got {rad.shape}")
    cam = camera or synthetic_camera(scene, rad.shape[1], rad.shape[0])
    raw = synth.capture(rad, float(exposure_ms), cam, seed=seed, noise=noise)
    return gray8_at(bayer_to_gray8(raw, white_level=cam.white_level, black_level=cam.black_level), size)


def real_frames_gray8(sequence_path, *, exposure_ms: float = 8.0, size: tuple[int, int] | None = (480, 300),
                      cameras: tuple[str, ...] = ("left", "right")) -> list[tuple[str, int, np.ndarray]]:
    """Grey images of the real frames of one bracket: full-resolution grey, then INTER_AREA to ``size``.

    Returns
    -------
    list of (camera, timestamp_ns, gray8)
        In timestamp order, left before right.
    """
    from emulator.io.borealhdr import load_sequence
    from emulator.core.gray import bayer_to_gray8

    seq = load_sequence(sequence_path)
    out = []
    for cycle in seq:
        for cam in cameras:
            frame = cycle.frames.get(cam, {}).get(float(exposure_ms))
            if frame is None:
                continue
            g = bayer_to_gray8(frame.load(), white_level=seq.white_level, black_level=seq.black_level)
            out.append((cam, int(frame.timestamp_ns), gray8_at(g, size)))
    if not out:
        raise SceneError(f"{sequence_path}: no frame at {exposure_ms:g} ms for camera(s) {', '.join(cameras)}")
    return out
