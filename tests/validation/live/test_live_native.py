"""The native-rate live loop (issue 22): latency, mid-exposure stamps, the window convention, the frame grid."""

from __future__ import annotations

import numpy as np
import pytest


from emulator.playback import RunConfig
from emulator.io.borealhdr import load_sequence, sequence_response
from synth.sequence import load_camera
from validation.live import DatasetRadiance, iter_live
from validation.live.config import LiveError
from validation.live.native import native_rate_loop, shot_timestamps
from tests.conftest import static_chart_recording  # noqa: E402

W, H = 40, 24
PROPOSALS = (1.5, 3.0, 6.0, 12.0, 2.5, 5.0, 9.0)  # distinct: an off-by-one frame cannot pass


class Counter:
    """Proposes PROPOSALS in turn, whatever it reads; records the exposures it was handed."""

    name = "counter"

    def __init__(self) -> None:
        self.n, self.read_ms = 0, []

    def reset(self) -> None:
        pass

    def next_exposure(self, raw, exposure_ms):
        self.read_ms.append(float(exposure_ms))
        self.n += 1
        return PROPOSALS[(self.n - 1) % len(PROPOSALS)]


class Constant:
    name = "constant"

    def reset(self) -> None:
        pass

    def next_exposure(self, raw, exposure_ms):
        return 4.0


class WindowRadiance:
    """Exposure-aware radiance that only exists at the recorder's shot instants (window starts); logs calls."""

    exposure_aware = True

    def __init__(self, base) -> None:
        self.base, self.calls = base, []

    def __call__(self, t, cam, exposure_ms):
        self.calls.append((int(t), cam, float(exposure_ms)))
        return self.base(t, cam)  # DatasetRadiance raises off the shot instants


@pytest.fixture(scope="module")
def static(tmp_path_factory):
    path = static_chart_recording(tmp_path_factory.mktemp("native") / "static", W, H, n_cycles=3, noise=False,
                                  save_radiance=True)
    seq = load_sequence(path)
    return seq, load_camera(path), sequence_response(seq), DatasetRadiance(path)


@pytest.mark.parametrize("latency", [0, 1, 2, 3])
def test_latency_applies_the_proposal_made_after_frame_k_minus_1_minus_latency(static, latency):
    seq, cam, resp, rad = static
    m = Counter()
    frames = list(native_rate_loop(seq, rad, cam, [m], response=resp, noise=False, initial_ms=4.0,
                                   latency_frames=latency, every_frame=True,
                                   config=RunConfig(workers="inline")))  # m is read after the loop: in this process
    n_shots = len(shot_timestamps(seq))
    assert [cs.cycle for cs in frames] == list(range(n_shots))  # one frame per recorder shot at 22 fps
    steps = [cs.steps["counter"] for cs in frames]
    assert [st.next_ms for st in steps] == [PROPOSALS[k % len(PROPOSALS)] for k in range(n_shots)]  # not guarded
    for k, st in enumerate(steps):
        expected = 4.0 if k <= latency else steps[k - 1 - latency].next_ms
        assert st.target_ms == expected, (k, latency)
    assert m.read_ms == [st.target_ms for st in steps]  # the method reads the frame taken at the applied exposure


def test_stamps_at_mid_exposure_and_radiance_over_the_frame_window(static):
    seq, cam, resp, rad = static
    wrad = WindowRadiance(rad)
    frames = list(native_rate_loop(seq, wrad, cam, [Counter()], response=resp, noise=False,
                                   initial_ms=4.0, every_frame=True))
    shots = shot_timestamps(seq)
    for k, cs in enumerate(frames):
        st = cs.steps["counter"]
        assert st.timestamp_ns == shots[k] + int(round(st.target_ms * 1e6 / 2))
        assert st.right is not None and st.left.shape == (H, W)
    # the radiance is asked at the window start (the shot instant), never at the mid-exposure stamp
    left_calls = [c for c in wrad.calls if c[1] == "left"]
    assert [(t, e) for t, _, e in left_calls] == [(shots[k], cs.steps["counter"].target_ms)
                                                  for k, cs in enumerate(frames)]


def test_per_cycle_frame_is_the_cycle_rate_fixed_instant_shot(static):
    """A constant exposure: the native frame at each cycle's first shot is, pixel for pixel, the
    cycle-rate fixed-instant live shot (same instant, same window), stamped half an exposure later."""
    seq, cam, resp, rad = static
    native = list(native_rate_loop(seq, WindowRadiance(rad), cam, [Constant()], response=resp,
                                   noise=False, initial_ms=4.0))
    live = list(iter_live(seq, WindowRadiance(rad), cam, [Constant()], timing="fixed-instant",
                          response=resp, noise=False, initial_ms=4.0))
    assert [cs.cycle for cs in native] == [c.index for c in seq.cycles] == [cs.cycle for cs in live]
    for a, b in zip(native, live):
        sa, sb = a.steps["constant"], b.steps["constant"]
        assert sa.cycle == a.cycle and sa.target_ms == sb.target_ms == 4.0
        assert sa.timestamp_ns == sb.timestamp_ns + 2_000_000
        np.testing.assert_array_equal(sa.left, sb.left)
        np.testing.assert_array_equal(sa.right, sb.right)


def test_frame_rate_must_fall_on_the_recorders_shots(static):
    seq, cam, resp, rad = static
    shots = shot_timestamps(seq)
    half = list(native_rate_loop(seq, rad, cam, [Counter()], response=resp, noise=False,
                                 frame_rate_hz=11.0, every_frame=True))
    assert [cs.steps["counter"].timestamp_ns - int(round(cs.steps["counter"].target_ms * 1e6 / 2))
            for cs in half] == shots[::2]
    with pytest.raises(LiveError, match="frame_rate_hz 30"):
        native_rate_loop(seq, rad, cam, ["fixed"], response=resp, frame_rate_hz=30.0)
    for bad in (-1, True, 1.5):
        with pytest.raises(LiveError, match="latency_frames"):
            native_rate_loop(seq, rad, cam, ["fixed"], response=resp, latency_frames=bad)


def test_cli_options_reach_the_configuration():
    from validation.live.cli import build_parser, command_line, config_from_args

    args = build_parser().parse_args(["-o", "x", "--quick", "--latency-frames", "2", "--frame-rate-hz", "11"])
    cfg = config_from_args(args)
    assert (cfg.latency_frames, cfg.frame_rate_hz, cfg.native) == (2, 11.0, True)
    assert "--latency-frames 2 --frame-rate-hz 11.0" in command_line(args, "exposim validate live")
    assert config_from_args(build_parser().parse_args(["-o", "x", "--no-native"])).native is False
    with pytest.raises(LiveError, match="latency_frames"):
        config_from_args(build_parser().parse_args(["-o", "x", "--latency-frames", "-1"]))
