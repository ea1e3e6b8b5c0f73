"""ROS camera_info through PyYAML: the same content in any YAML spelling reads the same;
malformed files give one line naming the file and the field."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from emulator.errors import CalibrationError
from emulator.io.camera_info import read_camera_info

from tests.conftest import SAMPLE, missing_shared

SEPT = SAMPLE / "calibration" / "september_2023"


@pytest.fixture(scope="module")
def left_yaml():
    if not (SEPT / "left.yaml").is_file():
        missing_shared("shared BorealHDR calibration not available")
    return SEPT / "left.yaml"


def _same(a, b):
    assert (a.width, a.height, a.distortion_model, a.name) == (b.width, b.height, b.distortion_model, b.name)
    for k in ("K", "D", "R", "P"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))


@pytest.mark.parametrize("style", ["safe_dump", "flow", "sorted_flow_one_line"])
def test_rewritten_left_yaml_reads_the_same(left_yaml, tmp_path, style):
    original = read_camera_info(left_yaml)
    assert original.P[1, 2] == 580.01843 and original.K[0, 0] == 1180.80514
    data = yaml.safe_load(left_yaml.read_text())
    if style == "safe_dump":
        text = yaml.safe_dump(data)
    elif style == "flow":
        text = yaml.safe_dump(data, default_flow_style=True)
    else:
        text = yaml.safe_dump(data, default_flow_style=True, width=10**6, sort_keys=True)
        assert text.count("\n") == 1
    path = tmp_path / "left.yaml"
    path.write_text(text)
    _same(read_camera_info(path), original)


@pytest.mark.parametrize(
    "edit, field",
    [
        (lambda d: d.pop("camera_matrix"), "camera_matrix"),
        (lambda d: d["projection_matrix"].update(data=[1, 2, 3]), "projection_matrix"),
        (lambda d: d["distortion_coefficients"].update(data="abc"), "distortion_coefficients"),
        (lambda d: d.update(image_width="wide"), "image_width"),
        (lambda d: d["rectification_matrix"].update(rows="x"), "rectification_matrix"),
    ],
)
def test_malformed_fields_are_named(left_yaml, tmp_path, edit, field):
    data = yaml.safe_load(left_yaml.read_text())
    edit(data)
    path = tmp_path / "left.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(CalibrationError) as info:
        read_camera_info(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and field in message and "\n" not in message


def test_not_yaml_names_the_line(tmp_path):
    path = tmp_path / "left.yaml"
    path.write_text("image_width: 10\ncamera_matrix: [1, 2\n")
    with pytest.raises(CalibrationError, match=r"left.yaml: not valid YAML at line \d+"):
        read_camera_info(path)
    path.write_text("- just\n- a list\n")
    with pytest.raises(CalibrationError, match="left.yaml: expected a YAML mapping"):
        read_camera_info(path)
