"""Unit tests of the validation helpers and the proposed selector (no rendering)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from emulator import CameraResponse
from emulator.core.emulate import emulate
from emulator.errors import ExposimError, OutputExistsError
from emulator.io.files import prepare_output, write_results
from emulator.io.pcalib import read_response
from validation.common import (
    ValidationError,
    gt_exposures,
    pair_noise_map,
    quantisation_bound,
    rmse_dn,
    seed_for,
    subtract_linear,
    subtract_quadrature,
    summary_stats,
    to_percent,
)
from validation.selectors import NoiseModel, _oracle, evaluate_choices, predicted_error, predicted_mse_table


def test_gt_exposures_log_spaced_and_checked():
    t = gt_exposures(1000)
    assert t.shape == (1000,) and t.dtype == np.float64
    assert t[0] == pytest.approx(0.02) and t[-1] == pytest.approx(50.0)
    np.testing.assert_allclose(np.diff(np.log(t)), math.log(2500) / 999)
    for bad in (1, 0, 2.5, True):
        with pytest.raises(ValidationError, match="exposures"):
            gt_exposures(bad)


def test_seed_for_is_stable_and_distinct():
    assert seed_for(0, "gt", 3, 1) == seed_for(0, "gt", 3, 1)
    assert seed_for(0, "gt", 3, 1) != seed_for(0, "gt", 3, 2)
    assert 0 <= seed_for("x") < 2**32


def test_rmse_and_percent():
    a = np.array([[0, 10], [20, 30]], dtype=np.uint16)
    b = np.array([[0, 13], [16, 30]], dtype=np.uint16)
    assert rmse_dn(a, b) == pytest.approx(math.sqrt((9 + 16) / 4))
    mask = np.array([[False, True], [False, False]])
    assert rmse_dn(a, b, mask) == pytest.approx(3.0)
    assert rmse_dn(a, b, np.zeros_like(mask)) is None
    assert to_percent(40.94, 4094, 0) == pytest.approx(1.0)
    assert to_percent(None, 4095, 0) is None
    np.testing.assert_allclose(to_percent(np.array([0.0, 40.95]), 4095, 0), [0.0, 1.0])


def test_pair_noise_map_estimates_the_variance():
    rng = np.random.default_rng(1)
    base = rng.uniform(100, 3000, (60, 80))
    sigma = 7.0
    caps = [np.rint(base + rng.normal(0, sigma, base.shape)) for _ in range(25)]
    var = pair_noise_map(caps)
    # rounding adds 1/12 DN^2 of variance
    assert var.mean() == pytest.approx(sigma**2 + 1 / 12, rel=0.03)
    # the fixed content cancels: a constant offset between images does not enter
    assert pair_noise_map([base, base]).max() == 0.0
    with pytest.raises(ValidationError, match="at least 2"):
        pair_noise_map([base])


def test_noise_subtraction_recovers_the_clean_error():
    rng = np.random.default_rng(2)
    truth = rng.uniform(500, 1500, 200_000)
    emulated = truth + rng.normal(0, 3.0, truth.size)  # emulation error, 3 DN rms
    gt = truth + rng.normal(0, 4.0, truth.size)  # the ground truth's own noise, 4 DN rms
    raw = rmse_dn(emulated, gt)
    assert raw == pytest.approx(5.0, rel=0.01)
    assert subtract_quadrature(raw, 4.0) == pytest.approx(3.0, rel=0.02)
    # the linear subtraction of the pair RMSE (sqrt(2) sigma) over-subtracts
    assert subtract_linear(raw, math.sqrt(2) * 4.0) < 3.0 * 0.5
    assert subtract_quadrature(1.0, 2.0) == 0.0
    assert subtract_quadrature(None, 2.0) is None


@pytest.mark.parametrize("resp", ["linear", "gamma", "pcalib"])
@pytest.mark.parametrize("source_ms,target_ms", [(1, 32), (2, 9.5), (8, 16), (32, 0.02), (4, 3.99), (1, 50)])
def test_quantisation_bound_holds_for_exact_captures(pcalib_path, resp, source_ms, target_ms):
    r = {"linear": CameraResponse.linear(4094), "gamma": CameraResponse.gamma(2.2, 4094),
         "pcalib": read_response(pcalib_path).with_levels(white_level=4094)}[resp]
    rng = np.random.default_rng(3)
    h = np.exp(rng.uniform(np.log(1e-4), np.log(1.0), (64, 64))) * r.g[-1] / 8.0

    def cap(t):
        return np.clip(np.rint(r.forward(t * h)), r.black_level, r.white_level).astype(np.uint16)

    src, truth = cap(source_ms), cap(target_ms)
    emu, valid = emulate(src, source_ms, target_ms, r, return_mask=True)
    err = np.abs(emu.astype(float) - truth.astype(float))
    bound = quantisation_bound(r, src, target_ms / source_ms)
    assert np.all(err[valid] <= bound[valid] + 1e-9)


def test_summary_stats_ignores_none_and_nan():
    s = summary_stats([1.0, None, 3.0, float("nan"), 2.0])
    assert s == {"median": 2.0, "mean": 2.0, "p95": pytest.approx(2.9), "max": 3.0, "n": 3}
    assert summary_stats([None])["median"] is None


def test_prepare_output_refuses_existing_results(tmp_path):
    out = prepare_output(tmp_path / "a")
    write_results(out / "results.json", {"x": 1.0})
    with pytest.raises(OutputExistsError, match="--force"):
        prepare_output(out)
    assert prepare_output(out, force=True) == out
    (tmp_path / "f").write_text("")
    with pytest.raises(OutputExistsError, match="not a folder"):
        prepare_output(tmp_path / "f")


def test_write_results_is_deterministic_and_refuses_nan(tmp_path):
    # the validation studies write results.json with 12 significant digits: stable text
    p = write_results(tmp_path / "r.json", {"b": np.float64(0.1) + np.float64(0.2), "a": np.arange(3), "c": None},
                      float_digits=12)
    first = p.read_text()
    write_results(p, {"b": 0.30000000000000004, "a": [0, 1, 2], "c": None}, float_digits=12)
    assert p.read_text() == first
    assert json.loads(first) == {"a": [0, 1, 2], "b": 0.3, "c": None}
    with pytest.raises(ExposimError, match="non-finite .* at x"):
        write_results(tmp_path / "bad.json", {"x": float("nan")})


# ----------------------------------------------------------------------------------- predicted-error selector
def _exact(r, t, h):
    return np.clip(np.rint(r.forward(t * h)), r.black_level, r.white_level).astype(np.uint16)


def test_predicted_error_prefers_longer_unsaturated_bracket():
    r = CameraResponse.linear(4094)
    h = np.linspace(0.001, 0.02, 4000).reshape(40, 100) * r.g[-1]  # 32 ms reaches 64 % of white
    brackets = {b: _exact(r, b, h) for b in (1.0, 2.0, 4.0, 8.0, 16.0, 32.0)}
    noise = NoiseModel(shot=1.0 / 10000, floor=(3.0 / 10000) ** 2)
    lv = dict(white_level=4094, black_level=0)
    choice, scores = predicted_error(5.0, brackets, response=r, noise=noise, return_scores=True, **lv)
    assert choice == 32.0  # emulating down from the longest unclipped bracket keeps the SNR
    assert scores[32.0] < scores[8.0] < scores[1.0]


def test_predicted_error_avoids_clipped_bracket_when_darkening():
    r = CameraResponse.gamma(2.2, 4094)
    rng = np.random.default_rng(4)
    h = np.exp(rng.uniform(np.log(1e-3), np.log(2.0), (50, 80))) * r.g[-1] / 4.0  # 8 ms clips a lot
    brackets = {b: _exact(r, b, h) for b in (1.0, 2.0, 4.0, 8.0)}
    noise = NoiseModel(shot=1e-5, floor=1e-10)
    lv = dict(white_level=4094, black_level=0)
    chosen = predicted_error(1.5, brackets, response=r, noise=noise, clip_weight=1.0, **lv)
    assert chosen in (1.0, 2.0)
    # accepts DN histograms as well as images, and ties go to the longer bracket
    hists = {b: np.bincount(v.ravel(), minlength=4095) for b, v in brackets.items()}
    assert predicted_error(1.5, hists, response=r, noise=noise, clip_weight=1.0, **lv) == chosen
    with pytest.raises(ExposimError, match="no brackets"):
        predicted_error(1.5, {}, response=r, noise=noise, **lv)


def test_predicted_mse_table_is_finite_and_zero_at_identity():
    r = CameraResponse.gamma(2.2, 4094)
    noise = NoiseModel(shot=1e-5, floor=1e-10)
    for k in (0.001, 0.5, 1.0, 2.0, 1000.0):
        t = predicted_mse_table(r, k, noise, white_level=4094, black_level=0)
        assert t.shape == (4095,) and np.all(np.isfinite(t)) and np.all(t >= 0)
    # at k = 1 only the source's noise remains; clipped pixels carry none
    t1 = predicted_mse_table(r, 1.0, NoiseModel(0.0, 0.0), white_level=4094, black_level=0)
    assert t1.max() <= 1.0 / 12 + 1e-9


def test_oracle_and_excess():
    err = np.array([[3.0, 1.0, 1.0], [0.5, 2.0, np.nan]])
    np.testing.assert_array_equal(_oracle(err), [2, 0])  # ties go to the longer bracket
    ev = evaluate_choices(err, {"a": np.array([0, 0]), "o": _oracle(err)})
    assert ev["a"]["excess_over_oracle"]["max"] == pytest.approx(2.0)
    assert ev["o"]["excess_over_oracle"]["max"] == 0.0
    assert ev["a"]["agreement_with_oracle"] == 0.5


def test_cli_refuses_unknown_scene_and_response(tmp_path, capsys):
    from emulator.commands.cli import main

    assert main(["validate", "emulation", "--quick", "-o", str(tmp_path / "a"), "--scenes", "nope"]) == 1
    assert "unknown study scene 'nope'" in capsys.readouterr().err
    assert main(["validate", "selectors", "--quick", "-o", str(tmp_path / "b"), "--responses", "sepia"]) == 1
    assert "unknown camera response 'sepia'" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()
