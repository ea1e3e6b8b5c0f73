"""Faults of the public API: a bad argument raises one ExposimError subclass that names it (two suites written independently, one after the other).

Fault suite, issue 24 (public API): every bad argument raises an ExposimError subclass that
names it, instead of a table, a number, or a bare AttributeError / ValueError.
"""

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


# ------------------------------------------------------------------------------------------------
# Public-API misuse (issue 24), written independently of the suite above: each call
# raises one ``ExposimError`` subclass whose message names the argument, never a bare
# NumPy/Python error or a wrong answer.
# ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def raw():
    return np.random.default_rng(0).integers(0, 4096, (8, 12)).astype(np.uint16)


@pytest.mark.parametrize("ratio", [math.nan, 0.0, -1.0, math.inf, -math.inf, "2", None, True, np.float64("nan")])
def test_lut_refuses_bad_ratios(response, ratio):
    with pytest.raises(ResponseError, match="ratio"):
        response.lut(ratio)


@pytest.mark.parametrize("ratio", [1.0, 2, np.float32(0.5), 1e-6, 1e6])
def test_lut_takes_good_ratios(response, ratio):
    table, valid = response.lut(ratio)
    assert table.shape == valid.shape == (4096,)
    assert table.dtype == np.uint16 and int(table.max()) <= 4095
    # emulating at ratio k is f(k g(d)): for a linear response exactly clip(round(k d))
    expected = np.clip(np.rint(float(ratio) * np.arange(4096)), 0, 4095)
    assert np.array_equal(table, expected.astype(np.uint16))


def test_lut_results_cannot_be_changed_by_a_caller(response):
    table, valid = response.lut(2.0)
    with pytest.raises(ValueError):
        table[0] = 7
    assert response.lut(2.0)[0][5] == 10


@pytest.mark.parametrize("white, black", [(10, 4000), (100, 100), (math.nan, 0), (4095, -1)])
def test_saturated_fraction_refuses_bad_levels(raw, white, black):
    with pytest.raises(ExposimError, match="white_level|black_level"):
        saturated_fraction(raw, white_level=white, black_level=black)


def test_saturated_fraction_value(raw):
    got = saturated_fraction(raw, white_level=4095, black_level=0)
    assert got == np.count_nonzero((raw >= 4095) | (raw <= 0)) / raw.size
    assert 0.0 <= got <= 1.0


def test_duplicate_bracket_keys_of_frames_are_refused(raw):
    with pytest.raises(ExposimError, match="4"):
        select("higher-no-sat", 6.0, {"4": raw, 4.0: raw, 8.0: raw}, white_level=4095, black_level=0)


def test_emulate_refuses_no_response(raw):
    with pytest.raises(EmulationError, match="response"):
        emulate(raw, 4.0, 8.0, None)


@pytest.mark.parametrize("value", [True, "8", math.nan, -1.0, 0.0, math.inf, None, np.bool_(True), [8.0]])
@pytest.mark.parametrize("which", ["source_ms", "target_ms"])
def test_emulate_refuses_bad_exposures(raw, response, value, which):
    args = {"source_ms": 4.0, "target_ms": 8.0, which: value}
    with pytest.raises(EmulationError, match=which):
        emulate(raw, args["source_ms"], args["target_ms"], response)


@pytest.mark.parametrize("bad", [np.zeros((8, 12), np.float64), np.zeros((8, 12, 3), np.uint16),
                                 np.zeros((0, 0), np.uint16), np.full((8, 12), 5000, np.uint16),
                                 np.zeros((8, 12), np.int16), [[1, 2], [3, 4]]])
def test_emulate_refuses_bad_images(response, bad):
    with pytest.raises(EmulationError, match="raw"):
        emulate(bad, 4.0, 8.0, response)


def test_emulate_does_not_change_its_input(raw, response):
    before = raw.copy()
    out = emulate(raw, 4.0, 8.0, response)
    assert np.array_equal(raw, before)
    assert np.array_equal(out, np.clip(2 * raw.astype(np.int64), 0, 4095).astype(np.uint16))


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_fit_inverse_response_refuses_non_finite_samples(bad):
    from emulator.calibration.stack_engel2016 import fit_inverse_response

    dn = np.random.default_rng(0).integers(100, 3000, (3, 50)).astype(np.float64)
    dn[1, 7] = bad
    with pytest.raises(CalibrationError, match="(?i)nan|finite|inf"):
        fit_inverse_response(dn, [1.0, 2.0, 4.0], max_iter=2)


@pytest.mark.parametrize("exposures", [[1.0, math.nan, 4.0], [1.0, -2.0, 4.0], [1.0, 0.0, 4.0]])
def test_fit_inverse_response_refuses_bad_exposures(exposures):
    from emulator.calibration.stack_engel2016 import fit_inverse_response

    dn = np.random.default_rng(0).integers(100, 3000, (3, 50)).astype(np.uint16)
    with pytest.raises(CalibrationError, match="exposure"):
        fit_inverse_response(dn, exposures, max_iter=2)


@pytest.mark.parametrize("g", [np.array([0.0, 1.0, math.nan, 3.0]), np.array([0.0, 2.0, 1.0, 3.0]),
                               np.array([0.0, 1.0, math.inf, 3.0])])
def test_camera_response_refuses_bad_tables(g):
    with pytest.raises(ResponseError):
        CameraResponse(g)


def test_camera_response_table_is_private():
    g = np.linspace(0.0, 1.0, 4096)
    r = CameraResponse(g)
    g[100] = 99.0  # the caller's array changes afterwards
    assert r.g[100] == pytest.approx(100 / 4095)
    with pytest.raises(ValueError):
        r.g.setflags(write=True)
        r.g[0] = 1.0
        raise AssertionError("unreachable")  # pragma: no cover
