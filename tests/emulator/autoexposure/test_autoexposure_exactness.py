"""The throughput work changes no method's output: optimised arithmetic against the frozen
pre-change implementations (tests/emulator/autoexposure/ae_reference.py) on real BorealHDR frames, bit for bit.

Frames: the sample's left-camera brackets and emulations of them at off-bracket targets
(what the closed loop hands the methods), through both gray conversions.  Then the whole
seven-method stereo loop in both modes, once with the library as it is and once with the
frozen per-frame arithmetic patched in: every row of every method must be identical.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.emulator.autoexposure import ae_reference as ref
from emulator.autoexposure import METHOD_NAMES, Kim2018, Shim2014, Zhang2017, to_gray
from emulator.autoexposure import kim as kim_mod
from emulator.autoexposure import shim as shim_mod
from emulator.autoexposure.base import REF_BAYER_CODE, RGGB_BAYER_CODE


@pytest.fixture(scope="module")
def sample(sample_seq):
    from emulator.io.borealhdr import load_sequence, sequence_response

    seq = load_sequence(sample_seq)
    return seq, sequence_response(seq)


@pytest.fixture(scope="module")
def frames(sample):
    """(name, exposure_ms, raw) of real frames: brackets and emulations at off-bracket targets."""
    from emulator.core.emulate import apply_lut

    seq, response = sample
    cycle = seq[1]
    out = []
    for b in (1.0, 8.0, 32.0):
        out.append((f"bracket {b:g}", b, cycle.frames["left"][b].load()))
    for source, target in ((8.0, 5.3), (16.0, 11.0), (2.0, 2.9)):
        raw = cycle.frames["left"][source].load()
        table, _ = response.lut(target / source)
        out.append((f"{source:g}->{target:g}", target, apply_lut(table, raw)))
    return out


def _grays(frames, code):
    return [(name, t, to_gray(raw, code)) for name, t, raw in frames]


@pytest.mark.slow
def test_shim_metrics_equal_frozen(frames):
    for name, _, y in _grays(frames, REF_BAYER_CODE):
        m_new, f_new = shim_mod.gamma_metrics_ref(y)
        m_old, f_old = ref.gamma_metrics_ref(y)
        assert np.array_equal(m_new, m_old) and np.array_equal(f_new, f_old), name
    paper_new, paper_old = Shim2014(mode="paper", range_ms=None), Shim2014(mode="paper", range_ms=None)
    for name, t, y in _grays(frames, RGGB_BAYER_CODE):
        m_new, _ = shim_mod.gamma_metrics_paper(y)
        m_old, _ = ref.gamma_metrics_paper(y)
        # paper mode: cv2.magnitude (old) rounds some pixels by the memory alignment of its
        # inputs; the new correctly rounded sqrt(Gx^2 + Gy^2) moves the metric by < 1e-6
        # relative (the tolerance of the Shim tests), and gamma-hat, the output, not at all.
        np.testing.assert_allclose(m_new, m_old, rtol=1e-6, atol=0, err_msg=name)
        gamma_new = paper_new.best_gamma(y)
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(shim_mod, "gamma_metrics_paper", lambda y, *a, **k: ref.gamma_metrics_paper(y))
            assert paper_old.best_gamma(y) == gamma_new, name


def test_shim_paper_metric_does_not_depend_on_memory_layout(frames):
    """The same image in a differently aligned buffer gives the same metric, bit for bit."""
    y = to_gray(frames[1][2], RGGB_BAYER_CODE)[:200]
    first, _ = shim_mod.gamma_metrics_paper(y)
    for offset in (1, 3, 5):
        buf = np.empty(y.size + 8, np.uint16)
        shifted = buf[offset : offset + y.size].reshape(y.shape)
        shifted[...] = y
        assert np.array_equal(shim_mod.gamma_metrics_paper(shifted)[0], first)


@pytest.mark.slow
def test_zhang_derivatives_equal_frozen(frames, sample):
    _, response = sample
    boreal = Zhang2017(mode="borealhdr", response=response, range_ms=None)
    paper = Zhang2017(mode="paper", response=response, range_ms=None)
    for name, t, y in _grays(frames, REF_BAYER_CODE):
        assert boreal._ref_derivative(y, t) == ref._ref_derivative(boreal, y, t), name
    for name, t, y in _grays(frames, RGGB_BAYER_CODE):
        assert paper._paper_derivative(y, t) == ref._paper_derivative(paper, y, t), name


@pytest.mark.slow
def test_kim_metrics_equal_frozen(frames):
    # borealhdr: the frozen float64 table form ends in a 2.3M-element BLAS dot whose last bits
    # follow OpenBLAS's kernel and thread count; the library now rounds REF's formula once
    # (tests/emulator/autoexposure/test_autoexposure_kim.py::test_metric_ref_is_ref_formula_correctly_rounded), so the
    # two agree to the frozen form's own accuracy, not bit for bit.
    for name, _, y in _grays(frames, REF_BAYER_CODE):
        assert kim_mod.metric_ref(y) == pytest.approx(ref.metric_ref(y), rel=1e-13, abs=0), name
    for name, _, y in _grays(frames, RGGB_BAYER_CODE):
        assert kim_mod.metric_paper(y) == ref.metric_paper(y), name


def _frozen(monkeypatch):
    """Patch the pre-change per-frame arithmetic into the library (gray conversion included)."""
    monkeypatch.setattr(shim_mod, "gamma_metrics_ref", lambda y, *a, **k: ref.gamma_metrics_ref(y))
    monkeypatch.setattr(shim_mod, "gamma_metrics_paper", lambda y, *a, **k: ref.gamma_metrics_paper(y))
    monkeypatch.setattr(Zhang2017, "_ref_derivative", lambda self, y, t, *a, **k: ref._ref_derivative(self, y, t))
    monkeypatch.setattr(Zhang2017, "_paper_derivative",
                        lambda self, y, t, *a, **k: ref._paper_derivative(self, y, t))
    # kim's borealhdr metric is not patched: it is correctly rounded now, no longer the frozen
    # float64 form (test_kim_metrics_equal_frozen)
    monkeypatch.setattr(kim_mod, "metric_paper", lambda y, *a, **k: ref.metric_paper(y))


def _rows(result):
    from emulator.io.runfolder import format_row

    return {name: [format_row(st) for st in steps] for name, steps in result.steps.items()}


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["borealhdr", "paper"])
def test_seven_method_stereo_loop_equals_frozen(sample, mode, monkeypatch):
    """Every CSV row of all seven methods (exposures, brackets, fractions, guards) is identical
    with the optimised arithmetic and with the frozen one, serial and threaded."""
    from emulator.playback import run

    seq, response = sample
    new = _rows(run(seq, "all", mode=mode, response=response, jobs=2))
    with monkeypatch.context() as mp:
        _frozen(mp)
        old = _rows(run(seq, "all", mode=mode, response=response, jobs=1))
    assert list(new) == list(METHOD_NAMES)
    assert new == old
    assert all(len(rows) == 4 for rows in new.values())
    for name in ("shim", "zhang", "kim"):
        assert all(math.isfinite(float(r[7])) for r in new[name])


def test_frozen_patch_reaches_the_methods(monkeypatch):
    """The loop comparison above is only meaningful if the patch is what the methods call."""
    calls = []
    monkeypatch.setattr(shim_mod, "gamma_metrics_ref", lambda y, *a, **k: calls.append("shim") or ref.gamma_metrics_ref(y))
    monkeypatch.setattr(kim_mod, "metric_ref", lambda y, *a, **k: calls.append("kim") or ref.metric_ref(y))
    rng = np.random.default_rng(0)
    raw = rng.integers(0, 4095, (48, 64), dtype=np.uint16)
    Shim2014(mode="borealhdr").next_exposure(raw, 4.0)
    Kim2018(mode="borealhdr").next_exposure(raw, 4.0)
    assert calls == ["shim", "kim"]
