"""One Levels (black, white) value; the BorealHDR defaults defined once."""

from __future__ import annotations

import dataclasses

import pytest

from emulator.errors import CalibrationError, ExposimError, ResponseError
from emulator.core.levels import BOREALHDR_LEVELS, Levels


def test_borealhdr_levels_are_the_one_default_and_the_old_names_alias_them():
    import emulator.io.borealhdr as bh
    import emulator.core.response as r

    assert (BOREALHDR_LEVELS.black, BOREALHDR_LEVELS.white, BOREALHDR_LEVELS.bit_depth) == (0, 4094, 12)
    assert bh.BOREALHDR_LEVELS is BOREALHDR_LEVELS
    assert (r.BOREALHDR_BLACK_LEVEL, r.BOREALHDR_WHITE_LEVEL) == (0, 4094)
    assert r.CameraResponse.linear().levels == Levels(0, 4094)
    assert BOREALHDR_LEVELS.span_dn == 4094


def test_levels_is_frozen_and_validated():
    lv = Levels(64, 4095, bit_depth=12)
    with pytest.raises(dataclasses.FrozenInstanceError):
        lv.white = 10
    assert Levels(0, 65535) == Levels(0.0, 65535.0)  # integral floats are ints
    assert type(Levels(0.0, 10.0).white) is int
    for black, white, bits, msg in [(10, 10, 16, "black_level < white_level"),
                                    (-1, 10, 16, "black_level < white_level"),
                                    (0, 4096, 12, "<= 4095 \\(12 bits\\)"),
                                    (0, 65536, 16, "<= 65535"),
                                    (0, 10.5, 16, "white_level must be an integer"),
                                    (0, 10, 17, "bit_depth")]:
        with pytest.raises(ExposimError, match=msg):
            Levels(black, white, bits)
    with pytest.raises(CalibrationError, match="^stack.json white_level: need 0 <= black_level"):
        Levels.checked(5, 4, bit_depth=12, where="stack.json white_level", error=CalibrationError)
    assert Levels.checked(5, 4000, bit_depth=12) == Levels(5, 4000, 12)


def test_readers_use_levels(tmp_path):
    from emulator.core.response import CameraResponse

    import numpy as np

    with pytest.raises(ResponseError, match="^custom: need 0 <= black_level < white_level <= 65535"):
        CameraResponse(np.linspace(0.0, 1.0, 101), 100, 100)
    assert CameraResponse(np.linspace(0.0, 1.0, 101), 100, 3).levels == Levels(3, 100)


def test_calibration_percent_names_keep_their_old_aliases():
    import inspect

    import numpy as np

    from emulator.calibration.result import CalibrationResult
    from emulator.calibration.stack_engel2016 import calibrate_stack
    from emulator.core.response import CameraResponse

    r = CalibrationResult(CameraResponse.linear(), np.zeros(2), np.zeros(2), "m", (0, 1), 1.0, 1.0, 2.5, np.nan,
                          np.zeros(0), np.zeros(0), 4094, 0)
    assert r.residual_rms_percent == r.residual_rms_pct == 2.5
    d = r.to_dict()
    assert d["residual_rms_percent"] == d["residual_rms_pct"] == 2.5
    params = inspect.signature(calibrate_stack).parameters
    assert params["static_floor_percent"].default == 1.0 and params["static_floor_pct"].default is None
