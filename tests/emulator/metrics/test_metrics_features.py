"""SIFT feature metrics (emulator.metrics.features) on constructed images."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from emulator.errors import MetricsError, RunFolderError
from emulator.core.gray import bayer_to_gray8
from emulator.metrics.features import (
    analyse_sequence,
    detect_sift,
    grid_occupancy,
    grid_uniformity,
    load_gray8,
    match_descriptors,
    run_succeeds,
    success_curve,
    to_gray8,
)
from emulator.io.runfolder import read_run_folder
from emulator.core.response import BOREALHDR_WHITE_LEVEL


def blob_image(cells, grid=20, cell_px=20, sigma_px=3.0) -> np.ndarray:
    """A grey image with one Gaussian blob at the centre of each given (row, col) cell."""
    size = grid * cell_px
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float32)
    img = np.full((size, size), 100.0, np.float32)
    for i, j in cells:
        cx, cy = j * cell_px + cell_px / 2 - 0.5, i * cell_px + cell_px / 2 - 0.5
        img += 120.0 * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * sigma_px**2))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def texture(shape=(240, 320), seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    noise = cv2.GaussianBlur(rng.standard_normal(shape).astype(np.float32), (0, 0), 2.0)
    return np.clip(128 + 40 * noise / noise.std(), 0, 255).astype(np.uint8)


# --------------------------------------------------------------------------- conversion


def test_bayer_to_gray8_is_a_fixed_linear_scale():
    levels = dict(white_level=4095, black_level=0)
    flat = np.full((8, 8), 4095, np.uint16)
    out = bayer_to_gray8(flat, **levels)
    assert out.dtype == np.uint8 and out.shape == (8, 8)
    assert (out == 255).all()
    assert (bayer_to_gray8(np.zeros((8, 8), np.uint16), **levels) == 0).all()
    # A dark image stays dark: no per-image normalisation (1000 DN -> round(62.27) = 62).
    assert (bayer_to_gray8(np.full((8, 8), 1000, np.uint16), **levels) == 62).all()
    # Levels: the white level maps to 255, values above clip, the black level maps to 0.
    assert (bayer_to_gray8(np.full((4, 4), 1023, np.uint16), white_level=1023, black_level=0) == 255).all()
    assert (bayer_to_gray8(np.full((4, 4), 3000, np.uint16), white_level=1023, black_level=0) == 255).all()
    assert (bayer_to_gray8(np.full((4, 4), 64, np.uint16), white_level=4095, black_level=64) == 0).all()
    # It is OpenCV's BayerRG2GRAY followed by the stated scale.
    rng = np.random.default_rng(3)
    raw = rng.integers(0, 4096, (16, 16)).astype(np.uint16)
    expected = np.clip(np.rint(cv2.cvtColor(raw, cv2.COLOR_BayerRG2GRAY) * (255 / 4095)), 0, 255)
    np.testing.assert_array_equal(bayer_to_gray8(raw, **levels), expected.astype(np.uint8))
    # ... and with a black level: (g - black) * 255 / (white - black)
    expected = np.clip(np.rint((cv2.cvtColor(raw, cv2.COLOR_BayerRG2GRAY) - 100.0) * (255 / 3994)), 0, 255)
    np.testing.assert_array_equal(bayer_to_gray8(raw, white_level=4094, black_level=100), expected.astype(np.uint8))


def test_conversion_input_checks(tmp_path):
    with pytest.raises(MetricsError, match="uint16"):
        bayer_to_gray8(np.zeros((4, 4), np.uint8), white_level=4094, black_level=0)
    with pytest.raises(MetricsError, match="black_level"):
        bayer_to_gray8(np.zeros((4, 4), np.uint16), white_level=10, black_level=10)
    gray = np.arange(16, dtype=np.uint8).reshape(4, 4)
    assert to_gray8(gray, white_level=4094, black_level=0) is gray  # png8 images are used as saved
    with pytest.raises(MetricsError, match="expected"):
        to_gray8(np.zeros((4, 4), np.float32), white_level=4094, black_level=0)
    (tmp_path / "x.png").write_bytes(b"not a png")
    with pytest.raises(RunFolderError, match="x.png: cannot read"):
        load_gray8(tmp_path / "x.png", white_level=4094, black_level=0)


# --------------------------------------------------------------------------- uniformity


def test_grid_uniformity_counts_occupied_cells_exactly():
    shape = (200, 400)  # H, W -> 20x20 cells of 10 x 20 px
    pts = np.array([[0.0, 0.0], [19.99, 9.99], [20.0, 0.0], [399.9, 199.9], [399.9, 5.0]])
    occ = grid_occupancy(pts, shape)
    assert occ.dtype == bool and occ.shape == (20, 20)
    assert occ.sum() == 4 and occ[0, 0] and occ[0, 1] and occ[19, 19] and occ[0, 19]
    assert grid_uniformity(pts, shape) == pytest.approx(4 / 400)
    # outside the image, NaN and infinity are ignored, not an error
    odd = np.array([[400.0, 10.0], [-0.1, 3.0], [np.nan, 5.0], [np.inf, 1.0]])
    assert grid_uniformity(odd, shape) == 0.0
    assert grid_uniformity(np.zeros((0, 2)), shape) == 0.0
    full = np.stack(np.meshgrid(np.arange(10, 400, 20.0), np.arange(5, 200, 10.0)), -1).reshape(-1, 2)
    assert grid_uniformity(full, shape) == 1.0
    assert grid_uniformity(full, shape, grid=(4, 5)) == 1.0
    with pytest.raises(MetricsError, match="grid"):
        grid_uniformity(full, shape, grid=(0, 20))


def test_sift_uniformity_on_a_known_blob_layout():
    # blobs in cells with both indices even (never adjacent): a checkerboard of 1/4 of
    # the grid, minus a missing block
    cells = [(i, j) for i in range(0, 20, 2) for j in range(0, 20, 2) if not (i < 6 and j < 6)]
    img = blob_image(cells)
    feats = detect_sift(img)
    assert len(feats) >= len(cells)
    expected = np.zeros((20, 20), bool)
    for c in cells:
        expected[c] = True
    np.testing.assert_array_equal(grid_occupancy(feats.points, feats.image_shape), expected)
    assert grid_uniformity(feats.points, feats.image_shape) == pytest.approx(len(cells) / 400)
    # a flat image has no keypoint, uniformity 0
    flat = detect_sift(np.full((64, 64), 90, np.uint8))
    assert len(flat) == 0 and flat.descriptors.shape == (0, 128)
    assert grid_uniformity(flat.points, flat.image_shape) == 0.0


def test_an_image_seen_again_gets_the_same_features_and_a_changed_one_its_own(monkeypatch):
    import emulator.metrics.sift as sift

    monkeypatch.setattr(sift, "_SIFT_MEMO", sift.SiftMemo())
    img = texture((200, 260), seed=3)
    first = detect_sift(img)
    again = detect_sift(img.copy())  # the same bytes in another array
    assert again is first and not first.points.flags.writeable and not first.descriptors.flags.writeable
    with pytest.raises(ValueError):
        first.descriptors[0, 0] = 1.0
    sift._SIFT_MEMO.clear()
    fresh = detect_sift(img)  # a fresh detection finds exactly what the memo gave
    assert fresh is not first
    np.testing.assert_array_equal(fresh.points, first.points)
    np.testing.assert_array_equal(fresh.descriptors, first.descriptors)
    changed = img.copy()
    changed[100, 130] ^= 1  # one pixel, one grey level
    assert detect_sift(changed) is not fresh
    assert detect_sift(img, n_features=50) is not fresh and len(detect_sift(img, n_features=50)) <= 52
    mask = np.full(img.shape, 255, np.uint8)
    masked = detect_sift(img, mask=mask)  # with a mask: always detected
    assert masked is not fresh and detect_sift(img, mask=mask) is not masked
    np.testing.assert_array_equal(masked.points, fresh.points)


def test_the_sift_memo_drops_the_least_recently_used_past_its_bytes(monkeypatch):
    import emulator.metrics.sift as sift

    memo = sift.SiftMemo()
    monkeypatch.setattr(sift, "_SIFT_MEMO", memo)
    a, b, c = (texture((160, 200), seed=s) for s in (4, 5, 6))
    fa = detect_sift(a)
    size = fa.points.nbytes + fa.descriptors.nbytes
    fb = detect_sift(b)
    monkeypatch.setattr(sift, "SIFT_MEMO_BYTES", size + fb.points.nbytes + fb.descriptors.nbytes)
    assert detect_sift(a) is fa  # a is now the most recent
    detect_sift(c)  # over the bound: b, the least recently used, goes
    assert memo._bytes <= sift.SIFT_MEMO_BYTES
    assert detect_sift(b) is not fb
    monkeypatch.setattr(sift, "SIFT_MEMO_BYTES", 16)  # larger than the whole bound: not kept
    big = detect_sift(texture((160, 200), seed=7))
    assert detect_sift(texture((160, 200), seed=7)) is not big


# --------------------------------------------------------------------------- matches


@pytest.mark.parametrize("matcher", ["flann", "bf"])
def test_shifted_copy_matches_with_the_shift(matcher):
    tex = texture((240, 330))
    a, b = tex[:, :320], tex[:, 7:327]  # b is a moved 7 px to the left
    fa, fb = detect_sift(a), detect_sift(b)
    pairs = match_descriptors(fa.descriptors, fb.descriptors, matcher=matcher)
    assert pairs.dtype == np.int64 and pairs.shape[1] == 2
    shift = fa.points[pairs[:, 0]] - fb.points[pairs[:, 1]]
    correct = np.all(np.abs(shift - [7.0, 0.0]) < 0.5, axis=1)
    # keypoints of a that are inside b's view (away from the cut border)
    inside = np.count_nonzero((fa.points[:, 0] > 15) & (fa.points[:, 0] < 312))
    assert correct.mean() > 0.99
    assert correct.sum() > 0.9 * inside
    # an unrelated texture gives almost nothing
    other = detect_sift(texture((240, 320), seed=9))
    assert match_descriptors(fa.descriptors, other.descriptors, matcher=matcher).shape[0] < 0.02 * len(fa)


def test_match_descriptors_edge_cases():
    d = np.random.default_rng(0).random((5, 128)).astype(np.float32)
    assert match_descriptors(d, d[:1]).shape == (0, 2)  # one neighbour: no ratio test
    assert match_descriptors(d[:0], d).shape == (0, 2)
    assert match_descriptors(d, d, matcher="bf").shape == (5, 2)  # identical: distance 0 < ratio * next
    with pytest.raises(MetricsError, match="ratio"):
        match_descriptors(d, d, ratio=1.5)
    with pytest.raises(MetricsError, match="unknown matcher 'kd'"):
        match_descriptors(d, d, matcher="kd")


# --------------------------------------------------------------------------- success rate


def test_success_curve_and_run_success():
    runs = [[10, 50, 40], [30, 40], [100]]
    np.testing.assert_array_equal(success_curve(runs, [5, 10, 11, 30, 31, 100, 101]),
                                  [1, 1, 2 / 3, 2 / 3, 1 / 3, 1 / 3, 0])
    assert run_succeeds([10, 50], 10) and not run_succeeds([10, 50], 11)
    with pytest.raises(MetricsError, match="no consecutive image pair"):
        run_succeeds([], 5)
    with pytest.raises(MetricsError, match="run 1"):
        success_curve([[5], []], [5])


def test_analyse_sequence_counts_pairs():
    tex = texture((240, 340))
    images = [(1000 + k, 4.0, tex[:, 5 * k:5 * k + 320]) for k in range(3)]
    seq = analyse_sequence(iter(images), matcher="bf")
    assert seq.timestamps_ns == [1000, 1001, 1002] and len(seq.matches) == 2
    assert all(m > 0.8 * n for m, n in zip(seq.matches, seq.n_keypoints))
    d = seq.to_dict()
    assert d["min_matches"] == min(seq.matches) and d["n_images"] == 3
    json.dumps(d)  # JSON-ready
    half = analyse_sequence(iter(images), scale=0.5)
    assert half.image_shape == (120, 160)


# --------------------------------------------------------------------------- run folder


def test_run_folder_errors(tmp_path):
    with pytest.raises(RunFolderError, match="does not exist"):
        read_run_folder(tmp_path / "missing")
    with pytest.raises(RunFolderError, match=r"not a run folder \(run.json missing\)"):
        read_run_folder(tmp_path)
    (tmp_path / "run.json").write_text(json.dumps({"methods": ["fixed"], "save": "none"}))
    with pytest.raises(RunFolderError, match="saved no images"):
        read_run_folder(tmp_path)
    (tmp_path / "run.json").write_text(json.dumps({"methods": ["fixed"], "save": "png16"}))
    (tmp_path / "fixed" / "images" / "left").mkdir(parents=True)
    with pytest.raises(RunFolderError, match="no images for method 'fixed'"):
        read_run_folder(tmp_path)
    cv2.imwrite(str(tmp_path / "fixed" / "images" / "left" / "100.png"), np.zeros((4, 4), np.uint16))
    (tmp_path / "fixed" / "images" / "times.txt").write_text("100 0.0000001 4.0\n200 0.0000002 8.0\n")
    with pytest.raises(RunFolderError, match="times.txt: 1 timestamp"):
        read_run_folder(tmp_path)
    (tmp_path / "fixed" / "images" / "times.txt").write_text("100 0.0000001 4.0\n")
    run = read_run_folder(tmp_path)
    assert run.white_level == BOREALHDR_WHITE_LEVEL == 4094 and run.methods["fixed"].frames[0].exposure_ms == 4.0
    with pytest.raises(RunFolderError, match="no right image"):
        read_run_folder(tmp_path, require_right=True)
    with pytest.raises(RunFolderError, match="not in this run"):
        read_run_folder(tmp_path, ["kim"])
