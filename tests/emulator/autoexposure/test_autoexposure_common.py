"""The AE protocol, the factories, gray conversion, guards and the hard-case set (all methods, both modes)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from emulator.autoexposure import (
    DEFAULT_RANGE_MS,
    METHOD_NAMES,
    METHODS,
    MODES,
    AutoExposure,
    AutoExposureError,
    AutoExposureMethod,
    bayer_to_gray_reference,
    hard_cases,
    make_method,
    to_gray,
)
from emulator.autoexposure.base import REF_BAYER_CODE, RGGB_BAYER_CODE
from emulator.errors import ExposimError
from emulator.core.response import CameraResponse

RANGE = (0.02, 50.0)


def _build(name, mode, **kw):
    if name == "zhang":
        kw.setdefault("response", CameraResponse.linear())
    return METHODS[name](mode=mode, **kw)


def test_methods_table_and_front_function():
    assert METHOD_NAMES == ("fixed", "classical-30", "classical-50", "classical-70", "shim", "zhang", "kim")
    for name in METHOD_NAMES:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # zhang without a response
            m = METHODS[name]()
        assert isinstance(m, AutoExposure) and isinstance(m, AutoExposureMethod)
        assert m.name == name and m.mode == "paper"
        assert m.config()["name"] == name
    with pytest.raises(AutoExposureError, match="unknown AE method 'nope'.*classical-50"):
        make_method("nope")
    with pytest.raises(AutoExposureError, match="mode must be one of"):
        make_method("shim", mode="ref")
    with pytest.raises(AutoExposureError, match="bad option"):
        make_method("shim", not_an_option=1)
    assert issubclass(AutoExposureError, ExposimError)


def test_input_checks_name_the_argument():
    m = make_method("classical-50")
    with pytest.raises(AutoExposureError, match="raw must be uint16"):
        m.next_exposure(np.zeros((8, 8), np.float32), 4.0)
    with pytest.raises(AutoExposureError, match="2-D Bayer mosaic"):
        m.next_exposure(np.zeros((8, 8, 3), np.uint16), 4.0)
    with pytest.raises(AutoExposureError, match="raw must be a numpy array"):
        m.next_exposure([[1, 2], [3, 4]], 4.0)
    for bad in (0.0, -1.0, math.nan, math.inf, "x"):
        with pytest.raises(AutoExposureError, match="exposure_ms"):
            m.next_exposure(np.zeros((8, 8), np.uint16), bad)
    with pytest.raises(AutoExposureError, match="range_ms"):
        make_method("shim", range_ms=(5.0, 1.0))


def test_gray_conversion_matches_spec():
    # R sites (even row, even column) at 4000, the rest 0: OpenCV's "RG" code weighs them 0.114.
    m = np.zeros((8, 8), np.uint16)
    m[0::2, 0::2] = 4000
    assert to_gray(m, REF_BAYER_CODE)[3, 3] == 456
    assert to_gray(m, RGGB_BAYER_CODE)[3, 3] == 1196  # paper mode: true RGGB weights (0.299)
    rng = np.random.default_rng(0)
    raw = rng.integers(0, 4096, (40, 56), dtype=np.uint16)
    y_cv = to_gray(raw, REF_BAYER_CODE)
    y_np = bayer_to_gray_reference(raw)
    assert y_cv.dtype == np.uint16 and y_np.dtype == np.uint16
    assert np.abs(y_cv.astype(int) - y_np.astype(int)).max() <= 1


class _NaNMethod(AutoExposureMethod):
    name = "nan"

    def _step(self, raw, t):
        return math.nan


def test_guard_replaces_non_finite_and_counts():
    m = _NaNMethod(mode="borealhdr")
    raw = np.zeros((8, 8), np.uint16)
    assert m.next_exposure(raw, 3.5) == 3.5
    assert m.next_exposure(raw, 2.0) == 2.0
    assert m.guard_count == 2
    m.reset()
    assert m.guard_count == 0


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", METHOD_NAMES)
def test_hard_cases_finite_and_inside_range(name, mode):
    m = _build(name, mode, range_ms=RANGE)
    cases = hard_cases((24, 32))
    starts = (RANGE[0], RANGE[1]) if name == "kim" else (RANGE[0], 1.0, 4.0, RANGE[1])  # kim: ~0.1 s a GP fit
    for case, img in cases.items():
        for t0 in starts:
            m.reset()
            t = m.next_exposure(img, t0)
            assert type(t) is float, (case, t0)
            assert math.isfinite(t) and RANGE[0] <= t <= RANGE[1], (case, t0, t)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", METHOD_NAMES)
def test_same_frame_repeated_100_times(name, mode):
    m = _build(name, mode, range_ms=RANGE)
    cases = hard_cases((24, 32))
    frames = [cases["noise-column-on-gray"], cases["saturated"], cases["single-bright-pixel"]]
    if name == "kim":  # ~0.1 s a GP fit: one case per mode (paper: a constant metric, the degenerate fit)
        frames = [cases["saturated"] if mode == "paper" else cases["noise-column-on-gray"]]
    for img in frames:
        m.reset()
        t = 4.0
        for _ in range(100):
            t = m.next_exposure(img, t)
            assert type(t) is float and math.isfinite(t) and RANGE[0] <= t <= RANGE[1]


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", METHOD_NAMES)
def test_no_clamp_in_borealhdr_default_and_output_positive(name, mode):
    m = _build(name, mode)
    if mode == "borealhdr":
        assert m.range_ms is None
    else:
        assert m.range_ms == DEFAULT_RANGE_MS == (0.02, 50.0)
    for img in hard_cases((16, 16)).values():
        t = m.next_exposure(img, 4.0)
        assert math.isfinite(t) and t > 0


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", METHOD_NAMES)
def test_deterministic_trajectory(name, mode):
    rng = np.random.default_rng(3)
    base = rng.uniform(0.2, 1.8, (12, 16)).repeat(4, 0).repeat(4, 1)

    def trajectory():
        m = _build(name, mode)
        t, out = 4.0, []
        for _ in range(6):
            raw = np.clip(np.rint(base * 150.0 * t), 0, 4095).astype(np.uint16)
            t = m.next_exposure(raw, t)
            out.append(t)
        return out

    assert trajectory() == trajectory()


@pytest.mark.parametrize("mode", MODES)
def test_reset_restores_initial_behaviour(mode):
    rng = np.random.default_rng(4)
    frames = [np.clip(rng.normal(1500 + 300 * i, 400, (32, 32)), 0, 4095).astype(np.uint16) for i in range(5)]
    for name in ("fixed", "kim"):
        m = _build(name, mode)
        first = [m.next_exposure(f, 4.0) for f in frames]
        m.reset()
        assert [m.next_exposure(f, 4.0) for f in frames] == first
