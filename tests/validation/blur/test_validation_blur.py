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
    with pytest.raises(ValidationError, match="sharpness_width"):
        BlurConfig(sharpness_width=0)
    assert (BlurConfig().sharpness_width, BlurConfig().sharpness_height) == (1920, 1200)  # the BorealHDR camera


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
    from emulator.commands.cli import main

    out = tmp_path / "blur"
    assert main(["validate", "blur", "--quick", "-o", str(out)]) == 0
    r = json.loads((out / "results.json").read_text())
    for key in ("reference_error_percent", "render_cost_ratio", "sharpness_error_plain_percent"):
        assert r[key] is not None and r[key] == r[key]
    assert r["sharpness_error_consistent_percent"] is not None  # emulator.core.blur fed with the walk's gyro
    row = r["sharpness"][0]
    assert row["size"] == [64, 40] and row["rms_plain_dn"] > 0 and row["rms_consistent_dn"] > 0
    assert r["image_rms_error_ratio"] == pytest.approx(row["rms_consistent_dn"] / row["rms_plain_dn"])
    assert r["sharpness_abs_error_ratio"] == pytest.approx(
        abs(row["consistent_error_percent"]) / abs(row["plain_error_percent"]))
    assert r["consistent_halves_error_goal"] == 0.5
    assert r["consistent_hook"] == "measured"
    assert r["reference"][0]["n_subinstants"] >= 2
    assert 0 < r["render_cost_ratio"] < 10
    if default_real_imu() is not None:
        assert set(r["angular_rate_ratio"]) == {"p50", "p90", "p99"}
        assert all(0.7 < v < 1.3 for v in r["angular_rate_ratio"].values())  # 30 s of walk: looser than 200 s
    assert (out / "report.md").read_text().startswith("# Exposure-time blur")
    v = r["live_versus_emulated"]  # the quick table: one walk, both recordings, two emulated runs
    assert len(v["walks"]) == 1 and set(v["walks"][0]["by_blur"]) == {"blurred", "sharp"}
    for key, rows in v["table"].items():
        for row in rows.values():
            assert row["median_matches"]["verdict"] == "undetermined"  # 2 frame pairs: fewer than MIN_FRAMES
            assert row["vo_failed_frames"]["verdict"] == "undetermined"  # one walk cannot decide a per-walk metric
    assert "Live against emulated" in (out / "report.md").read_text()


def test_versus_verdicts_follow_the_margin():
    from validation.blur.versus import _verdict

    assert _verdict([-0.5, 0.5], 1.0) == "agrees"
    assert _verdict([1.5, 3.0], 1.0) == "disagrees"
    assert _verdict([-3.0, -1.01], 1.0) == "disagrees"
    assert _verdict([0.5, 1.5], 1.0) == "undetermined"
    assert _verdict(None, 1.0) == "undetermined"


def test_versus_compare_differences_and_bases():
    import numpy as np

    from validation.blur.versus import METRICS, RUNS, compare

    def bench(offset):  # one recording's bench_walk result: live, and emulated runs shifted by ``offset``
        out = {}
        for run in RUNS:
            shift = 0.0 if run == "live" else offset
            out[run] = {"summary": {"m": {"median_matches": 40.0 + shift, "median_uniformity": 0.5,
                                          "vo_failed_frames": 1.0, "rpe_trans_pct": None}},
                        "frames": {"matches": {"m": list(np.arange(20.0) + shift)},
                                   "uniformity": {"m": [0.5] * 21}}}
        return out

    one = [{"walk": "w0", "by_blur": {"blurred": bench(10.0), "sharp": bench(0.0)}}]
    t = compare(one, ["m"])
    cell = t["blurred/emulated-plain"]["m"]["median_matches"]
    assert cell["per_walk"]["estimate"] == 10.0 and cell["per_walk"]["ci95"] is None  # one walk: no interval
    assert cell["basis"] == "frames" and cell["per_frame"]["estimate"] == 10.0
    assert cell["per_frame"]["ci95"] == [10.0, 10.0] and cell["verdict"] == "disagrees"  # margin 5 matches
    assert t["sharp/emulated-plain"]["m"]["median_matches"]["verdict"] == "agrees"
    assert t["sharp/emulated-plain"]["m"]["vo_failed_frames"]["verdict"] == "undetermined"  # one walk
    assert t["sharp/emulated-plain"]["m"]["rpe_trans_pct"]["per_walk"]["n"] == 0
    two = one + [{"walk": "w1", "by_blur": {"blurred": bench(12.0), "sharp": bench(0.0)}}]
    cell = compare(two, ["m"])["blurred/emulated-consistent"]["m"]["median_matches"]
    assert cell["basis"] == "walks" and cell["per_walk"]["estimate"] == 11.0
    assert 10.0 <= cell["per_walk"]["ci95"][0] <= cell["per_walk"]["ci95"][1] <= 12.0
    assert set(t) == {f"{b}/{r}" for b in ("blurred", "sharp") for r in RUNS[1:]}
    assert set(METRICS) == set(t["sharp/emulated-plain"]["m"])
