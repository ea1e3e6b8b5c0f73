"""``exposim validate blur --quick``: the study runs end to end and writes its figures."""

from __future__ import annotations

import json

import pytest

from validation.blur.config import BlurConfig, default_real_imu
from validation.blur.measure import sharpness
from validation.common import ValidationError


def test_config_refuses_bad_sizes():
    with pytest.raises(ValidationError, match="source_ms"):
        BlurConfig.quick(source_ms=40.0)
    with pytest.raises(ValidationError, match="spp"):
        BlurConfig.quick(spp=0)


def test_sharpness_of_a_ramp_is_exact():
    import numpy as np

    # green sites (0,1) and (1,0) of each 2x2 block: a ramp of 4 DN per green-plane column over a level of 500
    x = np.arange(64, dtype=np.float64)
    raw = np.tile(500.0 + 2.0 * (x - 31.5), (48, 1)).astype(np.uint16)
    g = 0.5 * (raw[0::2, 1::2].astype(float) + raw[1::2, 0::2].astype(float))
    assert sharpness(raw) == pytest.approx(np.percentile(np.abs(np.gradient(g, axis=1)), 95) / np.median(g))
    assert sharpness(raw) == pytest.approx(4.0 / np.median(g))


@pytest.mark.render
@pytest.mark.slow
def test_validate_blur_quick(tmp_path):
    from emulator.cli import main

    out = tmp_path / "blur"
    assert main(["validate", "blur", "--quick", "-o", str(out)]) == 0
    r = json.loads((out / "results.json").read_text())
    for key in ("reference_error_percent", "render_cost_ratio", "sharpness_error_plain_percent"):
        assert r[key] is not None and r[key] == r[key]
    assert r["sharpness_error_consistent_percent"] is not None  # emulator.blur fed with the walk's gyro
    assert r["consistent_hook"] == "measured"
    assert r["reference"][0]["n_subinstants"] >= 2
    assert 0 < r["render_cost_ratio"] < 10
    if default_real_imu() is not None:
        assert set(r["angular_rate_ratio"]) == {"p50", "p90", "p99"}
        assert all(0.7 < v < 1.3 for v in r["angular_rate_ratio"].values())  # 30 s of walk: looser than 200 s
    assert (out / "report.md").read_text().startswith("# Exposure-time blur")
