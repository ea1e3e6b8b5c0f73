import numpy as np
import pytest

from emulator import ExposimError, closest, higher_no_sat, saturated_fraction
from emulator.core.select import select
from emulator.core.select import reference_rule

BR = [1.0, 2.0, 4.0, 8.0, 16.0, 32.0]
LV = dict(white_level=4095, black_level=0)


def fractions(**over):
    f = {b: 0.0 for b in BR}
    f.update({float(k): v for k, v in over.items()})
    return f


def test_inside_range_picks_higher_when_unsaturated():
    assert higher_no_sat(5.3, fractions(), **LV) == 8.0
    assert higher_no_sat(1.01, fractions(), **LV) == 2.0


def test_equal_to_a_bracket_uses_it_even_if_saturated():
    assert higher_no_sat(8.0, fractions(**{"8.0": 0.9}), **LV) == 8.0
    assert higher_no_sat(8.0 * (1 + 1e-12), fractions(), **LV) == 8.0


def test_below_and_above_range_use_closest_end():
    assert higher_no_sat(0.02, fractions(**{"1.0": 0.5}), **LV) == 1.0
    assert higher_no_sat(50.0, fractions(**{"32.0": 0.9}), **LV) == 32.0


def test_threshold_is_strict_at_one_percent():
    assert higher_no_sat(5.0, fractions(**{"8.0": 0.01}), **LV) == 4.0
    assert higher_no_sat(5.0, fractions(**{"8.0": 0.0099999}), **LV) == 8.0
    assert higher_no_sat(5.0, fractions(**{"8.0": 0.5, "4.0": 0.9}), **LV) == 4.0


def test_images_both_clip_ends_count():
    white, black = 4094, 0
    hi = np.full((100, 100), 2000, np.uint16)
    lo = np.full((100, 100), 1000, np.uint16)
    hi.flat[:50] = white  # 0.5 % high
    hi.flat[50:100] = black  # 0.5 % low -> 1.0 % total: not below 1 %
    assert saturated_fraction(hi, white_level=white, black_level=black) == pytest.approx(0.01)
    assert higher_no_sat(5.0, {4.0: lo, 8.0: hi}, white_level=white, black_level=black) == 4.0
    hi.flat[99] = 1500
    assert higher_no_sat(5.0, {4.0: lo, 8.0: hi}, white_level=white, black_level=black) == 8.0


def test_keys_are_returned_as_given():
    assert higher_no_sat(3.0, {"2.0": 0.0, "4.0": 0.0}, **LV) == "4.0"


def test_closest_in_log_space():
    f = fractions()
    assert closest(5.0, f) == 4.0
    assert closest(6.0, f) == 8.0  # log(6/4) = 0.405 > log(8/6) = 0.288
    assert closest(np.sqrt(32.0), f) == 8.0  # exact tie in log space -> higher
    assert closest(0.02, f) == 1.0 and closest(99.0, f) == 32.0


def test_reference_rule():
    assert reference_rule(5.0, fractions(**{"8.0": 0.3, "4.0": 0.4}), **LV) == 8.0
    assert reference_rule(5.0, fractions(**{"8.0": 0.3, "4.0": 0.2}), **LV) == 4.0


def test_front_function_and_errors():
    assert select("higher-no-sat", 5.0, fractions(), **LV) == 8.0
    with pytest.raises(ExposimError, match="unknown selector 'best'; choose one of higher-no-sat, closest"):
        select("best", 5.0, fractions(), **LV)
    with pytest.raises(ExposimError, match="no brackets"):
        higher_no_sat(5.0, {}, **LV)
    with pytest.raises(ExposimError, match="target_ms"):
        higher_no_sat(float("nan"), fractions(), **LV)
    with pytest.raises(ExposimError, match=r"saturated fraction must lie in \[0, 1\]"):
        higher_no_sat(5.0, fractions(**{"8.0": 1.5}), **LV)


def test_predicted_error_selector():
    from emulator import CameraResponse
    from emulator.core.select import NoiseModel, predicted_error, predicted_mse_table

    r = CameraResponse.linear(4095)  # full 12-bit range, as the images below
    quiet = NoiseModel(shot=0.0, floor=0.0)
    mid = np.full((50, 50), 1500, np.uint16)
    # noiseless linear camera: darkening (k < 1) has less quantisation error than brightening
    assert predicted_error(5.0, {4.0: mid, 8.0: mid}, response=r, noise=quiet, **LV) == 8.0
    # k = 1/2 maps source DN d exactly to d/2 +- 1/4: predicted MSE is (1/4)^2 / 3 per pixel
    table = predicted_mse_table(r, 0.5, quiet, **LV)
    assert table[1500] == pytest.approx((0.25**3 + 0.25**3) / (3 * 0.5))
    # a bracket mostly saturated at white loses to the unsaturated shorter one
    hot = mid.copy()
    hot[:40] = 4095
    choice, scores = predicted_error(5.0, {4.0: mid, 8.0: hot}, response=r, noise=quiet, clip_weight=2.0,
                                     return_scores=True, **LV)
    assert choice == 4.0 and scores[8.0] > scores[4.0]
    # histograms work as well as images
    hist = np.bincount(mid.ravel(), minlength=4096)
    assert predicted_error(5.0, {4.0: hist, 8.0: hist}, response=r, noise=quiet, **LV) == 8.0
    with pytest.raises(ExposimError, match="no brackets"):
        predicted_error(5.0, {}, response=r, noise=quiet, **LV)


def test_blur_aware_weighs_excess_blur_against_noise():
    from emulator.core.select import blur_aware, higher_no_sat

    br = {4.0: 0.0, 8.0: 0.0, 16.0: 0.0}
    lv = dict(white_level=4095, black_level=0)
    # no motion: HigherNoSat, for every target
    for t in (1.0, 4.0, 5.0, 12.0, 40.0):
        assert blur_aware(t, br, **lv) == higher_no_sat(t, br, **lv)
        assert blur_aware(t, br, **lv, excess_blur_px=lambda b: 0.0) == higher_no_sat(t, br, **lv)
    # target 12 between 8 and 16: the lower bracket costs sqrt(12/8) - 1 = 0.2247 of noise
    cost = 12.0 ** 0.5 / 8.0 ** 0.5 - 1.0
    assert blur_aware(12.0, br, **lv, excess_blur_px=lambda b: cost * 0.99) == 16.0
    assert blur_aware(12.0, br, **lv, excess_blur_px=lambda b: cost * 1.01) == 8.0
    assert blur_aware(12.0, br, **lv, excess_blur_px=lambda b: 2 * cost, px_per_noise=2.0 / 0.99) == 16.0
    # a saturated higher bracket is never chosen, and NaN blur counts as none
    assert blur_aware(12.0, {8.0: 0.0, 16.0: 0.5}, **lv, excess_blur_px=lambda b: 0.0) == 8.0
    assert blur_aware(12.0, br, **lv, excess_blur_px=lambda b: float("nan")) == 16.0
    with pytest.raises(ExposimError, match="px_per_noise"):
        blur_aware(12.0, br, **lv, px_per_noise=0.0)
