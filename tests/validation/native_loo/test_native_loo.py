"""``exposim validate native``: each recorded frame of the shared sample hidden in turn, by warp mode."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from emulator.commands.cli import main
from emulator.io.borealhdr import load_sequence
from emulator.playback.motion import recording_motion
from emulator.playback import NativeProvider, RunConfig
from emulator.playback.native import recording_stamp
from validation.native_loo.measure import crop_sequence, motion_class
from validation.native_loo.study import NativeLooConfig, run_study

SIZE = (320, 200)


@pytest.fixture(scope="module")
def loo(sample_seq, tmp_path_factory):
    out = tmp_path_factory.mktemp("loo") / "out"
    return out, run_study(sample_seq, out, NativeLooConfig(size=SIZE, max_frames=3), command="test")


def test_every_hidden_frame_comes_from_a_neighbour_in_every_mode(loo):
    out, results = loo
    rows = results["rows"]
    assert results["n_frames"] == 18 and results["n_frames_hidden"] == 3 and results["size"] == list(SIZE)
    assert sorted({r["frame"] for r in rows}) == [0, 8, 17]
    assert len(rows) == 9 and {r["warp"] for r in rows} == {"none", "rotation", "flow"}
    assert all(r["source_offset"] != 0 for r in rows)  # never the hidden frame itself
    by = {(r["frame"], r["warp"]): r for r in rows}
    for k in (0, 8, 17):  # one selection for every mode: only the warp differs
        assert len({(by[k, w]["source_offset"], by[k, w]["ratio"]) for w in ("none", "rotation", "flow")}) == 1
    # the sample is at rest (< 1.3 deg/s): every frame is in class "rest"
    assert {r["motion_class"] for r in rows} == {"rest"}
    assert by[0, "none"]["warp_deg"] is None and by[0, "rotation"]["warp_deg"] > 0
    # frame 0 has no frame before it: the flow warp is the rotation there; frame 8 has both sides
    assert not by[0, "flow"]["flow_used"] and by[8, "flow"]["flow_used"]
    assert by[0, "flow"]["rmse_percent"] == by[0, "rotation"]["rmse_percent"]
    # measured (320x200; 480x300 over every frame in docs/results/native-loo-2026-12-04.md): the 8 ms frame 8 from
    # the 16 ms shot after it, error 2.68 % unwarped, 2.46 % turned, 2.36 % with the flow; motion left 0.49, 0.29,
    # 0.05 px; of its 429 keypoints 291, 253 and 282 good matches (the 1 and 2 ms frames have 2 and 11 keypoints)
    f8 = [by[8, w] for w in ("none", "rotation", "flow")]
    assert [r["source_offset"] for r in f8] == [1, 1, 1] and f8[0]["source_ms"] == 16.0
    assert [r["rmse_percent"] for r in f8] == pytest.approx([2.68, 2.46, 2.36], abs=0.03)
    assert [r["motion_left_px"] for r in f8] == pytest.approx([0.49, 0.29, 0.05], abs=0.05)
    assert [r["sift_good_matches"] for r in f8] == pytest.approx([291, 253, 282], rel=0.1)
    for k in (0, 17):
        assert by[k, "rotation"]["rmse_percent"] < by[k, "none"]["rmse_percent"] < 3.0
        assert by[k, "rotation"]["motion_left_px"] < 0.4 < by[k, "none"]["motion_left_px"]
    table = {(t["motion_class"], t["warp"]): t for t in results["summary"]["table"]}
    assert table["all", "rotation"]["n_frames"] == 3 and table["rest", "flow"]["n_frames"] == 3
    assert results["summary"]["speed"]["rotation"]["cpu_over_rotation"] == 1.0
    saved = json.loads((out / "results.json").read_text())
    assert saved["summary"]["table"][0]["warp"] == "none"
    report = (out / "report.md").read_text()
    assert "| rest | rotation | 3 |" in report and "CPU / rotation's" in report


def test_nothing_recorded_at_the_hidden_instant_informs_it(sample_seq):
    """Frame k's shots on both cameras replaced by noise: its emulation is the same bytes, in every mode."""
    seq = load_sequence(sample_seq, imu_warning=False)
    motion = recording_motion(seq, stamp=recording_stamp(seq))
    seq, motion = crop_sequence(seq, motion, SIZE)
    k = 8
    probe = NativeProvider(seq, RunConfig(rate="native"), RunConfig().response_for(seq), motion=motion)
    ts, e = probe.frames.timestamps[k], probe.frames.exposures[k]
    rng = np.random.default_rng(0)

    def poison(frame):
        if int(frame.timestamp_ns) != ts:
            return frame
        return dataclasses.replace(frame, reader=lambda f: rng.integers(0, 4095, SIZE[::-1], dtype=np.uint16))

    bad = dataclasses.replace(seq, cycles=[dataclasses.replace(c, frames={cam: {x: poison(f) for x, f in shots.items()}
                                                                          for cam, shots in c.frames.items()})
                                           for c in seq.cycles])
    response = RunConfig().response_for(seq)
    for warp in ("none", "rotation", "flow"):
        a, b = (NativeProvider(s, RunConfig(rate="native"), response, motion=motion, warp=warp).tick(k, hidden=True)
                for s in (seq, bad))
        sa, sb = a.shot(e), b.shot(e)
        assert sa.native.source_offset != 0
        assert np.array_equal(sa.left, sb.left), warp


def test_motion_classes():
    assert [motion_class(v) for v in (0.0, 2.99, 3.0, 7.9, 8.0, 40.0, float("nan"))] == \
        ["rest", "rest", "slow", "slow", "turning", "turning", "unknown"]


def test_cli_refuses_to_overwrite_and_has_help(loo, sample_seq, capsys):
    out, _ = loo
    assert main(["validate", "native", str(sample_seq), "-o", str(out), "--frames", "1", "--size", "64x64"]) != 0
    assert "refusing to overwrite" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        main(["validate", "native", "--help"])
    assert exit_.value.code == 0
    assert "leaving each frame out" in capsys.readouterr().out
