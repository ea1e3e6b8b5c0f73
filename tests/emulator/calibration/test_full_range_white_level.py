"""Full-range 12-bit data (DN 4095) against the default white level 4094: the refusal names
the real cause (the white level) and the flag that fixes it."""

from __future__ import annotations

import numpy as np

from emulator.commands.cli import main
from emulator.io.stack import write_stack
from emulator.core.response import CameraResponse

try:
    from tests.emulator.calibration.test_calibrate import stack_arrays
except ImportError:  # tests collected as a package
    from tests.test_calibrate import stack_arrays


def test_calibrate_full_range_stack_names_the_white_level(tmp_path, capsys):
    imgs, t = stack_arrays(CameraResponse.linear(), n=6)
    imgs[imgs == imgs.max()] = 4095  # a camera that saturates at the 12-bit top
    assert (imgs == 4095).any()
    root = write_stack(tmp_path / "st", imgs, t)  # no exposim.json: the default 4094 applies
    assert main(["calibrate", str(root), "-o", str(tmp_path / "r.txt"), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "exceeds the white level 4094" in err and "--white-level 4095" in err and "not 12-bit" not in err
    assert main(["calibrate", str(root), "-o", str(tmp_path / "r.txt"), "--no-progress", "--white-level",
                 "4095"]) == 0


def test_above_12_bits_is_called_not_12_bit(tmp_path):
    import pytest

    from emulator.errors import DatasetError
    from emulator.io.png import decode_png16, encode_png

    data = encode_png(np.full((4, 4), 5000, np.uint16))
    with pytest.raises(DatasetError, match="maximum DN 5000 exceeds 4095: not 12-bit data"):
        decode_png16(data, "x.png", white_level=4094)
