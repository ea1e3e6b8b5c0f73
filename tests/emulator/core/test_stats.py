"""emulator.core.stats: resampling plans, intervals, Holm, TOST, variance components, tau-b."""

import numpy as np
import pytest
from scipy.stats import kendalltau

from emulator.core import stats


def test_bootstrap_indices_shape_range_and_seed():
    a = stats.bootstrap_indices(5, 100, seed=3)
    assert a.shape == (100, 5) and a.dtype == np.int64
    assert a.min() >= 0 and a.max() <= 4
    np.testing.assert_array_equal(a, stats.bootstrap_indices(5, 100, seed=3))
    with pytest.raises(ValueError, match="n_units"):
        stats.bootstrap_indices(0, 10)


def test_block_bootstrap_keeps_runs_of_consecutive_indices():
    idx = stats.block_bootstrap_indices(20, 50, seed=1, block_length=4)
    assert idx.shape == (50, 20)
    # within each block of 4 the indices step by 1 modulo n
    steps = (np.diff(idx.reshape(50, 5, 4), axis=2)) % 20
    assert np.all(steps == 1)
    assert stats.default_block_length(1000) == 10 and stats.default_block_length(1) == 1


def test_percentile_interval_exact_quantiles_and_inf():
    r = np.arange(1001, dtype=float)  # 0..1000
    lo, hi = stats.percentile_interval(r, 0.95)
    assert lo == pytest.approx(25.0) and hi == pytest.approx(975.0)
    r2 = r.copy()
    r2[:100] = np.nan  # 10 % undefined -> counted as +inf: the upper end is unbounded
    lo2, hi2 = stats.percentile_interval(r2, 0.95)
    assert hi2 == np.inf and np.isfinite(lo2)


def test_percentile_interval_bias_correction_centres_a_shifted_distribution():
    r = np.linspace(0, 1, 2001)
    # estimate at the median: no correction
    assert stats.percentile_interval(r, estimate=0.5) == pytest.approx(stats.percentile_interval(r), abs=1e-9)
    # estimate below the replicates' median: the interval moves down
    lo, hi = stats.percentile_interval(r, estimate=0.3)
    assert hi < 0.975 and lo < 0.025 + 1e-12


def test_statistic_interval_mean_covers_and_degenerate_cases():
    x = np.random.default_rng(0).normal(10.0, 1.0, 400)
    r = stats.statistic_interval(x, "mean", seed=0)
    assert r["ci95"][0] < 10.0 < r["ci95"][1]
    # the interval half-width is about 1.96 / sqrt(400) = 0.098
    assert 0.07 < (r["ci95"][1] - r["ci95"][0]) / 2 < 0.13
    assert stats.statistic_interval([], "mean")["estimate"] is None
    one = stats.statistic_interval([3.0, np.nan], "median")
    assert one["estimate"] == 3.0 and one["ci95"] is None and one["n"] == 1
    with pytest.raises(ValueError, match="statistic"):
        stats.statistic_interval(x, "mode")


def test_block_interval_is_wider_for_a_persistent_series():
    rng = np.random.default_rng(2)
    e = rng.normal(size=600)
    ar = np.empty(600)
    ar[0] = e[0]
    for i in range(1, 600):
        ar[i] = 0.9 * ar[i - 1] + e[i]
    iid = stats.statistic_interval(ar, "mean", seed=0)["ci95"]
    blk = stats.statistic_interval(ar, "mean", block=True, block_length=30, seed=0)["ci95"]
    assert (blk[1] - blk[0]) > 2 * (iid[1] - iid[0])


def test_difference_interval_paired():
    rng = np.random.default_rng(4)
    common = rng.normal(0, 10, 200)  # shared between the methods: cancels when paired
    a, b = common + 1.0 + rng.normal(0, 0.2, 200), common + rng.normal(0, 0.2, 200)
    r = stats.difference_interval(a, b, seed=0)
    assert r["excludes_zero"] and r["ci95"][0] > 0.9 and r["ci95"][1] < 1.1
    with pytest.raises(ValueError, match="aligned"):
        stats.difference_interval(a, b[:10])


def test_holm_reference_values_and_nan():
    np.testing.assert_allclose(stats.holm([0.01, 0.04, 0.03]), [0.03, 0.06, 0.06])
    np.testing.assert_allclose(stats.holm([0.5, np.nan, 0.01]), [0.5, np.nan, 0.02])
    assert stats.holm([0.9, 0.8]).tolist() == [1.0, 1.0]  # monotone: never below a smaller p's adjustment


def test_tost_paired_equivalence_and_not():
    rng = np.random.default_rng(1)
    d = rng.normal(0.0, 1.0, (100, 3))
    d[:, 2] += 2.0
    p = stats.tost_paired(d, 0.5)
    assert p[0] < 0.05 and p[1] < 0.05 and p[2] > 0.5
    assert stats.tost_paired(np.zeros((5,)), 0.1) == 0.0
    assert stats.tost_paired(np.array([1.0]), 0.1) == 1.0
    with pytest.raises(ValueError, match="margin"):
        stats.tost_paired(d, 0.0)


def test_variance_components_exact_and_unbiased():
    # noise-free: the method component is the variance of the method effects, the residual 0
    b = np.array([0.0, 1.0, 2.0, 6.0])
    x = b + np.array([[0.0], [5.0], [-3.0]])
    m, r = stats.variance_components(x)
    assert m == pytest.approx(b.var(ddof=1)) and r == pytest.approx(0.0)
    # with noise: unbiased over many tables (vectorised over the leading axis)
    rng = np.random.default_rng(0)
    xs = b + rng.normal(0, 2.0, (4000, 10, 4))
    m, r = stats.variance_components(xs)
    assert m.mean() == pytest.approx(b.var(ddof=1), rel=0.05)
    assert r.mean() == pytest.approx(4.0, rel=0.02)
    mc, rc = stats.covariance_components(xs, xs)
    np.testing.assert_allclose(mc, m)
    np.testing.assert_allclose(rc, r)


def test_kendall_tau_b_matches_scipy_and_ties_are_undefined():
    rng = np.random.default_rng(3)
    x = rng.integers(0, 4, (50, 7)).astype(float)
    y = rng.integers(0, 4, (50, 7)).astype(float)
    ours = stats.kendall_tau_b(x, y)
    for k in range(50):
        ref = kendalltau(x[k], y[k], variant="b").statistic
        if np.isnan(ref):
            assert np.isnan(ours[k])
        else:
            assert ours[k] == pytest.approx(ref)
    assert np.isnan(stats.kendall_tau_b(np.ones(7), np.arange(7.0)))


def test_compare_methods_best_difference_and_unaligned():
    rng = np.random.default_rng(0)
    common = rng.normal(0, 5, 200)  # shared by the aligned methods: cancels in the paired difference
    series = {"a": common + 10.0 + rng.normal(0, 0.3, 200), "b": common + 9.0 + rng.normal(0, 0.3, 200),
              "c": common[:150] + 9.5 + rng.normal(0, 0.3, 150), "d": []}
    r = stats.compare_methods(series, "mean", seed=0)
    assert r["best"] == "a" and r["methods"]["d"]["estimate"] is None
    b = r["methods"]["b"]["difference_to_best"]
    assert b["excludes_zero"] and -1.2 < b["ci95"][0] < b["ci95"][1] < -0.8  # paired: the shared part cancels
    lower = stats.compare_methods(series, "mean", higher_is_better=False, seed=0)
    assert lower["best"] == "b" and lower["methods"]["b"]["difference_to_best"] is None
    # unaligned (different lengths): independent resampling, the shared part no longer cancels: wider
    ca = stats.compare_methods({"a": series["a"], "c": series["c"]}, "mean", seed=1)
    d = ca["methods"]["c"]["difference_to_best"]
    assert d["ci95"][1] - d["ci95"][0] > 1.0 and d["excludes_zero"] is False


def test_compare_methods_by_segment_is_a_cluster_bootstrap_and_pairs_methods():
    from emulator.core.stats import compare_methods_by_segment, statistic_interval

    rng = np.random.default_rng(5)
    units = rng.normal(size=20)
    values = np.repeat(units, 50)  # 50 values per segment, all alike: 20 units, not 1000
    segments = np.repeat(np.arange(20), 50)
    res = compare_methods_by_segment({"a": values, "b": values + 0.25, "c": values[:500]},
                                     {"a": segments, "b": segments, "c": segments[:500]}, "median",
                                     block_length=1, n_resamples=500, seed=3)
    ref = statistic_interval(units, "median", n_resamples=500, seed=3)  # the same draws over the 20 units
    a = res["methods"]["a"]
    assert a["estimate"] == ref["estimate"] and a["ci95"] == ref["ci95"]
    assert (a["n"], a["n_segments"], res["best"]) == (1000, 20, "a")
    # b = a + 0.25 on the same segments: paired, so the difference is 0.25 in every resample
    d = res["methods"]["b"]["difference_to_best"]
    assert d["estimate"] == pytest.approx(0.25) and d["ci95"] == pytest.approx([0.25, 0.25]) and d["excludes_zero"]
    # c is on other segments (10 of them): resampled on its own, an interval that holds its difference
    c = res["methods"]["c"]
    assert c["n_segments"] == 10 and c["difference_to_best"]["ci95"][0] < c["difference_to_best"]["estimate"]
    one = compare_methods_by_segment({"a": [1.0, 2.0]}, {"a": [0, 0]})
    assert one["methods"]["a"]["ci95"] is None and one["methods"]["a"]["estimate"] == 1.5
