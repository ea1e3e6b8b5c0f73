"""M_Zhang against spec section 6 (borealhdr, full 1200x1920 frames) and paper-mode behaviour."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from emulator.autoexposure import Zhang2017
from emulator.autoexposure.zhang import REF_PIXELS, ref_icrf_derivative, sine_weights, sorted_values
from emulator.io.pcalib import read_response

FULL = (1200, 1920)


@pytest.fixture(scope="module")
def pcalib(pcalib_path):
    return read_response(pcalib_path)


@pytest.fixture(scope="module")
def crf_scene(pcalib):
    """Spec's CRF block scene: raw = CRF(clip(base k t)) with the pcalib CRF, truncated, full size."""
    rng = np.random.default_rng(1)
    h, w = FULL
    blocks = rng.uniform(0.2, 1.8, (h // 16 + 1, w // 16 + 1))
    base = np.kron(blocks, np.ones((16, 16)))[:h, :w] * rng.uniform(0.97, 1.03, FULL)
    e = 16.0 * pcalib.knots
    e[0], e[-1] = 0.0, 4095.0
    dn = np.linspace(0.0, 4095.0, e.size)

    def make(k, t):
        return np.interp(np.clip(base * k * t, 0, 4095), e, dn).astype(np.uint16)

    return make


def test_weights_and_icrf_derivative(pcalib):
    w = sine_weights(REF_PIXELS, 0.8, 5, "l2")
    assert w.sum() == pytest.approx(1038.9, abs=0.05)
    assert np.linalg.norm(w) == pytest.approx(1.0)
    assert sine_weights(1000, 0.7, 5, "sum").sum() == pytest.approx(1.0)
    h = ref_icrf_derivative(pcalib.knots)
    assert h[0] == pytest.approx(-0.34, abs=0.01)
    assert h[4095] == pytest.approx(4.78, abs=0.01)
    crossing = int(np.argmax(h > 0))
    assert 230 <= crossing <= 245 and np.all(h[:crossing] < 0)
    assert np.abs(h).min() > 1e-4  # never 0 on integer DN: the non-finite guard never fires


def test_fallback_is_classical_50_with_abs():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        m = Zhang2017(mode="borealhdr")
    low = np.full(FULL, 394, np.uint16)
    assert m.next_exposure(low, 1.0) == pytest.approx(4.308)
    high = np.full(FULL, 3068, np.uint16)
    assert m.next_exposure(high, 16.0) == pytest.approx(13.96)
    white = np.full((64, 64), 4095, np.uint16)
    assert m.next_exposure(white, 4.094) == 0.02  # |4.094 - 4.094| = 0 -> floor


def test_dead_band_without_crf_and_flat_gray(pcalib):
    with pytest.warns(UserWarning, match="dead band"):
        ident = Zhang2017(mode="borealhdr")
    with pytest.warns(UserWarning, match="linear response"):
        Zhang2017(mode="paper")
    rng = np.random.default_rng(0)
    textured = np.clip(rng.normal(2048, 300, (240, 320)), 0, 4095).astype(np.uint16)
    # identity CRF: D constant (to rounding), d ~ 0 inside the band
    assert ident.next_exposure(textured, 5.5) == pytest.approx(5.5, abs=1e-9)
    flat = np.full((240, 320), 2048, np.uint16)
    for mode in ("borealhdr", "paper"):
        m = Zhang2017(mode=mode, response=pcalib)
        out = m.next_exposure(flat, 7.25)
        assert out == 7.25 and type(out) is float


@pytest.mark.slow
def test_spec_single_steps_and_closed_loop(crf_scene, pcalib):
    m = Zhang2017(mode="borealhdr", response=pcalib)
    for t, expected, tol in ((4.0, 4.23, 0.005), (8.0, 7.98, 0.005), (12.0, 11.975, 0.0015)):
        assert m.next_exposure(crf_scene(100, t), t) == pytest.approx(expected, abs=tol)
    t, traj = 4.0, []
    for _ in range(25):
        t = m.next_exposure(crf_scene(100, t), t)
        traj.append(t)
    steps = np.diff(np.r_[4.0, traj])
    assert np.all(steps > 0) and np.all(steps < 0.25)
    assert traj[-1] == pytest.approx(5.4, abs=0.05)


@pytest.mark.slow
def test_ref_step_scales_with_image_size(pcalib):
    """Off the reference size gamma is scaled by sqrt(S_ref / S): a block scene with the same
    statistics at 1/16 of the pixels steps like the full frame."""
    e = 16.0 * pcalib.knots
    e[0], e[-1] = 0.0, 4095.0
    dn = np.linspace(0.0, 4095.0, e.size)
    steps = []
    for shape in (FULL, (300, 480)):
        rng = np.random.default_rng(5)
        blocks = rng.uniform(0.2, 1.8, (shape[0] // 16 + 1, shape[1] // 16 + 1))
        base = np.kron(blocks, np.ones((16, 16)))[: shape[0], : shape[1]] * rng.uniform(0.97, 1.03, shape)
        raw = np.interp(np.clip(base * 100 * 4.0, 0, 4095), e, dn).astype(np.uint16)
        steps.append(Zhang2017(mode="borealhdr", response=pcalib).next_exposure(raw, 4.0) - 4.0)
    assert steps[0] > 0 and abs(steps[1] / steps[0] - 1) < 0.25


def test_paper_mode_converges_from_both_sides(pcalib):
    rng = np.random.default_rng(2)
    shape = (300, 480)
    blocks = rng.uniform(0.2, 1.8, (shape[0] // 16 + 1, shape[1] // 16 + 1))
    base = np.kron(blocks, np.ones((16, 16)))[: shape[0], : shape[1]] * rng.uniform(0.97, 1.03, shape)
    e = 16.0 * pcalib.knots
    dn = np.linspace(0.0, 4095.0, e.size)

    def capture(t):
        return np.interp(np.clip(base * 100 * t, 0, 4095), e, dn).astype(np.uint16)

    ends = []
    for t0 in (2.0, 30.0):
        m, t, traj = Zhang2017(mode="paper", response=pcalib), t0, []
        for _ in range(40):
            t_new = m.next_exposure(capture(t), t)
            assert abs(t_new / t - 1) <= 0.1 + 1e-12  # Zhang's +-10 % clamp
            t = t_new
            traj.append(t)
        assert (traj[0] > t0) if t0 < 5 else (traj[0] < t0)
        ends.append(t)
    assert abs(ends[0] / ends[1] - 1) < 0.05
    assert 6.0 < ends[0] < 16.0  # a mid exposure (gradient-rich, little saturation)
    for t in ends:
        assert 1120 < capture(t).mean() < 3300


def test_percentile_is_named_as_the_fraction_it_is_and_the_old_name_still_works(pcalib):
    from emulator.autoexposure import make_method
    from emulator.autoexposure.base import AutoExposureError

    new = make_method("zhang", mode="paper", percentile_fraction=0.6)
    old = make_method("zhang", mode="paper", percentile=0.6)  # deprecated alias (--option zhang.percentile=0.6)
    assert new.percentile_fraction == old.percentile_fraction == old.percentile == 0.6
    assert make_method("zhang", mode="paper").percentile_fraction == 0.7
    assert make_method("zhang", mode="borealhdr", response=pcalib).percentile_fraction == 0.8
    assert new._options()["percentile_fraction"] == 0.6 and "percentile" not in new._options()
    with pytest.raises(AutoExposureError, match="percentile_fraction 0.6 and its deprecated alias percentile 0.7"):
        make_method("zhang", percentile_fraction=0.6, percentile=0.7)
    with pytest.raises(AutoExposureError, match="percentile_fraction must be a fraction in \\(0, 1\\), got 60"):
        make_method("zhang", percentile_fraction=60.0)


def test_sorted_values_equals_numpy_sort_bit_for_bit():
    """The derivative's fast sort gives np.sort's array: on a wide spread of magnitudes and signs with
    repeated values, infinities, NaNs, signed zeros and subnormals, and on a size below its threshold."""
    rng = np.random.default_rng(7)
    n = 300_000
    d = rng.standard_normal(n) * np.exp2(rng.integers(-60, 60, n))
    d[rng.integers(0, n, 5000)] = 3.0  # runs of one value
    d[rng.integers(0, n, 300)] = np.nan
    d[rng.integers(0, n, 300)] = -np.inf
    d[rng.integers(0, n, 300)] = np.inf
    d[rng.integers(0, n, 300)] = 5e-324
    d[rng.integers(0, n, 300)] = -5e-324
    d[rng.integers(0, n, 500)] = 0.0
    zeros = rng.integers(0, n, 500)
    d[zeros] = -0.0
    for x in (d, d[:1000], np.sort(d)[::-1].copy()):
        got, want = sorted_values(x), np.sort(x)
        assert got.dtype == np.float64 and got.shape == want.shape
        assert np.array_equal(got, want, equal_nan=True)
        # equal-comparing values may swap (only 0.0 and -0.0 here); every other value keeps its bits
        nonzero = want != 0
        assert np.array_equal(got[nonzero].view(np.int64)[~np.isnan(want[nonzero])],
                              want[nonzero].view(np.int64)[~np.isnan(want[nonzero])])
    assert sorted_values(d).size == n and np.isnan(sorted_values(d)[-300:]).any()


def test_ref_derivative_equals_the_plain_sort(crf_scene, pcalib):
    """borealhdr's m = sum w_i d_(i) with the fast sort equals the one through np.sort, to the bit."""
    z = Zhang2017(response=pcalib, mode="borealhdr")
    y = crf_scene(1.0, 4.0)
    d, _ = z._products(y, 1.0 / (z._h * 4.0), with_g2=False)
    w = sine_weights(d.size, z.percentile_fraction, z.order, "l2")
    assert z._ref_derivative(y, 4.0) == float(np.dot(w, np.sort(d)))
