"""Emulation against exact ground truth (noiseless forward model through the same response)."""

import numpy as np
import pytest

from emulator import CameraResponse, EmulationError
from emulator.core.emulate import emulate
from emulator.io.pcalib import read_response

#: These tests use synthetic responses over the full 12-bit range (the BorealHDR default is 4094).
FULL_12BIT = 4095

RATIOS = [(1, 2), (1, 32), (2, 32), (8, 16), (1, 3.7), (4, 4.01), (2, 9.5)]
DOWN = [(2, 1), (32, 1), (32, 5.3), (16, 8), (8, 0.02), (4, 3.99)]


def _radiance(shape=(256, 256), seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.0, 1.0, shape)


def _capture(response, t_ms, E):
    """Exact noiseless capture: DN = clip(round(f(t * E)), black, white)."""
    dn = np.rint(response.forward(t_ms * E))
    return np.clip(dn, response.black_level, response.white_level).astype(np.uint16)


@pytest.mark.parametrize("source_ms,target_ms", RATIOS + DOWN)
def test_linear_response_within_quantisation_bound(source_ms, target_ms):
    r = CameraResponse.linear(FULL_12BIT)
    E = _radiance() / 32.0  # h = t*E in units where g(4095) = 1
    src = _capture(r, source_ms, E)
    truth = _capture(r, target_ms, E)
    emu, valid = emulate(src, source_ms, target_ms, r, return_mask=True)
    assert emu.dtype == np.uint16 and emu.shape == src.shape
    k = target_ms / source_ms
    inside = (src > 0) & (src < 4095) & (truth > 0) & (truth < 4095)
    assert inside.mean() > 0.02
    err = np.abs(emu.astype(int) - truth.astype(int))[inside]
    if k <= 1:
        assert err.max() <= 1
    elif float(k).is_integer():
        # round(k * round(x)) vs round(k x): |k e| <= k/2 plus one rounding, integer k.
        assert err.max() <= k / 2 + 0.5
    else:
        # Non-integer ratio: two independent roundings, strictly below k/2 + 1.
        assert err.max() < k / 2 + 1
    assert valid[inside].all()


def _bound_nonlinear(r, src, k):
    """Per-pixel analytic bound for a nonlinear response.

    The source DN d stands for any h in [g(d - 1/2), g(d + 1/2)]; scaled by k and mapped
    through f, that interval [lo, hi] holds the true target, while the emulator returns
    f(k g(d)); the error is at most the larger distance to the interval's ends, plus one
    rounding.
    """
    d = src.astype(np.float64)
    lo = r.forward(k * r.inverse(np.clip(d - 0.5, 0, r.white_level)))
    hi = r.forward(k * r.inverse(np.clip(d + 0.5, 0, r.white_level)))
    mid = r.forward(k * r.inverse(d))
    return np.maximum(hi - mid, mid - lo) + 1.0


@pytest.mark.parametrize("source_ms,target_ms", RATIOS + DOWN)
def test_real_borealhdr_response_within_bound(pcalib_path, source_ms, target_ms):
    r = read_response(pcalib_path)
    E = _radiance(seed=1) * r.g[-1] / 32.0
    src = _capture(r, source_ms, E)
    truth = _capture(r, target_ms, E)
    emu = emulate(src, source_ms, target_ms, r)
    k = target_ms / source_ms
    # Clipping is 1-Lipschitz, so the bound holds wherever the source was not clipped.
    inside = (src > 0) & (src < 4095)
    err = np.abs(emu.astype(float) - truth.astype(float))
    bound = _bound_nonlinear(r, src, k)
    assert np.all(err[inside] <= bound[inside] + 1e-9)
    if k < 1:
        # Shorter from longer, above the response's flat foot (DN < 100, where one DN of g
        # spans several DN of f): within 1 DN except where g is so convex that
        # g'(source) > 2 g'(target) / k (the per-pixel bound above covers those).
        steep = inside & (truth >= 100)
        if steep.any():
            assert np.mean(err[steep] <= 1) >= 0.999
            assert err[steep].max() <= 2


@pytest.mark.parametrize("which", ["linear", "pcalib"])
def test_identity_and_round_trip_below_saturation(pcalib_path, which):
    r = CameraResponse.linear(FULL_12BIT) if which == "linear" else read_response(pcalib_path)
    raw = np.arange(4096, dtype=np.uint16).reshape(64, 64)
    np.testing.assert_array_equal(emulate(raw, 8.0, 8.0, r), raw)
    # t1 -> t2 -> t1 with t2 > t1 returns within 1 DN where t2 does not saturate (and,
    # for the real response, above its flat foot below DN 100).
    up = emulate(raw, 4.0, 8.0, r)
    back = emulate(up, 8.0, 4.0, r)
    ok = (up < 4095) & (raw >= (0 if which == "linear" else 100))
    assert np.abs(back.astype(int) - raw.astype(int))[ok].max() <= 1


def test_clipping_and_mask():
    r = CameraResponse.linear(FULL_12BIT, black_level=64)
    raw = np.array([[0, 64, 65, 2000], [3000, 4094, 4095, 100]], dtype=np.uint16)
    up, m_up = emulate(raw, 1.0, 2.0, r, return_mask=True)
    assert up.min() >= 64 and up.max() <= 4095
    # linear with a black offset: DN = 64 + k * (d - 64), rounded half to even, clipped
    np.testing.assert_array_equal(up[0], [64, 64, 66, 3936])
    np.testing.assert_array_equal(up[1], [4095, 4095, 4095, 136])
    # black sources are invalid when brightening, saturated ones stay valid
    np.testing.assert_array_equal(m_up, [[False, False, True, True], [True, True, True, True]])
    down, m_down = emulate(raw, 2.0, 1.0, r, return_mask=True)
    np.testing.assert_array_equal(down[0], [64, 64, 64, 1032])
    np.testing.assert_array_equal(down[1], [1532, 2079, 2080, 82])
    # saturated sources are invalid when darkening, black ones stay valid
    np.testing.assert_array_equal(m_down, [[True, True, True, True], [True, True, False, True]])


def test_lut_is_cached_per_ratio():
    r = CameraResponse.gamma(2.2, FULL_12BIT)
    a = r.lut(2.5)
    b = r.lut(2.5)
    assert a[0] is b[0]
    raw = np.arange(4096, dtype=np.uint16).reshape(64, 64)
    out = emulate(raw, 2.0, 5.0, r)
    np.testing.assert_array_equal(out.ravel(), a[0])


def test_large_image_threaded_path_matches_small(pcalib_path):
    r = read_response(pcalib_path)
    rng = np.random.default_rng(5)
    raw = rng.integers(0, 4096, (1200, 1920), dtype=np.uint16)
    out = emulate(raw, 4.0, 9.0, r)
    table, _ = r.lut(9.0 / 4.0)
    np.testing.assert_array_equal(out, table[raw])


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "x", None])
def test_bad_exposures(bad):
    raw = np.zeros((4, 4), np.uint16)
    r = CameraResponse.linear(FULL_12BIT)
    with pytest.raises(EmulationError, match="source_ms"):
        emulate(raw, bad, 1.0, r)
    with pytest.raises(EmulationError, match="target_ms"):
        emulate(raw, 1.0, bad, r)


def test_bad_images():
    r = CameraResponse.linear(FULL_12BIT)
    with pytest.raises(EmulationError, match="uint16"):
        emulate(np.zeros((4, 4), np.float32), 1, 2, r)
    with pytest.raises(EmulationError, match="uint16"):
        emulate(np.zeros((4, 4), np.uint8), 1, 2, r)
    with pytest.raises(EmulationError, match="2-D"):
        emulate(np.zeros((4, 4, 3), np.uint16), 1, 2, r)
    with pytest.raises(EmulationError, match="empty"):
        emulate(np.zeros((0, 4), np.uint16), 1, 2, r)
    raw = np.zeros((4, 4), np.uint16)
    raw[2, 3] = 5000
    with pytest.raises(EmulationError, match=r"1 pixel\(s\) above white_level=4095 .*row 2, col 3"):
        emulate(raw, 1, 2, r)
    with pytest.raises(EmulationError, match="numpy array"):
        emulate([[1, 2]], 1, 2, r)


def test_extreme_ratios_stay_finite_and_clipped(pcalib_path):
    r = read_response(pcalib_path)
    raw = np.arange(4096, dtype=np.uint16).reshape(64, 64)
    for s, t in [(32.0, 0.02), (1.0, 50.0), (1e-6, 1e6)]:
        out = emulate(raw, s, t, r)
        assert out.dtype == np.uint16 and out.min() >= 0 and out.max() <= 4095
        assert np.all(np.diff(out.ravel().astype(int)) >= 0)  # monotone in the source DN


@pytest.mark.parametrize("ratio", [0.25, 0.999, 1.0, 1.5, 40.0])
def test_mask_by_comparison_equals_mask_table(ratio):
    from emulator.core.emulate import validity_mask

    r = CameraResponse.gamma(2.2, FULL_12BIT, black_level=10).with_levels(white_level=4094)
    raw = np.arange(4095, dtype=np.uint16).reshape(63, 65)
    np.testing.assert_array_equal(validity_mask(raw, ratio, r), r.lut(ratio)[1][raw])


def test_lut_cache_is_thread_safe_under_eviction(monkeypatch):
    from concurrent.futures import ThreadPoolExecutor

    import emulator.core.response as resp

    monkeypatch.setattr(resp, "LUT_CACHE_SIZE", 4)
    r = CameraResponse.gamma(2.2, FULL_12BIT)
    ratios = [1 + (i % 23) / 7 for i in range(400)]
    with ThreadPoolExecutor(4) as pool:
        tables = list(pool.map(lambda k: r.lut(k)[0], ratios))
    for k, t in zip(ratios[:30], tables[:30]):
        np.testing.assert_array_equal(t, CameraResponse.gamma(2.2, FULL_12BIT).lut(k)[0])
    assert len(r._luts) <= 4


def test_both_gather_paths_agree(monkeypatch):
    import importlib

    em = importlib.import_module("emulator.core.lut")  # the module that holds the gather

    rng = np.random.default_rng(9)
    raw = rng.integers(0, 4096, (1200, 1920), dtype=np.uint16)
    table = CameraResponse.gamma(2.2, FULL_12BIT).lut(1.7)[0]
    fast = em.apply_lut(table, raw)
    monkeypatch.setattr(em, "_CV_LUT_U16", False)  # the OpenCV 4 fallback: blocked np.take
    slow = em.apply_lut(table, raw)
    np.testing.assert_array_equal(fast, table[raw])
    np.testing.assert_array_equal(slow, table[raw])
    assert fast.dtype == slow.dtype == np.uint16
