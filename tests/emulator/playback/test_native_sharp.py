"""The flow-sharp warp (the default of ``exposim run --rate native``): the flow warp, but a neighbour whose median
move is under a pixel is used as recorded."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from emulator.io.borealhdr import load_sequence
from emulator.playback.motion import recording_motion
from emulator.core.native import DEFAULT_NATIVE_WARP, SHARP_MOTION_PX, median_motion_px
from emulator.playback import NativeProvider, RunConfig
from emulator.playback.native import recording_stamp
from validation.native_loo.measure import crop_sequence

#: The shared sample's frames are at rest (0.5-1.3 deg/s); moved 1.9 s, its gyro turns at 5.6-14.6 deg/s under them.
TURN_SHIFT_NS = 1_900_000_000


def test_median_motion_px():
    shape = (40, 60)
    assert median_motion_px(np.eye(3), None, shape) == 0.0
    H = np.array([[1.0, 0.0, 3.0], [0.0, 1.0, 4.0], [0.0, 0.0, 1.0]])
    assert median_motion_px(H, None, shape) == pytest.approx(5.0)
    back = np.zeros((20, 30, 2), np.float32)
    back[..., 0], back[..., 1] = -3.0, -4.0
    assert median_motion_px(H, back, shape) == pytest.approx(0.0, abs=1e-6)


def test_the_default_native_warp_is_flow_sharp_and_rotation_stays_as_it_was():
    assert DEFAULT_NATIVE_WARP == "flow-sharp" and SHARP_MOTION_PX == 1.0
    native = RunConfig(rate="native")
    assert native.native_warp == "flow-sharp" and native.to_json()["native_warp"] == "flow-sharp"
    assert "native_warp" not in RunConfig(rate="native", native_warp="rotation").to_json()
    assert RunConfig().native_warp is None and RunConfig().warp_mode == "rotation"
    assert RunConfig.from_json({"rate": "native"}).native_warp == "rotation"  # a folder from before the setting
    assert RunConfig().replace(rate="native").native_warp == "flow-sharp"


def _providers(sample_seq, shift_ns):
    seq = load_sequence(sample_seq, imu_warning=False)
    motion = recording_motion(seq, stamp=recording_stamp(seq))
    motion = dataclasses.replace(motion, origin_ns=motion.origin_ns - shift_ns)
    seq, motion = crop_sequence(seq, motion, (480, 300))
    response = RunConfig().response_for(seq)
    return [NativeProvider(seq, RunConfig(rate="native"), response, motion=motion, warp=w)
            for w in ("flow", "flow-sharp")]


@pytest.mark.parametrize("shift_ns", [0, TURN_SHIFT_NS])
def test_a_sub_pixel_move_is_skipped_and_a_larger_one_is_the_flow_warp(sample_seq, shift_ns):
    flow, sharp = _providers(sample_seq, shift_ns)
    lead, fr = flow.cameras[0], flow.frames
    moved, kept = [], 0
    for k in range(len(fr)):
        e = fr.exposures[k]
        shot = sharp.tick(k, hidden=True).shot(e)
        j = k + shot.native.source_offset
        shape = flow.images(j).get(lead, fr.exposures[j])[0].shape
        H, disp = flow.geometry(lead, j, k, fr.exposures[j], e, shape)
        Hs, ds = sharp.geometry(lead, j, k, fr.exposures[j], e, shape)
        m = median_motion_px(H, disp, shape)
        moved.append(m)
        if m < SHARP_MOTION_PX:  # as recorded: no resampling, no warp angle
            assert Hs is None and ds is None and math.isnan(shot.native.warp_deg)
            assert np.array_equal(shot.left, sharp.images(j)._emulate(lead, fr.exposures[j], shot.ratio,
                                                                      sharp.response.lut(shot.ratio)[0], sharp.stats))
            kept += 1
        else:  # the flow warp, to the byte
            assert np.array_equal(Hs, H) and (ds is None) == (disp is None)
            assert ds is None or np.array_equal(ds, disp)
            assert np.array_equal(shot.left, flow.tick(k, hidden=True).shot(e).left)
    if shift_ns == 0:  # at rest: every neighbour moves 0.28-0.94 px
        assert kept == len(fr) and max(moved) < SHARP_MOTION_PX
    else:  # the upstream sample's turn: 1.06-15.5 px (the frames do not turn: the
        # flow measures what the rotation put wrong)
        assert kept == 0 and min(moved) > SHARP_MOTION_PX
