"""Faults found by trying bad input (issue 11): shifted inverse responses, a mislabelled exposure.

* A pcalib table that is strictly increasing but negative (or shifted up) at the black
  level passed every check and emulated wrongly (a table negative at the dark end makes
  darker targets brighter): :func:`emulator.io.pcalib.read_response` refuses it, naming the
  file and the value; a camera with a black-level pedestal (negative below the black level
  by construction) still reads back when its black level is given.
* A stack with one wrong exposure line calibrated with no more than "not converged" and a
  larger residual: the image is now named, with the exposure time its pixels fit.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from emulator.calibration import calibrate_stack, fit_inverse_response
from emulator.commands.cli import main
from emulator.core.emulate import emulate
from emulator.errors import ResponseError
from emulator.io.borealhdr import load_sequence, sequence_response
from emulator.io.pcalib import PCALIB_ORIGIN_TOLERANCE, read_response, write_pcalib
from emulator.io.stack import write_stack
from emulator.core.response import CameraResponse

from tests.emulator.calibration.test_calibrate import stack_arrays


# ---------------------------------------------------------------------------- (a) shifted inverse responses
def test_negative_or_shifted_table_is_refused(tmp_path, pcalib_path):
    good = read_response(pcalib_path)
    knots = good.knots.copy()
    assert abs(knots[0]) <= PCALIB_ORIGIN_TOLERANCE * knots[-1]  # the real table: g(0) = 0.173 of 255

    # strictly increasing but negative at the dark end: darker targets would come out brighter
    down = write_pcalib(tmp_path / "down.txt", knots - 40.0)
    shifted = CameraResponse.from_samples(knots - 40.0, 4095, black_level=0, name="shifted")
    raw = np.array([[300, 400]], dtype=np.uint16)  # g(300), g(400) < 0 in the shifted table
    darker = emulate(raw, 8.0, 4.0, shifted)
    assert np.all(darker > raw)  # the fault: halving the exposure brightens these pixels
    with pytest.raises(ResponseError, match=r"down\.txt: inverse response is negative at DN 0 \(g = -39\.8"):
        read_response(down)

    # a little below 0 is refused too (-0.33 % of the top): negative exposure is meaningless
    with pytest.raises(ResponseError, match=r"low\.txt: inverse response is negative at DN 0"):
        read_response(write_pcalib(tmp_path / "low.txt", knots - 1.0))

    # entirely negative
    neg = write_pcalib(tmp_path / "neg.txt", knots - 300.0)
    with pytest.raises(ResponseError, match=r"neg\.txt: inverse response is not positive anywhere"):
        read_response(neg)

    # shifted up by 9 % of the top: refused (5 % allowed), named with the percentage
    up = write_pcalib(tmp_path / "up.txt", knots + 25.5)
    with pytest.raises(ResponseError, match=r"up\.txt: inverse response is shifted up: g = 25\.67.* is 9\.15 %"):
        read_response(up)
    # just inside the tolerance: accepted, values exactly as written
    ok = write_pcalib(tmp_path / "ok.txt", knots + 12.0)
    np.testing.assert_array_equal(read_response(ok).knots, knots + 12.0)


def test_pedestal_table_reads_with_its_black_level(tmp_path):
    """A table negative *below* the black level (synth with black_level > 0) is fine at that level."""
    black = 256
    table = (np.arange(4096.0) - black) / (4095 - black) * 255.0  # 0 at DN 256, -17 at DN 0
    path = write_pcalib(tmp_path / "pedestal.txt", table)
    with pytest.raises(ResponseError, match="negative at DN 0"):
        read_response(path, expected_count=None)
    r = read_response(path, black_level=black, expected_count=None)
    assert r.g[black] == 0.0 and r.black_level == black and r.g[0] == table[0]


def test_synth_dataset_with_pedestal_round_trips(tmp_path):
    from synth import Camera, capture_sequence
    from synth.procedural import TranslatingChart
    from synth.sequence import load_camera

    cam = Camera.preset("linear", width=32, height=24, black_level=256)
    assert cam.response.g[0] < 0  # the table continues below the black level
    src = TranslatingChart(32, 24, seed=0, speed_m_s=0.0, duration_s=1.0, dynamic_range_db=40)
    path = capture_sequence(src, tmp_path / "ped", cam, n_cycles=1, stereo=False, seed=0)
    seq = load_sequence(path)
    resp = sequence_response(seq)
    assert resp.black_level == 256 and np.array_equal(resp.g, cam.response.g[: resp.white_level + 1])
    assert np.array_equal(load_camera(path).response.g, cam.response.g)


# ---------------------------------------------------------------------------- (b) a mislabelled exposure
def test_mislabelled_exposure_is_named_with_the_time_it_fits(tmp_path):
    truth = CameraResponse.gamma(2.2)
    imgs, t = stack_arrays(truth, n=12)
    wrong = t.copy()
    wrong[6] *= 0.5  # one line of times.txt says half the real exposure
    root = write_stack(tmp_path / "st", imgs, wrong, white_level=4095)
    res = calibrate_stack(root, check_static=False)
    (out,) = res.info["outlier_images"]
    assert out["name"].endswith("00006.png") and out["exposure_ms"] == wrong[6]
    # the exposure its pixels fit is the true one (noise-free stack: quantisation only)
    assert out["fitted_exposure_ms"] == pytest.approx(t[6], rel=0.01)
    assert any("00006.png: its exposure time" in w and "times.txt" in w for w in res.info["warnings"])
    # the same stack with the right times: nothing flagged, every image's exposure fits within 1 %
    clean = fit_inverse_response(imgs.reshape(len(t), -1), t)
    assert clean.info["outlier_images"] == []
    scales = [s for s in clean.info["exposure_scale_per_image"] if s is not None]
    assert len(scales) >= 6 and max(abs(s - 1) for s in scales) < 0.01


@pytest.mark.parametrize("k,factor", [(3, 1.1), (5, 1.25), (8, 0.8), (10, 2.0)])
def test_mislabelled_exposure_real_table(k, factor, pcalib_path):
    """The real response, one exposure off by 10 % to 2x: the right image, its true exposure within 1 %."""
    truth = read_response(pcalib_path)
    imgs, t = stack_arrays(truth, n=12)
    wrong = t.copy()
    wrong[k] *= factor
    res = fit_inverse_response(imgs.reshape(len(t), -1), wrong)
    (out,) = res.info["outlier_images"]
    assert out["index"] == k and out["name"] == f"image {k}"
    assert out["fitted_exposure_ms"] == pytest.approx(t[k], rel=0.01)


def test_cli_prints_the_mislabelled_image(tmp_path, capsys):
    imgs, t = stack_arrays(CameraResponse.gamma(2.2), n=12)
    wrong = t.copy()
    wrong[5] *= 1.25
    root = write_stack(tmp_path / "st", imgs, wrong, white_level=4095)
    assert main(["calibrate", str(root), "-o", str(tmp_path / "r.txt"), "--no-progress"]) == 0
    text = capsys.readouterr().out
    line = next(ln for ln in text.splitlines() if "00005.png" in ln)
    assert line.startswith("warning") and f"{wrong[5]:g} ms does not fit" in line
    assert main(["calibrate", str(root), "-o", str(tmp_path / "r.txt"), "--no-progress", "--force", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert [o["index"] for o in d["outlier_images"]] == [5]
