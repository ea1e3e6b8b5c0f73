"""Native-rate emulation (issue 32): the selector, the rotation warp, the provider in the one closed loop."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest


import synth
from emulator.core.blur import rotation_homography
from emulator.errors import EmulationError, PlaybackError
from emulator.io.borealhdr import load_sequence, sequence_response
from emulator.core.native import NativeCandidate, invalid_fraction, native_cost, native_select, warp_to_instant
from emulator.playback import NativeProvider, RunConfig, closed_loop
from emulator.playback.native import NativeWarpWarning
from emulator.core.response import CameraResponse
from synth.sequence import load_camera
from validation.common import quantisation_bound
from validation.live import DatasetRadiance
from validation.live.native import native_rate_loop, shot_timestamps
from tests.conftest import static_chart_recording  # noqa: E402

W, H = 40, 24
PROPOSALS = (1.5, 3.0, 6.0, 12.0, 2.5, 5.0, 9.0, 24.0, 0.7)


class Counter:
    """Proposes PROPOSALS in turn, whatever it reads."""

    name = "counter"

    def __init__(self) -> None:
        self.n = 0

    def reset(self) -> None:
        pass

    def next_exposure(self, raw, exposure_ms):
        self.n += 1
        return PROPOSALS[(self.n - 1) % len(PROPOSALS)]


class Constant:
    def __init__(self, ms: float) -> None:
        self.name, self.ms = f"constant-{ms:g}", ms

    def reset(self) -> None:
        pass

    def next_exposure(self, raw, exposure_ms):
        return self.ms


def C(offset, bracket, invalid=0.0):
    return NativeCandidate(offset, bracket, invalid)


RULE = {"motion_stops_per_frame": 0.5, "saturation_limit": 0.01}  # the rule's parameters these cases are worked for


def pick(target, cands, **kw):
    return native_select(target, cands, **{**RULE, **kw})


# ============================================================================ the selector, by hand
def test_own_bracket_from_above_is_chosen():
    cands = [C(-1, 1.0), C(0, 8.0), C(1, 16.0), C(2, 4.0)]
    assert pick(4.0, cands).offset == 0  # 8 ms emulated down: cost 0
    assert pick(8.0, cands).offset == 0  # the bracket itself


def test_motion_against_upward_ratio():
    # frame k is a 1 ms shot, target 8 ms: up 3 stops from its own bracket (cost 3), or the
    # 8 ms shot 3 frames later (1.5), or the 32 ms shot 1 frame earlier (0.5)
    cands = [C(-1, 32.0), C(0, 1.0), C(1, 2.0), C(2, 4.0), C(3, 8.0)]
    assert pick(8.0, cands).offset == -1
    assert native_cost(8.0, C(0, 1.0), 0.5) == 3.0 and native_cost(8.0, C(3, 8.0), 0.5) == 1.5
    # the 32 ms shot clipped beyond 1 %: the next cost is 4 ms two frames later (1 + 1 = 2) against 8 ms at +3 (1.5)
    cands[0] = C(-1, 32.0, invalid=0.05)
    assert pick(8.0, cands).offset == 3
    # a heavier motion weight keeps frame k's own bracket: 3 stops against 3 frames at 1 stop each
    assert pick(8.0, cands, motion_stops_per_frame=1.0).offset == 0
    # a small upward ratio beats a neighbour: 2 ms -> 2.6 ms (0.38 stop) against 4 ms one frame later (0.5)
    assert pick(2.6, [C(0, 2.0), C(1, 4.0)]).offset == 0
    assert pick(3.0, [C(0, 2.0), C(1, 4.0)]).offset == 1  # 0.58 stop > 0.5


def test_ties_go_to_the_nearer_then_the_earlier_frame():
    assert pick(4.0, [C(2, 8.0), C(-2, 8.0)]).offset == -2
    assert pick(4.0, [C(2, 4.0), C(0, 2.0)]).offset == 0  # 1 stop up against 2 frames: equal, the nearer
    assert pick(4.0, [C(3, 4.0), C(-1, 1.0)]).offset == 3  # 1.5 against 0.5 + 2 = 2.5


def test_clipping_is_judged_against_the_least_clipped_candidate_and_bad_input_is_refused():
    got = pick(4.0, [C(0, 8.0, 0.30), C(1, 2.0, 0.05), C(-1, 16.0, 0.5)])
    assert got.offset == 1  # only the least clipped is within 1 % of the least clipped
    # a dark scene: every short bracket loses 20-21 % at black; within 1 % of each other, the cost decides
    got = pick(8.0, [C(0, 1.0, 0.205), C(1, 2.0, 0.21), C(3, 8.0, 0.20), C(-1, 32.0, 0.35)])
    assert got.offset == 3  # 1.5 against 3 (own) and 2.5: the 32 ms shot clips 15 % more, out
    with pytest.raises(EmulationError, match="no candidate"):
        native_select(4.0, [])
    with pytest.raises(EmulationError, match="target_ms"):
        pick(float("nan"), [C(0, 1.0)])
    with pytest.raises(EmulationError, match="motion weight"):
        pick(4.0, [C(0, 1.0)], motion_stops_per_frame=-1)


def test_invalid_fraction_counts_what_the_ratio_loses():
    hist = np.zeros(4095, dtype=np.int64)
    hist[0], hist[100], hist[4094] = 2, 5, 3
    assert invalid_fraction(hist, 2.0, white_level=4094, black_level=0) == 0.2  # black lost going up
    assert invalid_fraction(hist, 0.5, white_level=4094, black_level=0) == 0.3  # white lost going down
    assert invalid_fraction(hist, 1.0, white_level=4094, black_level=0) == 0.0


# ============================================================================ the warp
def _texture(u, v):
    """A smooth texture in linear exposure (0.2..0.8 of the range), periods 13-41 px."""
    return 0.5 + 0.12 * np.sin(u / 6.5 + 0.3) + 0.1 * np.cos(v / 4.1) + 0.08 * np.sin((u + 2 * v) / 9.0)


def _rot(axis, deg):
    import cv2

    return cv2.Rodrigues(np.asarray(axis, dtype=np.float64) * math.radians(deg))[0]


@pytest.mark.parametrize("bayer", [True, False])
def test_a_known_pure_rotation_is_undone_to_sub_pixel(bayer):
    import cv2

    w, h = 320, 240
    K = np.array([[300.0, 0, (w - 1) / 2], [0, 300.0, (h - 1) / 2], [0, 0, 1]])
    R = _rot([0, 1, 0], 1.2) @ _rot([1, 0, 0], -0.8) @ _rot([0, 0, 1], 0.6)  # about 10 px, 4 px and a roll
    Hm = rotation_homography(K, R)  # source pixel -> pixel after the turn
    resp = CameraResponse.linear()
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    top = resp.white_level
    src = np.rint(_texture(u, v) * top).astype(np.uint16)
    q = np.linalg.inv(Hm) @ np.stack([u.ravel(), v.ravel(), np.ones(u.size)])
    dst = np.rint(_texture((q[0] / q[2]).reshape(h, w), (q[1] / q[2]).reshape(h, w)) * top)
    warped, inside = warp_to_instant(src, Hm, resp, bayer=bayer)
    core = (slice(20, -20), slice(20, -20))
    a, b, s = (x[core].astype(np.float64) for x in (warped, dst, src))
    (dx, dy), _ = cv2.phaseCorrelate(a, b)
    assert math.hypot(dx, dy) < 0.02  # what is left of the turn: under a fiftieth of a pixel
    rms = lambda x: float(np.sqrt(np.mean((x - b) ** 2))) / top  # noqa: E731
    assert rms(s) > 0.05  # unwarped, the turn (10 px, 4 px and a roll) costs over 5 % of the range
    assert rms(a) < 0.005  # warped, under 0.5 % (Lanczos resampling of each Bayer plane)
    # the share of the image the source covers: the outline moved by the homography
    assert 0.93 < inside < 0.97


@pytest.mark.parametrize(("resample", "low", "high"), [("linear", 0.65, 0.76), ("lanczos4", 0.97, 1.01)])
def test_a_half_pixel_warp_keeps_the_fine_detail_with_lanczos(resample, low, high):
    """A sinusoid of a quarter cycle per Bayer-plane pixel, moved half a plane pixel: linear
    interpolation averages two neighbours and scales its amplitude by cos(pi/4) = 0.707, which
    removes the fine detail SIFT detects; the native warp's Lanczos kernel keeps it."""
    resp = CameraResponse.linear()
    h, w = 64, 256
    x = np.arange(w, dtype=np.float64)
    plane_x = x // 2  # each Bayer site's own grid: x = 2 * plane_x + phase
    wave = lambda shift: 0.5 + 0.3 * np.cos(2 * np.pi * 0.25 * (plane_x - shift))  # noqa: E731
    top = resp.white_level
    src = np.rint(np.tile(wave(0.0), (h, 1)) * top).astype(np.uint16)
    Hm = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])  # one full-resolution pixel: half a plane pixel
    out, _ = warp_to_instant(src, Hm, resp, resample=resample)
    row = out[h // 2, 32:-32].astype(np.float64) / top
    expected = np.tile(wave(0.5), (h, 1))[h // 2, 32:-32] - 0.5
    gain = float(np.dot(row - 0.5, expected) / np.dot(expected, expected))  # amplitude kept, in phase
    assert low < gain < high
    if resample == "linear":
        assert gain == pytest.approx(math.cos(math.pi / 4), abs=0.01)


def test_an_unknown_resampler_is_refused():
    with pytest.raises(EmulationError, match="unknown resampler 'nearest'"):
        warp_to_instant(np.zeros((8, 8), np.uint16), np.eye(3), CameraResponse.linear(), resample="nearest")


def test_identity_warp_is_byte_for_byte():
    resp = CameraResponse.linear()
    img = np.random.default_rng(0).integers(0, 4095, (24, 40)).astype(np.uint16)
    out, inside = warp_to_instant(img, np.eye(3), resp)
    assert np.array_equal(out, img) and inside == 1.0


# ============================================================================ the provider in the loop
@pytest.fixture(scope="module")
def static(tmp_path_factory):
    path = static_chart_recording(tmp_path_factory.mktemp("native") / "static", W, H, n_cycles=3, noise=False,
                                  save_radiance=True, start_bracket_index=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seq = load_sequence(path)
    return seq, load_camera(path), sequence_response(seq), DatasetRadiance(path)


def _native(seq, resp, methods, rule=None, **cfg):
    config = RunConfig(rate="native", initial_ms=4.0, **cfg)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NativeWarpWarning)
        provider = NativeProvider(seq, config, resp, **(rule or {}))
    return provider, list(closed_loop(provider, {m.name: m for m in methods}, config, want_right=True,
                                      keep_images=True))


@pytest.mark.parametrize("latency", [0, 1, 3])
def test_one_step_per_recorded_frame_with_the_latency(static, latency):
    seq, cam, resp, _ = static
    _, frames = _native(seq, resp, [Counter()], latency_frames=latency)
    shots = shot_timestamps(seq)
    assert [cs.cycle for cs in frames] == list(range(len(shots)))
    steps = [cs.steps["counter"] for cs in frames]
    assert [st.timestamp_ns for st in steps] == shots  # every frame at its own recorded instant
    for k, st in enumerate(steps):
        assert st.target_ms == (4.0 if k <= latency else steps[k - 1 - latency].next_ms), (k, latency)


def test_static_scene_equals_the_native_live_frames_to_quantisation(static):
    seq, cam, resp, rad = static
    _, emu = _native(seq, resp, [Counter()])
    live = list(native_rate_loop(seq, rad, cam, [Counter()], response=resp, noise=False, initial_ms=4.0,
                                 every_frame=True))
    assert len(emu) == len(live) == len(shot_timestamps(seq))
    offsets, emulated = set(), 0
    for e, v in zip(emu, live):
        a, b = e.steps["counter"], v.steps["counter"]
        assert a.target_ms == b.target_ms and a.next_ms == b.next_ms
        src = next(f for c in seq.cycles for f in c.frames["left"].values()
                   if f.timestamp_ns == a.native.source_timestamp_ns).load()
        offsets.add(a.native.source_offset)
        for mine, theirs in ((a.left, b.left), (a.right, b.right)):
            if a.ratio == 1.0:
                assert np.array_equal(mine, theirs)
                continue
            valid = resp.lut(a.ratio)[1][src]
            diff = np.abs(mine.astype(np.float64) - theirs.astype(np.float64))
            bound = quantisation_bound(resp, src, a.ratio)
            assert np.all(diff[valid] <= bound[valid] + 1e-9), (e.cycle, float((diff - bound)[valid].max()))
            emulated += 1
    assert emulated >= 4 and len(offsets) >= 3, (emulated, offsets)  # neighbours served, ratios off 1


@pytest.fixture(scope="module")
def ramp(tmp_path_factory):
    """A static ramp whose 32 ms shots clip 14 % of their pixels and no shorter one clips (checked below)."""
    base = np.linspace(0.4, 1.0, W * H, dtype=np.float32).reshape(H, W)
    field = np.repeat(base[:, :, None], 3, axis=2) * np.float32(15.0)

    def source(t, cam):
        return field, np.eye(4)

    cam = synth.Camera.preset("borealhdr", width=W, height=H)
    path = synth.capture_sequence(source, tmp_path_factory.mktemp("native") / "ramp", cam, n_shots=18, seed=5,
                                  noise=False, stereo=False, start_bracket_index=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seq = load_sequence(path)
    return seq, sequence_response(seq)


def test_selection_on_a_hand_built_sequence(ramp):
    """A constant target of 3 ms on the sweep 4, 8, 16, 32, 1, 2 ms (x3), the 32 ms shots clipped: the
    source of each frame, worked out by hand from the rule (cost = stops up + 0.5 per frame of offset,
    candidates clipping over 1 % more than the least clipped left out); then with the defaults."""
    seq, resp = ramp
    provider, frames = _native(seq, resp, [Constant(3.0)], rule=RULE)
    assert provider.frames.exposures == [4.0, 8.0, 16.0, 32.0, 1.0, 2.0] * 3
    lost = {e: invalid_fraction(np.bincount(f.load().ravel(), minlength=4095), 3.0 / e, white_level=4094,
                                black_level=0) for e, f in seq.cycles[1].frames["left"].items()}
    assert lost[32.0] > 0.1 and max(v for e, v in lost.items() if e != 32.0) == 0.0  # the premise
    # 4, 8, 16 ms: their own, downwards (cost 0); 32 ms: clipped, so the 16 ms shot before (0.5);
    # 1 ms: its own costs log2(3) = 1.58, the 2 ms after 0.58 + 0.5, the 16 ms two before and the 4 ms two
    # after 1.0 each: the earlier; 2 ms: its own 0.58, the 4 ms after 0.5; the last 2 ms has no frame after
    expected = [0, 0, 0, -1, -2, 1] * 3
    expected[-1] = 0
    got = [cs.steps["constant-3"].native.source_offset for cs in frames]
    assert [cs.steps["constant-3"].target_ms for cs in frames][2:] == [3.0] * 16  # latency 1: from frame 2
    assert got[2:] == expected[2:]
    brackets = [cs.steps["constant-3"].bracket_ms for cs in frames]
    assert brackets[2:] == [16.0, 16.0, 16.0, 4.0, 4.0, 8.0, 16.0, 16.0, 16.0, 4.0, 4.0, 8.0, 16.0, 16.0, 16.0, 2.0]
    # the defaults (1 stop per frame, 20 % of clipping): the 32 ms shots (14 % clipped) serve themselves; the
    # 1 ms shot takes the 32 ms one just before it (cost 1) over its own emulated up 3x (1.58), the 2 ms one after
    # it (0.58 + 1) and the 4 ms one two frames later (2); the 2 ms shot is emulated up 1.5x (0.58), not the 4 ms
    # one after it (1)
    _, frames = _native(seq, resp, [Constant(3.0)])
    assert [cs.steps["constant-3"].native.source_offset for cs in frames] == [0, 0, 0, 0, -1, 0] * 3


def test_a_rotation_from_the_gyro_between_frames(static):
    seq, cam, resp, _ = static
    from emulator.playback.motion import recording_motion

    rate = np.array([0.0, 0.2, 0.0])  # rad/s about the camera's y axis
    K = np.array([[40.0, 0, 19.5], [0, 40.0, 11.5], [0, 0, 1]])
    motion = recording_motion(seq, omega=lambda t: np.tile(rate, (np.size(t), 1)), origin_ns=0,
                              intrinsics={"left": (K, (W, H)), "right": (K, (W, H))}, stamp="start")
    provider = NativeProvider(seq, RunConfig(rate="native"), resp, motion=motion)
    fr = provider.frames
    R = provider.rotation(4, 2, fr.exposures[4], 3.0)  # from frame 4's window middle to frame 2's at 3 ms
    t_from = fr.timestamps[4] * 1e-9 + fr.exposures[4] * 5e-4
    t_to = fr.timestamps[2] * 1e-9 + 3.0 * 5e-4
    angle = math.degrees(math.acos((np.trace(R) - 1) / 2))
    assert angle == pytest.approx(math.degrees(0.2 * abs(t_to - t_from)), rel=1e-6)
    assert R[0, 2] * (t_to - t_from) > 0  # turned about +y forward in time


def test_without_an_imu_one_warning_and_no_warp(static):
    seq, cam, resp, _ = static
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        provider = NativeProvider(seq, RunConfig(rate="native"), resp)
    assert [str(w.message).split(": ", 1)[1] for w in caught if w.category is NativeWarpWarning] == [
        "no imu/imu.csv; at native rate a neighbour frame is used without undoing the camera's rotation since its "
        "instant"]
    assert provider.motion is None and provider.describe()["warp"] == "none"


def test_run_config_rate_and_latency():
    assert RunConfig().rate == "cycle" and "rate" not in RunConfig().to_json()
    cfg = RunConfig(rate="native", latency_frames=2)
    assert cfg.to_json()["rate"] == "native" and cfg.to_json()["latency_frames"] == 2
    assert RunConfig.from_json(cfg.to_json()) == cfg
    with pytest.raises(PlaybackError, match="^rate must be one of cycle, native"):
        RunConfig(rate="fast")
    for bad in (-1, 1.5, True):
        with pytest.raises(PlaybackError, match="^latency_frames must be an integer >= 0"):
            RunConfig(rate="native", latency_frames=bad)
    with pytest.raises(PlaybackError, match="rate"):
        cfg.resumed(RunConfig().to_json())


def test_native_emulation_summary_figures():
    from validation.live.native import native_emulation_summary

    walk = lambda w, u: {"m": {"rmse_percent": w, "rmse_percent_unwarped": u,  # noqa: E731
                               "rmse_percent_own_bracket": [x if i in (0, 3) else x / 2 for i, x in enumerate(w)],
                               "source_offset": [0, 1, -2, 0], "exposure_log2_error": [0.0, 0.1, 0.2]}}
    per_walk = {"a/seed0": walk([1.0, 2.0, 3.0, 9.0], [4.0, 4.0, 6.0, 8.0]),  # medians 2.5 and 5: the warp halves it
                "b/seed0": walk([2.0, 2.0, 2.0, 2.0], [3.0, 3.0, 3.0, 3.0]),  # 2 and 3: a third
                "c/seed0": None}  # a walk without the native condition is left out
    out = native_emulation_summary(per_walk, ["m"], seed=0)
    a = out["per_walk"]["a/seed0"]["m"]
    assert a["image_rmse_percent_median"] == 2.5 and a["image_rmse_percent_median_unwarped"] == 5.0
    assert a["warp_share_of_error"] == 0.5 and a["neighbour_fraction"] == 0.5 and a["exposure_log2_error_median"] == 0.1
    r, c = out["median_image_rmse_percent"], out["warp_cut_fraction"]
    assert r["estimate"] == 2.25 and r["n_walks"] == 2 and 2.0 <= r["ci95"][0] <= r["ci95"][1] <= 2.5
    assert c["estimate"] == pytest.approx((0.5 + 1 / 3) / 2) and c["met"] is False  # the interval reaches below 0.5
    assert r["met"] is True  # the whole interval is under 3 %
    # neighbour frames (offsets 1 and -2): a: 2.5 against 5, the own bracket 1.25; b: 2 against 3, the own bracket 1
    assert out["warp_cut_fraction_neighbour_frames"]["estimate"] == pytest.approx((0.5 + 1 / 3) / 2)
    nb = out["neighbour_frames"]
    assert nb["median_image_rmse_percent_own_bracket"]["estimate"] == pytest.approx((1.25 + 1.0) / 2)
    assert nb["median_image_rmse_percent_unwarped"]["estimate"] == pytest.approx((5.0 + 3.0) / 2)
    assert out["warp_cut_fraction_of_excess_neighbour_frames"]["estimate"] == pytest.approx((2.5 / 3.75 + 0.5) / 2)
    # a perfect warp: a's neighbour frames at 0 give 0, 0, 1, 9 (median 0.5 of 5), b's 0, 0, 2, 2 (1 of 3)
    assert out["warp_cut_fraction_perfect_warp"]["estimate"] == pytest.approx((0.9 + 2 / 3) / 2)
    assert native_emulation_summary({"a": None}, ["m"]) is None



def test_native_image_errors_on_a_static_scene(static):
    """At rest and without noise every emulated frame is the live one to quantisation, warped or not, and on the
    frames a neighbour served the frame's own bracket at the same exposure is as close; elsewhere it is the frame."""
    from validation.live.native import native_image_errors

    seq, cam, resp, rad = static
    live = list(native_rate_loop(seq, rad, cam, [Counter()], response=resp, noise=False, initial_ms=4.0,
                                 every_frame=True))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NativeWarpWarning)
        d = native_image_errors(seq, live, resp, RunConfig(rate="native", initial_ms=4.0), ["counter"])["counter"]
    n = len(shot_timestamps(seq))
    assert all(len(v) == n for v in d.values())
    off = np.asarray(d["source_offset"])
    assert (off != 0).sum() >= 3 and (off == 0).sum() >= 3
    for key in ("rmse_percent", "rmse_percent_unwarped", "rmse_percent_own_bracket"):  # over the pixels they can give
        assert max(d[key]) < 0.5, key  # a few DN of 4094 at most
    assert max(d["rmse_percent_all"]) > 1.0  # every pixel in view: those the source lost to clipping count
    assert d["rmse_percent"] == d["rmse_percent_unwarped"]  # no gyro: nothing to warp
    own = [o for o, s in zip(d["rmse_percent_own_bracket"], off) if s == 0]
    assert own == [r for r, s in zip(d["rmse_percent"], off) if s == 0]


@pytest.mark.parametrize("record", ["whole", "ends-early", "hole", "microseconds"])
def test_frames_the_gyro_does_not_cover_get_no_warp_and_the_run_counts_them(static, record):
    """An IMU record that ends early, has a 0.2 s hole, or whose stamps are microseconds read as
    nanoseconds: a neighbour frame whose rotation it does not cover is used unwarped (warp NaN),
    never warped by a guess, and :meth:`NativeProvider.gyro_coverage` counts the frames in one line."""
    seq, cam, resp, _ = static
    from emulator.playback.motion import recording_motion

    t = np.arange(-0.5, 1.5, 0.005)
    t = {"whole": t, "ends-early": t[t < 0.3], "hole": t[(t < 0.25) | (t > 0.45)], "microseconds": t / 1000}[record]
    K = np.array([[40.0, 0, 19.5], [0, 40.0, 11.5], [0, 0, 1]])
    motion = recording_motion(seq, omega=(t, np.tile([0.0, 0.2, 0.0], (t.size, 1))), origin_ns=0,
                              intrinsics={"left": (K, (W, H)), "right": (K, (W, H))}, stamp="start")
    config = RunConfig(rate="native", initial_ms=4.0)
    provider = NativeProvider(seq, config, resp, motion=motion)
    steps = [cs.steps["constant-3"].native for cs in closed_loop(provider, {"constant-3": Constant(3.0)}, config)]
    unwarped = [s for s in steps if s.source_offset != 0 and math.isnan(s.warp_deg)]
    coverage = provider.gyro_coverage()
    if record == "whole":
        assert coverage == {} and not unwarped
        return
    assert unwarped and coverage["frames_not_warped"] >= len(unwarped)
    assert coverage["gyro_note"] == (f"{coverage['frames_not_warped']} of 16 frames used a neighbour frame without "
                                     "a warp: the gyro does not cover the rotation (its record ends early, its stamps "
                                     "are in another unit, or a hole over 0.1 s)")


def test_a_hole_in_the_gyro_record_is_not_covered():
    from emulator.core.gyro import AngularVelocity

    t = np.r_[np.arange(0.0, 1.0, 0.01), np.arange(1.6, 3.0, 0.01)]  # a 0.6 s hole
    omega = AngularVelocity(t, np.zeros((t.size, 3)))
    assert omega.covers(0.1, 0.9) and omega.covers(1.7, 2.5)
    assert not omega.covers(0.9, 1.7) and not omega.covers(1.2, 1.3) and not omega.covers(2.9, 3.5)


def test_an_invalid_left_yaml_is_named_as_invalid_not_missing(static, tmp_path):
    """A recording with an IMU and a left.yaml that is not valid YAML: the warning names the file and
    its problem (it used to say 'no camera calibration (left.yaml)')."""
    import shutil

    seq, _, resp, _ = static
    root = tmp_path / "rec"
    shutil.copytree(seq.path, root)
    (root / "imu").mkdir(exist_ok=True)
    rows = [f"{int(t * 1e9)},{int(t * 1e9)},0.0,0.0,0.0,0.0,0.0,9.81" for t in np.arange(-1.0, 2.0, 0.01)]
    (root / "imu" / "imu.csv").write_text("timestamp,ros_time,gyro_x,gyro_y,gyro_z,acc_x,acc_y,acc_z\n"
                                          + "\n".join(rows) + "\n")
    (root / "calibration").mkdir(exist_ok=True)
    (root / "calibration" / "left.yaml").write_text("image_width: [1, 2\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = load_sequence(root)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        NativeProvider(rec, RunConfig(rate="native"), resp)
    said = [str(w.message) for w in caught if w.category is NativeWarpWarning]
    assert len(said) == 1 and "invalid camera calibration (" in said[0] and "no camera calibration" not in said[0]
    assert f"{root / 'calibration' / 'left.yaml'}: not valid YAML" in said[0]


def test_a_run_says_in_one_line_and_in_run_json_how_many_frames_got_no_warp(static, tmp_path, capsys):
    """An IMU record that ends after 0.2 s of a 0.7 s recording: ``run.json`` still says "rotation from
    the gyro" for the frames it covers, and counts those it does not, in one warning line too."""
    import json
    import shutil

    from emulator.commands.cli import main

    seq, _, _, _ = static
    root = tmp_path / "rec"
    shutil.copytree(seq.path, root)
    (root / "imu").mkdir()
    rows = [f"{int(t * 1e9)},{int(t * 1e9)},0.0,0.0,0.01,0.0,0.0,9.81" for t in np.arange(-1.0, 0.2, 0.01)]
    (root / "imu" / "imu.csv").write_text("timestamp,ros_time,gyro_x,gyro_y,gyro_z,acc_x,acc_y,acc_z\n"
                                          + "\n".join(rows) + "\n")
    out = tmp_path / "run"
    assert main(["run", str(root), "--methods", "classical-50,shim", "--rate", "native", "-o", str(out),
                 "--no-progress"]) == 0
    native = json.loads((out / "run.json").read_text())["native"]
    assert native["warp"] == "rotation from the gyro" and native["frames_not_warped"] > 0
    said = [line for line in capsys.readouterr().err.splitlines() if "without a warp" in line]
    assert said == [f"exposim run: warning: {native['gyro_note']}"]
    assert native["gyro_note"].startswith(f"{native['frames_not_warped']} of 16 frames used a neighbour frame")
