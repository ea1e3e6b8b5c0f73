"""Fault suite, issue 24 (public API): every bad argument raises an ExposimError subclass that
names it, instead of a table, a number, or a bare AttributeError / ValueError."""

from __future__ import annotations

import math

import numpy as np
import pytest

from emulator.calibration.stack_engel2016 import fit_inverse_response
from emulator.core.emulate import emulate
from emulator.errors import CalibrationError, EmulationError, ExposimError, ResponseError
from emulator.core.response import CameraResponse
from emulator.core.select import saturated_fraction, select


@pytest.fixture(scope="module")
def response():
    return CameraResponse.linear(4095)


@pytest.mark.parametrize("ratio", [math.nan, -1.0, 0.0, math.inf, True, "2"])
def test_lut_refuses_ratios_that_are_not_finite_positive_numbers(response, ratio):
    with pytest.raises(ResponseError, match="ratio"):
        response.lut(ratio)


def test_lut_of_a_valid_ratio_still_works(response):
    table, valid = response.lut(2.0)
    assert table[100] == 200 and valid[100] and table[4000] == 4095


def test_saturated_fraction_refuses_white_at_or_below_black():
    raw = np.arange(100, dtype=np.uint16).reshape(10, 10)
    with pytest.raises(ExposimError, match="white_level 10 must exceed black_level 4000"):
        saturated_fraction(raw, white_level=10, black_level=4000)
    with pytest.raises(ExposimError, match="white_level"):
        saturated_fraction(raw, white_level=5, black_level=5)
    assert saturated_fraction(raw, white_level=99, black_level=0) == 0.02


def test_duplicate_bracket_keys_are_refused():
    from emulator.core.select import _sorted_brackets

    with pytest.raises(ExposimError, match=r"brackets given twice: 4 ms \(keys '4', 4.0\)"):
        select("higher-no-sat", 6.0, {"4": 0.0, 4.0: 0.0, 8.0: 0.0}, white_level=4095, black_level=0)
    with pytest.raises(ExposimError, match="bracket exposure_ms must be a number of milliseconds, got True"):
        select("higher-no-sat", 6.0, {True: 0.0, 8.0: 0.0}, white_level=4095, black_level=0)
    assert select("higher-no-sat", 6.0, {"4": 0.0, "8": 0.0}, white_level=4095, black_level=0) == "8"
    with pytest.raises(ExposimError, match="brackets given twice: 4 ms"):
        _sorted_brackets(_TwoFours())


class _TwoFours(dict):
    """A mapping whose keys are two objects both equal to 4 ms (as '4' and 4.0 were)."""

    def __init__(self):
        super().__init__({_Ms(4.0, "a"): 0.0, _Ms(4.0, "b"): 0.0, 8.0: 0.0})


class _Ms(float):
    def __new__(cls, value, tag):
        obj = super().__new__(cls, value)
        obj.tag = tag
        return obj

    def __hash__(self):
        return hash(self.tag)

    def __eq__(self, other):
        return self is other


def test_emulate_refuses_a_missing_response_and_exposures_that_are_not_numbers(response):
    raw = np.full((8, 8), 100, np.uint16)
    with pytest.raises(EmulationError, match="response must be a CameraResponse, got NoneType"):
        emulate(raw, 4.0, 8.0, None)
    for bad in (True, "8"):
        with pytest.raises(EmulationError, match=r"must be a number of milliseconds, got"):
            emulate(raw, 4.0, bad, response)
        with pytest.raises(EmulationError, match=r"must be a number of milliseconds, got"):
            emulate(raw, bad, 8.0, response)
    assert int(emulate(raw, 4.0, 8.0, response)[0, 0]) == 200


def test_fit_inverse_response_on_nan_is_a_calibration_error():
    dn = np.full((3, 64), 1000.0)
    dn[1, 5] = np.nan
    with pytest.raises(CalibrationError, match="NaN or infinity"):
        fit_inverse_response(dn, [1.0, 2.0, 4.0])
