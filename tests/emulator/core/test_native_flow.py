"""The flow warp's parts: the image velocity between two neighbours, and the one resampling that applies it."""

from __future__ import annotations

import numpy as np
import pytest

from emulator.core.native import flow_velocity, move_mask, radiance_gray, warp_to_instant, warp_with_flow
from emulator.core.response import CameraResponse

W, H = 320, 240


def _texture(u, v):
    """A smooth pattern in 0.1..0.9 (periods of 19-100 px: the flow runs on 2x2 binned pixels), defined everywhere."""
    waves = [(0.05, 0.013, 0.3), (0.012, 0.045, 1.1), (0.03, -0.035, 2.0), (0.008, 0.006, 0.7)]
    return 0.5 + 0.1 * sum(np.sin(2 * np.pi * (a * u + b * v) + p) for a, b, p in waves)


def _image(shift_x, scale=1.0, top=4095):
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    return np.rint(np.clip(_texture(u - shift_x, v) * scale, 0, 1) * top).astype(np.uint16)


def test_a_translation_between_the_neighbours_is_measured_and_interpolated_to_the_instant():
    resp = CameraResponse.linear()
    # frame a (4 ms) and frame b (8 ms, twice the DN) 0.1 s apart; the scene moved 4 px right between them
    a, b = _image(0.0, 0.5), _image(4.0, 1.0)
    ga, gb = radiance_gray(a, 4.0, resp), radiance_gray(b, 8.0, resp)
    assert ga.shape == (H // 2, W // 2)
    assert float(np.median(np.abs(ga - gb))) > 0.05  # unaligned: the radiances differ
    vel = flow_velocity(ga, np.eye(3), gb, np.eye(3), 0.1)
    core = (slice(10, -10), slice(10, -10))
    vx, vy = (float(np.median(vel[core][..., i])) for i in (0, 1))
    assert abs(vx - 40.0) < 2.0 and abs(vy) < 1.0  # 4 px in 0.1 s, full-resolution px/s
    # frame k halfway: frame a moved by the velocity times 0.05 s lands on the scene 2 px right
    warped, inside = warp_with_flow(a, np.eye(3), vel * np.float32(0.05), resp)
    core = (slice(20, -20), slice(20, -20))
    rms = lambda x: float(np.sqrt(np.mean((x[core].astype(np.float64) - _image(2.0, 0.5)[core]) ** 2)))  # noqa: E731
    assert rms(a) > 100.0 and rms(warped) < 1.0  # DN: unwarped 108, moved by the flow 0
    assert (1 - 2 / W) - 0.01 < inside < 1.0  # two columns come from outside the source


def test_without_a_displacement_the_flow_warp_is_the_rotation_warp():
    resp = CameraResponse.linear()
    img = _image(0.0, 0.8)
    out, inside = warp_with_flow(img, np.eye(3), None, resp)
    assert np.array_equal(out, img) and inside == 1.0
    Hm = np.array([[1.0, 0.002, 3.4], [-0.001, 1.0, -1.7], [0.0, 0.0, 1.0]])
    (a, ia), (b, ib) = warp_with_flow(img, Hm, None, resp), warp_to_instant(img, Hm, resp)
    # cv2.remap and cv2.warpPerspective, the same kernel; they round the source position apart (at most 9 DN here)
    assert float(np.mean(np.abs(a.astype(int) - b.astype(int)) > 1)) < 1e-3
    assert ia == pytest.approx(ib, abs=2e-3)  # sites inside, against the area of the moved outline


def test_the_mask_moves_with_the_image():
    mask = np.zeros((H, W), dtype=bool)
    mask[100:140, 100:140] = True
    disp = np.zeros((H // 2, W // 2, 2), np.float32)
    disp[..., 0] = 6.0
    moved = move_mask(mask, np.eye(3), disp)
    assert moved[100:140, 106:146].all() and not moved[100:140, 100:106].any()
    assert np.array_equal(move_mask(mask, None), mask)
