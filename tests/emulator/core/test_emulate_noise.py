"""emulate(..., noise="consistent"): variance against exact theory, the default path, seeds, excess, errors.

The theory is recomputed here from the documented model, independently of
:mod:`emulator.noise`: a capture holds electrons ~ N(e, e + r^2) (the synthetic camera's
Gaussian shot + read noise; r = 2.4 e- keeps it Gaussian throughout) quantised at the
decision levels ``G (g[d] + g[d+1]) / 2``; consistent emulation from source DN d draws
electrons ~ N(k G g(d), V_add(d)) with ``V_add = k e + r^2 - k^2 (e + r^2 + (G g'(d))^2/12)``,
``e = G g(d)``, quantised the same way (the plain table value where V_add <= 0).  Summing
over the source DN distribution gives the exact distribution of the emulated DN, so its
variance and fourth moment are exact, and the sample variance of N i.i.d. flat-field pixels
has standard deviation ``sqrt((mu4 - sigma^4 (N - 3) / (N - 1)) / N)``: the tests accept 4.5
of those (two-sided p ~ 7e-6 under the normal approximation of the sample variance).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import ndtr

from emulator import CameraResponse, EmulationError, ExposimError
from emulator.core.emulate import emulate
from emulator.io.borealhdr import load_sequence, sequence_response
from emulator.noise import NoiseModel, NoiseModelError
from synth import Camera, capture
from synth.noise_model import noise_model_of

SIZE = 256
#: Sample-variance tolerance in standard deviations of the estimate (see the module notes).
Z = 4.5


# ---------------------------------------------------------------------------- exact theory
def _dn_distribution(levels_e, mean_e, var_e, black, white):
    """P(DN = d) for d = 0..white: electrons ~ N(mean, var), DN = black + #{levels <= e}."""
    cdf = ndtr((levels_e - mean_e) / np.sqrt(var_e))
    p = np.diff(np.concatenate([[0.0], cdf, [1.0]]))
    out = np.zeros(white + 1)
    out[black: black + p.size] = p
    return out


def _moments(p):
    v = np.arange(p.size, dtype=np.float64)
    m = float(np.sum(v * p))
    c = v - m
    return m, float(np.sum(c**2 * p)), float(np.sum(c**4 * p))


def _theory(cam: Camera, e_target: float, source_ms: float, target_ms: float):
    """Exact (mean, var, mu4) of the DN of: a live capture, the consistent and the plain emulation."""
    resp = cam.response
    g, b, w = resp.g, resp.black_level, resp.white_level
    gain = cam.full_well_e / g[w]  # electrons per unit of h, from the camera's own definition
    r2 = cam.read_noise_e**2
    levels = 0.5 * (g[b:w] + g[b + 1: w + 1]) * gain
    k = target_ms / source_ms
    live = _dn_distribution(levels, e_target, e_target + r2, b, w)
    src = _dn_distribution(levels, e_target / k, e_target / k + r2, b, w)
    slope = np.gradient(g)
    lut = np.clip(np.rint(resp.forward(k * g)), b, w).astype(int)
    emu = np.zeros(w + 1)
    plain = np.zeros(w + 1)
    for d in np.flatnonzero(src > 1e-14):
        e = gain * max(g[d], 0.0)
        v_add = k * e + r2 - k * k * (e + r2 + (gain * slope[d]) ** 2 / 12.0)
        plain[lut[d]] += src[d]
        if v_add > 0:
            emu += src[d] * _dn_distribution(levels, k * e, v_add, b, w)
        else:
            emu[lut[d]] += src[d]
    return _moments(live), _moments(emu), _moments(plain)


def _sample_var_sd(var: float, mu4: float, n: int) -> float:
    return float(np.sqrt((mu4 - var**2 * (n - 3) / (n - 1)) / n))


def _flat(cam: Camera, electrons_at_1ms: float) -> np.ndarray:
    """Per-site radiance giving ``electrons_at_1ms`` mean electrons per ms at every site (no vignetting)."""
    return np.full((cam.height, cam.width), electrons_at_1ms / cam.radiance_scale, dtype=np.float32)


# ---------------------------------------------------------------------------- variance vs theory
@pytest.mark.parametrize(
    "preset,e_target,source_ms,target_ms",
    [
        ("linear", 100.0, 8.0, 2.0),
        ("linear", 1500.0, 8.0, 5.3),
        ("linear", 20.0, 32.0, 1.0),
        ("borealhdr", 150.0, 8.0, 2.0),
        ("borealhdr", 2000.0, 16.0, 4.0),
        ("gamma22", 400.0, 4.0, 1.0),
    ],
)
def test_consistent_variance_matches_theory_on_a_flat_field(preset, e_target, source_ms, target_ms):
    cam = Camera.preset(preset, width=SIZE, height=SIZE, vignetting_strength=0.0)
    model = noise_model_of(cam)
    radiance = _flat(cam, e_target / target_ms)
    src = capture(radiance, source_ms, cam, seed=np.random.SeedSequence([11, 0]))
    cons = emulate(src, source_ms, target_ms, cam.response, noise="consistent", noise_model=model,
                   rng=np.random.SeedSequence([11, 1])).astype(np.float64)
    plain = emulate(src, source_ms, target_ms, cam.response).astype(np.float64)
    live_img = capture(radiance, target_ms, cam, seed=np.random.SeedSequence([11, 2])).astype(np.float64)
    (m_live, v_live, q_live), (m_emu, v_emu, q_emu), (m_plain, v_plain, q_plain) = _theory(
        cam, e_target, source_ms, target_ms)
    n = cons.size
    # the implementation draws what the theory says (exact distribution, sampling error only)
    assert abs(cons.var(ddof=1) - v_emu) <= Z * _sample_var_sd(v_emu, q_emu, n)
    assert abs(cons.mean() - m_emu) <= Z * np.sqrt(v_emu / n)
    assert abs(plain.var(ddof=1) - v_plain) <= Z * _sample_var_sd(v_plain, q_plain, n)
    # and the live camera does what its theory says (same bound): the comparison is fair
    assert abs(live_img.var(ddof=1) - v_live) <= Z * _sample_var_sd(v_live, q_live, n)
    # the model: consistent emulation has the live variance (exact computation; the residual
    # is the shape of the distribution through a curved response, < 1 % at these levels)
    assert abs(v_emu / v_live - 1.0) < 0.01
    assert abs(m_emu - m_live) < 0.05 * np.sqrt(v_live)
    # the plain emulation is as clean as the theory says: k^2 e + ... over k e + ...
    k = target_ms / source_ms
    assert v_plain / v_live < k + 0.05
    # and measured against the live capture directly: within 1 % model + sampling bounds
    sd = _sample_var_sd(v_live, q_live, n) + _sample_var_sd(v_emu, q_emu, n)
    assert abs(cons.var(ddof=1) - live_img.var(ddof=1)) <= 0.01 * v_live + Z * sd


def test_per_phase_model_adds_per_phase_noise():
    """A 2x2 gain tile: each Bayer phase gets its own variance (linear response, exact)."""
    resp = CameraResponse.linear()
    gains = ((4000.0, 10000.0), (10000.0, 25000.0))
    model = NoiseModel(resp, gains, 3.0)
    assert model.per_phase
    k = 0.25
    d = 2000
    raw = np.full((512, 512), d, dtype=np.uint16)  # a noiseless source: only added noise is seen
    out = emulate(raw, 8.0, 2.0, resp, noise="consistent", noise_model=model, rng=3).astype(np.float64)
    slope = 1.0 / 4095.0
    for (i, j), gain in zip(((0, 0), (0, 1), (1, 0), (1, 1)), (4000.0, 10000.0, 10000.0, 25000.0)):
        e = gain * d / 4095.0
        v_add = k * e + 9.0 - k * k * (e + 9.0 + (gain * slope) ** 2 / 12)  # electrons^2
        expected = v_add / (gain * slope) ** 2 + 1.0 / 12.0  # DN^2: added noise, then rounding
        phase = out[i::2, j::2]
        sd = expected * np.sqrt(2.0 / (phase.size - 1))
        assert abs(phase.var(ddof=1) - expected) <= Z * sd, (i, j)
        assert abs(phase.mean() - k * d) <= Z * np.sqrt(expected / phase.size)


# ---------------------------------------------------------------------------- default path
def _reference_plain(raw, k, resp):
    """Eq. 2 per pixel in float64 (what the reference code does), rounded half to even, clipped."""
    dn = np.arange(resp.white_level + 1, dtype=np.float64)
    h = np.interp(raw.astype(np.float64), dn, resp.g) * k
    return np.clip(np.rint(np.interp(h, resp.g, dn)), resp.black_level, resp.white_level).astype(np.uint16)


def test_default_path_unchanged_on_real_frames(sample_seq):
    seq = load_sequence(sample_seq)
    resp = sequence_response(seq)
    model = NoiseModel.from_full_well(resp, 10500.0, 2.4)
    for exp_ms, target_ms in ((8.0, 5.3), (2.0, 7.9), (32.0, 1.0), (16.0, 16.0)):
        raw = seq[1].frames["left"][exp_ms].load()
        k = target_ms / exp_ms
        ref = _reference_plain(raw, k, resp)
        out, mask = emulate(raw, exp_ms, target_ms, resp, return_mask=True)
        np.testing.assert_array_equal(out, ref)
        # naming the default, or passing a model and a seed to it, changes nothing
        out2, mask2 = emulate(raw, exp_ms, target_ms, resp, return_mask=True, noise="none",
                              noise_model=model, rng=0)
        np.testing.assert_array_equal(out2, out)
        np.testing.assert_array_equal(mask2, mask)
        assert emulate(raw, exp_ms, target_ms, resp).dtype == np.uint16


# ---------------------------------------------------------------------------- seeds
def test_seeded_reruns_are_bit_identical_and_independent_of_blocking(sample_seq):
    seq = load_sequence(sample_seq)
    resp = sequence_response(seq)
    model = NoiseModel.from_full_well(resp, 10500.0, 2.4)
    raw = seq[1].frames["left"][8.0].load()  # 1920x1200: the two-thread path

    def run(rng, image=raw):
        return emulate(image, 8.0, 3.1, resp, noise="consistent", noise_model=model, rng=rng)

    a = run(42)
    assert a.dtype == np.uint16 and a.shape == raw.shape
    np.testing.assert_array_equal(a, run(42))
    np.testing.assert_array_equal(a, run(np.random.default_rng(42)))
    np.testing.assert_array_equal(a, run(np.random.SeedSequence(42)))
    b = run(43)
    assert np.mean(a != b) > 0.5  # another seed, other noise
    # the draw is in raster order: the top rows alone get the same noise (single thread)
    np.testing.assert_array_equal(run(42, np.ascontiguousarray(raw[:200])), a[:200])
    # a Generator advances: two calls with one Generator differ
    gen = np.random.default_rng(5)
    assert np.mean(run(gen) != run(gen)) > 0.5


# ---------------------------------------------------------------------------- excess
def _ratio_formula(d, k, model):
    """var_emulated / var_live of the Notes, recomputed (electrons^2)."""
    resp = model.response
    g, slope = resp.g, np.gradient(resp.g)
    gain, r2 = model.gain_e_per_h, model.read_noise_e**2
    e = gain * np.maximum(g[d], 0.0)
    d_t = resp.forward(k * g[d])
    q_t = (gain * np.interp(d_t, np.arange(g.size), slope)) ** 2 / 12.0
    v_emu = k * k * (e + r2 + (gain * slope[d]) ** 2 / 12.0) + q_t
    return v_emu / (k * e + r2 + q_t)


@pytest.mark.parametrize("preset", ["linear", "borealhdr"])
def test_excess_flagged_when_brightening_and_never_hidden(preset):
    cam = Camera.preset(preset, width=128, height=96)
    model = noise_model_of(cam)
    rng = np.random.default_rng(0)
    raw = rng.integers(0, cam.white_level + 1, size=(96, 128)).astype(np.uint16)
    for k in (2.0, 4.0, 1.7):
        plain = emulate(raw, 4.0, 4.0 * k, cam.response)
        out, mask, excess = emulate(raw, 4.0, 4.0 * k, cam.response, return_mask=True, noise="consistent",
                                    noise_model=model, rng=1, return_excess=True)
        np.testing.assert_array_equal(out, plain)  # nothing can be removed, nothing is added
        assert excess.dtype == np.float32 and excess.shape == raw.shape
        assert np.all(excess[mask] > 1.0)
        np.testing.assert_allclose(excess, _ratio_formula(raw, k, model), rtol=1e-5)
        _, plain_excess = emulate(raw, 4.0, 4.0 * k, cam.response, noise_model=model, return_excess=True)
        np.testing.assert_array_equal(plain_excess, excess)
    # darkening: consistent is 1 where noise is added, plain is below 1 (too clean)
    k = 0.25
    _, excess = emulate(raw, 8.0, 2.0, cam.response, noise="consistent", noise_model=model, rng=1,
                        return_excess=True)
    _, plain_excess = emulate(raw, 8.0, 2.0, cam.response, noise_model=model, return_excess=True)
    inside = (raw > cam.black_level) & (raw < cam.white_level)
    assert np.all(excess[inside] == 1.0)
    assert np.all(plain_excess[inside] < 1.0)
    np.testing.assert_allclose(plain_excess, _ratio_formula(raw, k, model), rtol=1e-5)
    # k = 1 is the identity: the capture itself, ratio exactly 1 and no noise
    same, ratio1 = emulate(raw, 4.0, 4.0, cam.response, noise="consistent", noise_model=model, rng=1,
                           return_excess=True)
    np.testing.assert_array_equal(same, raw)
    assert np.all(ratio1 == 1.0)


# ---------------------------------------------------------------------------- errors
def test_errors_name_the_problem():
    resp = CameraResponse.linear()
    model = NoiseModel(resp, 10500.0, 2.4)
    raw = np.full((8, 8), 100, dtype=np.uint16)
    with pytest.raises(EmulationError, match="noise_model"):
        emulate(raw, 2.0, 1.0, resp, noise="consistent", rng=0)
    with pytest.raises(EmulationError, match="noise_model"):
        emulate(raw, 2.0, 1.0, resp, return_excess=True)
    with pytest.raises(EmulationError, match="NoiseModel"):
        emulate(raw, 2.0, 1.0, resp, noise="consistent", noise_model={"gain_e_per_h": 1.0}, rng=0)
    with pytest.raises(EmulationError, match="rng is required"):
        emulate(raw, 2.0, 1.0, resp, noise="consistent", noise_model=model)
    for bad in (-1, 1.5, "seed", True):
        with pytest.raises(EmulationError, match="rng must be"):
            emulate(raw, 2.0, 1.0, resp, noise="consistent", noise_model=model, rng=bad)
    with pytest.raises(EmulationError, match="noise must be one of 'none', 'consistent'"):
        emulate(raw, 2.0, 1.0, resp, noise="poisson", noise_model=model, rng=0)
    other = CameraResponse.gamma(2.2)
    with pytest.raises(EmulationError, match="refers to response 'linear'.*gamma2.2"):
        emulate(raw, 2.0, 1.0, other, noise="consistent", noise_model=model, rng=0)
    for gain in (float("nan"), float("inf"), 0.0, -3.0, "x", [[1.0, 2.0]]):
        with pytest.raises(NoiseModelError, match="gain_e_per_h"):
            NoiseModel(resp, gain, 2.4)
    for read in (float("nan"), -0.1, float("-inf")):
        with pytest.raises(NoiseModelError, match="read_noise_e"):
            NoiseModel(resp, 100.0, read)
    with pytest.raises(NoiseModelError, match="full_well_e"):
        NoiseModel.from_full_well(resp, float("nan"), 2.4)
    with pytest.raises(NoiseModelError, match="CameraResponse"):
        NoiseModel(np.arange(4096.0), 100.0, 2.4)
    assert issubclass(NoiseModelError, ExposimError)
    # a bad exposure is still refused before anything else
    with pytest.raises(EmulationError, match="target_ms"):
        emulate(raw, 2.0, float("nan"), resp, noise="consistent", noise_model=model, rng=0)


# ---------------------------------------------------------------------------- measured variance ratio
#: Electrons per site at the target exposure: inside 1-90 % of the range at the target, sources
#: (up to 4x more) unclipped.
BANDS_E = (120.0, 220.0, 400.0, 750.0, 1300.0, 2200.0)


def _banded_flat(cam: Camera, target_ms: float) -> np.ndarray:
    """Six flat horizontal bands (per-site radiance) giving BANDS_E electrons at ``target_ms``."""
    rows = np.array_split(np.arange(cam.height), len(BANDS_E))
    rad = np.empty((cam.height, cam.width), dtype=np.float32)
    for r, e in zip(rows, BANDS_E):
        rad[r] = e / target_ms / cam.radiance_scale
    return rad


@pytest.mark.parametrize("preset,source_ms,target_ms", [("linear", 8.0, 2.0), ("borealhdr", 16.0, 5.3)])
def test_noise_variance_ratio_on_a_flat_field(preset, source_ms, target_ms):
    """Plain emulation from a longer bracket is too clean by the analytic ratio; consistent is within 10 % of 1."""
    from emulator.noise import noise_variance_ratio

    cam = Camera.preset(preset, width=SIZE, height=6 * 64, vignetting_strength=0.0)
    model = noise_model_of(cam)
    rad = _banded_flat(cam, target_ms)
    src = capture(rad, source_ms, cam, seed=np.random.SeedSequence([21, 0]))
    live = capture(rad, target_ms, cam, seed=np.random.SeedSequence([21, 1]))
    levels = capture(rad, target_ms, cam, seed=None, noise=False)  # noiseless target DN: one value per band
    plain = emulate(src, source_ms, target_ms, cam.response)
    cons = emulate(src, source_ms, target_ms, cam.response, noise="consistent", noise_model=model, rng=7)
    r_plain = noise_variance_ratio(plain, live, cam.response, levels=levels)
    r_cons = noise_variance_ratio(cons, live, cam.response, levels=levels)
    assert r_plain.mode == "spatial" and len(r_plain.bins) == len(BANDS_E)  # one bin per band here
    n = SIZE * 64
    for band, e, bp, bc in zip(range(len(BANDS_E)), BANDS_E, r_plain.bins, r_cons.bins):
        (_, v_live, q_live), (_, v_emu, q_emu), (_, v_pl, q_pl) = _theory(cam, e, source_ms, target_ms)
        assert bp["dn_lo"] <= levels[band * 64, 0] < bp["dn_hi"]
        # measured ratio against the exact one: sampling error of both variances (Z sigma)
        for got, v_e, q_e in ((bp, v_pl, q_pl), (bc, v_emu, q_emu)):
            ratio = v_e / v_live
            sd = ratio * np.hypot(_sample_var_sd(v_e, q_e, n) / v_e, _sample_var_sd(v_live, q_live, n) / v_live)
            assert abs(got["ratio"] - ratio) <= Z * sd, (band, got["ratio"], ratio)
        assert v_pl / v_live < 1.0
        assert abs(bc["ratio"] - 1.0) < 0.10
    k = target_ms / source_ms
    theory_plain = np.median([_theory(cam, e, source_ms, target_ms)[2][1] / _theory(cam, e, source_ms, target_ms)[0][1]
                              for e in BANDS_E])
    assert r_plain.median < 1.0 and abs(r_plain.median - theory_plain) < 0.05
    assert k - 0.05 < theory_plain < 1.0  # shot-noise dominated: about k (read noise pushes it up a little)
    assert abs(r_cons.median - 1.0) < 0.10 and r_cons.max_abs_deviation < 0.10


def test_noise_variance_ratio_temporal_stacks_and_errors():
    """Stacks of repeats give the per-pixel temporal variance; bad shapes are refused by name."""
    from emulator.noise import NoiseModelError, noise_variance_ratio

    cam = Camera.preset("linear", width=64, height=6 * 8, vignetting_strength=0.0)
    model = noise_model_of(cam)
    rad = _banded_flat(cam, 2.0)
    ss = lambda *k: np.random.SeedSequence([31, *k])  # noqa: E731
    src = [capture(rad, 8.0, cam, seed=ss(0, r)) for r in range(24)]
    live = np.stack([capture(rad, 2.0, cam, seed=ss(1, r)) for r in range(24)])
    plain = np.stack([emulate(s, 8.0, 2.0, cam.response) for s in src])
    cons = np.stack([emulate(s, 8.0, 2.0, cam.response, noise="consistent", noise_model=model, rng=ss(2, r))
                     for r, s in enumerate(src)])
    levels = capture(rad, 2.0, cam, seed=None, noise=False)
    rp = noise_variance_ratio(plain, live, cam.response, levels=levels)
    rc = noise_variance_ratio(cons, live, cam.response, levels=levels)
    assert rp.mode == "temporal" and rp.bins[0]["dof"] == 64 * 8 * 23
    # dof 11776 per bin: sampling sd of a ratio ~2 %; the theory says 0.25-0.33 and 1
    assert 0.2 < rp.median < 0.4 and abs(rc.median - 1.0) < 0.10
    assert rc.to_dict()["median"] == rc.median
    with pytest.raises(NoiseModelError, match="must both be"):
        noise_variance_ratio(plain, live[0], cam.response)
    with pytest.raises(NoiseModelError, match="at least 2 repeats"):
        noise_variance_ratio(plain[:1], live, cam.response)
    with pytest.raises(NoiseModelError, match="no intensity bin"):
        noise_variance_ratio(plain, live, cam.response, levels=np.zeros(levels.shape))


# ---------------------------------------------------------------------------- reproducibility
def test_same_seed_same_bytes_synthetic_and_estimate(tmp_path):
    """Same seed, same bytes: consistent emulation (pooled and per-phase models), and the in-situ
    estimate and its JSON, which draw nothing (deterministic in their inputs)."""
    from emulator.io.noisemodel import write_noise_model
    from emulator.noise import bracket_groups, estimate_noise_model
    from synth import capture_sequence
    from synth.procedural import TranslatingChart

    cam = Camera.preset("borealhdr", width=192, height=128)
    pooled = noise_model_of(cam)
    per_phase = NoiseModel(cam.response, ((30.0, 41.5), (41.5, 25.0)), 2.4)
    src = TranslatingChart(192, 128, seed=2, speed_m_s=0.8, duration_s=2.0, dynamic_range_db=60)
    seq_path = capture_sequence(src, tmp_path / "walk", cam, n_cycles=2, stereo=False, seed=4)
    seq = load_sequence(seq_path)
    raw = seq[0].frames["left"][16.0].load()
    for model in (pooled, per_phase):
        outs = [emulate(raw, 16.0, 5.3, cam.response, noise="consistent", noise_model=model, rng=seed).tobytes()
                for seed in (9, 9, 10)]
        assert outs[0] == outs[1] and outs[0] != outs[2]
        # a fresh model object (empty caches) gives the same bytes
        fresh = NoiseModel.from_json(model.to_json(), cam.response)
        assert emulate(raw, 16.0, 5.3, cam.response, noise="consistent", noise_model=fresh, rng=9).tobytes() == outs[0]
    # the recording itself is reproducible bit for bit, and so is the estimate written from it
    again = load_sequence(capture_sequence(src, tmp_path / "walk2", cam, n_cycles=2, stereo=False, seed=4))
    assert again[0].frames["left"][16.0].load().tobytes() == raw.tobytes()
    a = write_noise_model(tmp_path / "a.json", estimate_noise_model(bracket_groups(seq), cam.response, n_bins=8, min_pixels=40))
    b = write_noise_model(tmp_path / "b.json", estimate_noise_model(bracket_groups(again), cam.response, n_bins=8, min_pixels=40))
    assert a.read_bytes() == b.read_bytes()
