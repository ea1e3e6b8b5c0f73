"""SIFT on 8-bit grey images, for the feature and VO metrics: keypoints and descriptors
(:func:`detect_sift`, OpenCV defaults, with a memo of recently seen images) and descriptor matching
with Lowe's ratio test (:func:`match_descriptors`).  Split out of :mod:`emulator.metrics.features`,
which re-exports these names.
"""

from __future__ import annotations

import collections
import hashlib
import threading
from dataclasses import dataclass

import cv2
import numpy as np

from emulator.errors import MetricsError

__all__ = [
    "RATIO_TEST",
    "MATCHERS",
    "SiftFeatures",
    "SIFT_MEMO_BYTES",
    "SiftMemo",
    "detect_sift",
    "match_descriptors",
]

#: Lowe's ratio test threshold (Lowe 2004, section 7.1: 0.8 rejects 90 % of the false
#: matches and under 5 % of the correct ones).
RATIO_TEST = 0.8
#: Nearest-neighbour matchers: ``"flann"`` (kd-trees, 5 trees, 50 checks; deterministic
#: under ``cv2.setRNGSeed``) or ``"bf"`` (exact brute force, L2).
MATCHERS = ("flann", "bf")


@dataclass(frozen=True)
class SiftFeatures:
    """SIFT keypoints of one image.

    Attributes
    ----------
    points : numpy.ndarray
        (N, 2) ``float32`` keypoint positions (x, y) in pixels.
    descriptors : numpy.ndarray
        (N, 128) ``float32`` SIFT descriptors.
    image_shape : tuple of int
        (H, W) of the image the keypoints were detected in.
    """

    points: np.ndarray
    descriptors: np.ndarray
    image_shape: tuple[int, int]

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def subset(self, index: np.ndarray) -> "SiftFeatures":
        """The features selected by ``index`` (boolean mask or integer indices)."""
        return SiftFeatures(self.points[index], self.descriptors[index], self.image_shape)


_SIFT_CACHE: dict[int, "cv2.SIFT"] = {}

#: Bytes of keypoints and descriptors :func:`detect_sift` keeps for images it may see again.
SIFT_MEMO_BYTES = 256 << 20


class SiftMemo:
    """The features of recently seen images, by the image's bytes (a BLAKE2b digest of its shape and
    pixels) and ``n_features``, least recently used dropped past :data:`SIFT_MEMO_BYTES`.

    A live-study walk detects on the same images again: the VO benchmark on the left images the
    feature benchmark has read (a synthetic rig's rectification leaves them as they are), and runs
    whose images are the same bytes (counted on one 4-cycle walk: 792 detections, 320 distinct
    images).  SIFT gives the same keypoints for the same image, so a repeat gets the features the
    first detection found; their arrays are read-only."""

    def __init__(self) -> None:
        self._items: collections.OrderedDict = collections.OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()

    @staticmethod
    def key(gray8: np.ndarray, n_features: int) -> tuple:
        digest = hashlib.blake2b(np.ascontiguousarray(gray8).data, digest_size=20).digest()
        return gray8.shape, int(n_features), digest

    def get(self, key) -> "SiftFeatures | None":
        with self._lock:
            hit = self._items.get(key)
            if hit is not None:
                self._items.move_to_end(key)
            return hit

    def put(self, key, feats: "SiftFeatures") -> None:
        size = feats.points.nbytes + feats.descriptors.nbytes
        if size > SIFT_MEMO_BYTES:
            return
        with self._lock:
            if key in self._items:
                return
            self._items[key] = feats
            self._bytes += size
            while self._bytes > SIFT_MEMO_BYTES:
                _, old = self._items.popitem(last=False)
                self._bytes -= old.points.nbytes + old.descriptors.nbytes

    def clear(self) -> None:
        with self._lock:
            self._items.clear()
            self._bytes = 0


_SIFT_MEMO = SiftMemo()


def detect_sift(gray8: np.ndarray, *, n_features: int = 0, mask: np.ndarray | None = None) -> SiftFeatures:
    """Detect SIFT keypoints and compute their descriptors (OpenCV defaults).

    Without a mask, an image seen recently (the same shape and bytes, the same ``n_features``)
    gets the features found then, read-only (:class:`SiftMemo`).

    Parameters
    ----------
    gray8 : numpy.ndarray
        (H, W) ``uint8`` grey image.
    n_features : int
        Keep the ``n_features`` strongest keypoints; 0 keeps all (OpenCV default).
    mask : numpy.ndarray, optional
        (H, W) ``uint8`` mask; keypoints are detected where it is non-zero.

    Returns
    -------
    SiftFeatures
    """
    gray8 = np.asarray(gray8)
    if gray8.ndim != 2 or gray8.dtype != np.uint8:
        raise MetricsError(f"detect_sift: expected a 2-D uint8 image, got {gray8.dtype} {gray8.shape}")
    if n_features < 0:
        raise MetricsError(f"detect_sift: n_features must be >= 0, got {n_features}")
    key = SiftMemo.key(gray8, n_features) if mask is None else None
    hit = None if key is None else _SIFT_MEMO.get(key)
    if hit is not None:
        return hit
    sift = _SIFT_CACHE.get(n_features)
    if sift is None:
        sift = _SIFT_CACHE[n_features] = cv2.SIFT_create(nfeatures=n_features)
    keypoints, descriptors = sift.detectAndCompute(gray8, mask)
    if descriptors is None or len(keypoints) == 0:
        points, descriptors = np.zeros((0, 2), np.float32), np.zeros((0, 128), np.float32)
    else:
        points = np.array([kp.pt for kp in keypoints], dtype=np.float32).reshape(-1, 2)
        descriptors = np.ascontiguousarray(descriptors, dtype=np.float32)
    feats = SiftFeatures(points, descriptors, gray8.shape)
    if key is not None:
        points.setflags(write=False)
        descriptors.setflags(write=False)
        _SIFT_MEMO.put(key, feats)
    return feats


def match_descriptors(
    descriptors_a: np.ndarray,
    descriptors_b: np.ndarray,
    *,
    ratio: float = RATIO_TEST,
    matcher: str = "flann",
    seed: int = 0,
) -> np.ndarray:
    """Match descriptors of image a to image b with Lowe's ratio test.

    For every descriptor of ``a`` the two nearest descriptors of ``b`` (L2) are found; the
    nearest is kept when its distance is strictly below ``ratio`` times the second's.

    Parameters
    ----------
    descriptors_a, descriptors_b : numpy.ndarray
        (Na, D) and (Nb, D) ``float32`` descriptors.
    ratio : float
        Ratio test threshold in (0, 1]; default 0.8.
    matcher : {"flann", "bf"}
        Approximate kd-tree search (fast, deterministic for a given ``seed``) or exact
        brute force.
    seed : int
        Seed of OpenCV's random generator (``cv2.setRNGSeed``) for the kd-trees.

    Returns
    -------
    numpy.ndarray
        (M, 2) ``int64`` index pairs ``(index in a, index in b)``, sorted by index in a.
        Empty when either side has fewer than 2 descriptors (the ratio test needs two
        neighbours).
    """
    if not 0.0 < ratio <= 1.0:
        raise MetricsError(f"ratio must lie in (0, 1], got {ratio}")
    if matcher not in MATCHERS:
        raise MetricsError(f"unknown matcher {matcher!r}; valid: {', '.join(MATCHERS)}")
    a = np.ascontiguousarray(descriptors_a, dtype=np.float32)
    b = np.ascontiguousarray(descriptors_b, dtype=np.float32)
    if a.ndim != 2 or b.ndim != 2 or (a.size and b.size and a.shape[1] != b.shape[1]):
        raise MetricsError(f"descriptors must be (N, D) arrays of equal D, got {a.shape} and {b.shape}")
    if a.shape[0] < 1 or b.shape[0] < 2:
        return np.zeros((0, 2), dtype=np.int64)
    cv2.setRNGSeed(int(seed))
    if matcher == "flann":
        nn = cv2.FlannBasedMatcher({"algorithm": 1, "trees": 5}, {"checks": 50})
    else:
        nn = cv2.BFMatcher(cv2.NORM_L2)
    pairs = []
    for m in nn.knnMatch(a, b, k=2):
        if len(m) == 2 and m[0].distance < ratio * m[1].distance:
            pairs.append((m[0].queryIdx, m[0].trainIdx))
    if not pairs:
        return np.zeros((0, 2), dtype=np.int64)
    out = np.array(pairs, dtype=np.int64)
    return out[np.argsort(out[:, 0], kind="stable")]
