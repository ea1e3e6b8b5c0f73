"""The blur-aware native selector (opt-in): on a recorded turn of the shared sample's gyro it never emulates down
from a window that blurs more than 1 px beyond the target's while a candidate within 1 px is kept."""

from __future__ import annotations

import dataclasses
import json

import pytest

from emulator.io.borealhdr import load_sequence
from emulator.playback.motion import recording_motion
from emulator.core.native import BLUR_LIMIT_PX, NativeCandidate, native_select
from emulator.playback import NativeProvider, RunConfig
from emulator.playback.native import recording_stamp

#: The sample's frames span 0.17-0.95 s of its IMU, at rest (< 1.3 deg/s); its gyro turns at 20-35 deg/s from
#: 104.7 s on.  Moved 104.6 s, the gyro puts that turn under the frames.
TURN_SHIFT_NS = 104_600_000_000
TARGETS_MS = (0.5, 1.5, 3.0, 6.0, 12.0, 24.0)
#: The upstream BorealHDR data_sample has the same IMU and 60 frames over 0.17-2.87 s, turning at 4-16 deg/s from
#: 1.25 s on (it cannot be read by tests).  Moved 1.9 s, the gyro puts its last 0.8 s of frames (its recorded
#: turn, 5.6-14.6 deg/s at the frames) under the shared sample's.
RECORDED_TURN_SHIFT_NS = 1_900_000_000


def test_blur_breaks_ties_and_drops_blurred_candidates():
    a = NativeCandidate(-1, 32.0, 0.0, excess_blur_px=5.0)
    b = NativeCandidate(1, 1.0, 0.0, excess_blur_px=0.2)
    own = NativeCandidate(0, 32.0, 0.0, excess_blur_px=5.0)
    assert native_select(0.5, [a, b]) == a  # a tie (cost 1 each): the earlier frame
    assert native_select(0.5, [a, b], blur_stops_per_px=0.0) == b  # the same cost: the less blurred
    assert native_select(0.5, [own, b]) == own
    assert native_select(0.5, [own, b], blur_stops_per_px=0.0) == b  # more than 1 px beyond: dropped
    assert native_select(0.5, [own], blur_stops_per_px=1.0) == own  # nothing within 1 px: the best of the rest


def _shifted(sample_seq, shift_ns):
    seq = load_sequence(sample_seq, imu_warning=False)
    motion = recording_motion(seq, stamp=recording_stamp(seq))
    motion = dataclasses.replace(motion, origin_ns=motion.origin_ns - shift_ns)
    response = RunConfig().response_for(seq)
    return [NativeProvider(seq, RunConfig(rate="native"), response, motion=motion, blur_stops_per_px=w)
            for w in (None, 1.0)]


@pytest.fixture(scope="module")
def turn(sample_seq):
    return _shifted(sample_seq, TURN_SHIFT_NS)


def _over(plain, aware):
    """(frame, target) pairs with a candidate within 1 px of the target's blur, and those whose source (the
    selector as runs use it, the blur-aware one) blurs more than 1 px beyond it."""
    over_plain, over_aware, cases = [], [], 0
    for k in range(len(aware.frames)):
        tp, ta = plain.tick(k), aware.tick(k)
        for t in TARGETS_MS:
            least = min(aware.excess_blur_px(j, k, t) for j in ta.sources)
            if least > BLUR_LIMIT_PX:
                continue
            cases += 1
            over_plain += [(k, t)] if aware.excess_blur_px(tp.select(t), k, t) > BLUR_LIMIT_PX else []
            over_aware += [(k, t)] if aware.excess_blur_px(ta.select(t), k, t) > BLUR_LIMIT_PX else []
    return cases, over_plain, over_aware


def test_on_the_upstream_samples_recorded_turn_no_source_blurs_over_a_pixel_more_than_it_must(sample_seq):
    plain, aware = _shifted(sample_seq, RECORDED_TURN_SHIFT_NS)
    cases, over_plain, over_aware = _over(plain, aware)
    assert cases == 108 and over_aware == []
    # as runs use it, the selector takes a window over 1 px beyond in 66, e.g. frame 0 (frame 2's 8 ms shot)
    # for 0.5 ms: 3.1 px; the blur-aware one takes frame 5's 1 ms shot (0.3 px)
    assert len(over_plain) == 66 and (0, 0.5) in over_plain
    assert plain.tick(0).select(0.5) == 2 and aware.tick(0).select(0.5) == 5
    assert aware.excess_blur_px(2, 0, 0.5) == pytest.approx(3.1, abs=0.1)


def test_on_a_recorded_turn_no_source_blurs_over_a_pixel_more_than_it_must(turn):
    plain, aware = turn
    cases, over_plain, over_aware = _over(plain, aware)
    assert cases == 108 and over_aware == []  # every (frame, target) of 18 x 6 has a candidate within 1 px
    # the selector as runs use it takes a blurred window in 76 of them, e.g. frame 4 (its own 32 ms shot) for
    # 0.5 ms: 35 px of blur beyond the target's; the blur-aware one takes the 1 ms shot after it (0.5 px)
    assert len(over_plain) == 76 and (4, 0.5) in over_plain
    assert plain.tick(4).select(0.5) == 4 and aware.tick(4).select(0.5) == 5
    assert aware.excess_blur_px(4, 4, 0.5) == pytest.approx(35.4, abs=0.5)
    assert aware.excess_blur_px(5, 4, 0.5) == pytest.approx(0.5, abs=0.1)


def test_the_run_flags_are_recorded_only_when_set(sample_seq, tmp_path):
    from emulator.orchestration.runner import run_to_folder

    run_to_folder(sample_seq, "fixed", tmp_path / "a", rate="native", native_blur_aware=True, native_warp="flow")
    native = json.loads((tmp_path / "a" / "run.json").read_text())
    assert native["native_warp"] == "flow" and native["native_blur_aware"] is True
    assert native["native"]["warp_mode"] == "flow" and native["native"]["blur_stops_per_px"] == 1.0
    with pytest.raises(Exception, match="native rate"):
        RunConfig(native_warp="flow")
