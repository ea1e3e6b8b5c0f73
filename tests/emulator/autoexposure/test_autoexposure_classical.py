"""Classical M_30/M_50/M_70 and M_fixed against spec section 6 (borealhdr) and paper-mode behaviour."""

from __future__ import annotations

import numpy as np
import pytest

from emulator.autoexposure import Classical, Fixed, make_method
from emulator.autoexposure.classical import DEAD_BAND_DN, GAIN_MS_PER_DN, target_dn


@pytest.fixture(scope="module")
def base():
    return np.random.default_rng(0).uniform(0.5, 1.5, (240, 320))


def linear_scene(base, k, t):
    """Spec's linear scene: raw = clip(base k t, 0, 4095), truncated to uint16."""
    return np.clip(base * k * t, 0, 4095).astype(np.uint16)


def test_constants():
    assert [target_dn(p) for p in (30, 50, 70)] == [1228, 2048, 2867]
    assert DEAD_BAND_DN == 15 and GAIN_MS_PER_DN == 0.002
    assert make_method("classical-30").target_dn == 1228
    assert make_method("classical-70").name == "classical-70"


def test_spec_linear_scene_trajectory(base):
    m = Classical(50, mode="borealhdr")
    t, traj = 4.0, []
    for _ in range(10):
        t = m.next_exposure(linear_scene(base, 256, t), t)
        traj.append(t)
    assert np.allclose(traj[:6], [6.05, 7.05, 7.54, 7.77, 7.89, 7.95], atol=0.011)
    assert traj[6:] == [traj[5]] * 4  # inside the dead band from then on
    assert abs(m.last["mean_dn"] - 2048) < 15 and abs(m.last["mean_dn"] - 2034) < 3


@pytest.mark.parametrize("percent,target", [(30, 1228), (70, 2867)])
def test_spec_other_targets_converge(base, percent, target):
    m = Classical(percent, mode="borealhdr")
    t = 4.0
    for _ in range(30):
        t = m.next_exposure(linear_scene(base, 256, t), t)
    assert abs(m.last["mean_dn"] - target) < 15


def test_dead_band_and_abs_quirk():
    m = Classical(50, mode="borealhdr")
    for mean in (2048 - 14, 2048, 2048 + 14):
        assert m.update(mean, 3.7) == 3.7
    white = np.full((32, 32), 4095, np.uint16)
    assert m.next_exposure(white, 1.0) == pytest.approx(3.094)  # |1 - 4.094|: longer!
    assert Classical(50, mode="paper").next_exposure(white, 1.0) == 0.02  # SAFE
    black = np.zeros((32, 32), np.uint16)
    assert m.next_exposure(black, 1.0) == pytest.approx(5.096)


def test_no_convergence_when_k_above_1000(base):
    m = Classical(50, mode="borealhdr")
    t, traj = 1.0, []
    for _ in range(15):
        t = m.next_exposure(linear_scene(base, 2000, t), t)
        traj.append(t)
    assert len(set(np.round(traj[-5:], 6))) > 1  # still oscillating after 15 frames


@pytest.mark.parametrize("mode,n_adjust", [("borealhdr", 4), ("paper", 3)])
def test_fixed_adjusts_then_freezes(base, mode, n_adjust):
    fixed, classical = Fixed(mode=mode, range_ms=None), Classical(50, mode=mode, range_ms=None)
    t = 1.0
    for _ in range(n_adjust):
        raw = linear_scene(base, 256, t)
        expected = classical.next_exposure(raw, t)
        t = fixed.next_exposure(raw, t)
        assert t == expected
    assert fixed.n_adjustments == n_adjust
    for img in (np.zeros((16, 16), np.uint16), np.full((16, 16), 4095, np.uint16), linear_scene(base, 256, 3.0)):
        for t_in in (0.37, 12.5, 80.0):
            assert fixed.next_exposure(img, t_in) == t_in  # returns its input exactly


def test_paper_mode_safe_floor_never_lengthens_when_over_exposed(base):
    m = Classical(50, mode="paper")
    for t in (1.5, 3.0, 10.0):  # mean >= 3000 DN: over-exposed
        assert m.next_exposure(linear_scene(base, 2000, t), t) < t
